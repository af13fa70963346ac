"""The fleet package stays on monitor's side: no torch, no offline; `propwatch fleet --help` imports no Ray."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

BLOCKED = """
import sys
sys.modules["torch"] = None
sys.modules["offline"] = None
"""


def run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BLOCKED + code], capture_output=True, text=True, cwd=REPO, timeout=120)


def test_fleet_runs_without_torch_or_offline(tmp_path):
    pytest.importorskip("duckdb")
    log = tmp_path / "x.tlog"
    log.write_bytes(b"not a log")
    code = f"""
from fleet.ingest import ingest
from fleet.report import write_site
s = ingest([{str(log)!r}], {str(tmp_path / "f.duckdb")!r}, ray_address="off", progress=False)
assert (s.new, s.error) == (1, 1), s
write_site({str(tmp_path / "f.duckdb")!r}, {str(tmp_path / "site")!r})
assert not [m for m, mod in sys.modules.items() if mod is not None and (m == "torch" or m.startswith("offline"))]
print("ok")
"""
    res = run(code)
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stderr[-3000:]


def test_help_is_fast_and_imports_no_ray():
    res = run(
        "from monitor.cli import main\ntry:\n    main(['fleet', '--help'])\nexcept SystemExit:\n    pass\nassert 'ray' not in sys.modules and 'duckdb' not in sys.modules\n"
    )
    assert res.returncode == 0, res.stderr[-2000:]
    assert "fleet ingest" in res.stdout
