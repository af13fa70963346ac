"""What a new user trips over first: each test here failed before its fix (paper cuts)."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

from monitor.cli import main as propwatch

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
EVENTS_ULOG = DATA / "px4_ulog" / "sample_px4_events.ulg"


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> Path:
    """``propwatch simulate`` with no --format: two short flights, as a new user would first run it."""
    out = tmp_path_factory.mktemp("sim") / "run"
    r = subprocess.run(
        [sys.executable, "-m", "monitor.cli", "simulate", "--out", str(out), "--flights", "2", "--label", "4",
         "--duration-s", "12", "--propellers", "quadratic"],
        capture_output=True, text=True, cwd=REPO,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    return out, r.stdout


def test_simulate_writes_what_diagnose_reads_and_says_what_it_simulated(simulated, capsys):
    out, stdout = simulated
    lines = stdout.splitlines()
    assert lines == [
        f"{out / 'flight_000.tlog'}: 2024-06-01, 12 s, propeller 3 bent from take-off, payload 0 kg",
        f"{out / 'flight_001.tlog'}: 2024-06-02, 12 s, propeller 3 bent from take-off, payload 0 kg",
        f"ground truth: {out / 'sidecar.json'}",
    ]
    code = propwatch(["diagnose", str(out / "flight_000.tlog"), "--json"])
    assert code in (0, 1, 3) and "error" not in capsys.readouterr().out  # read: a verdict or a reason, never "unknown"


def test_the_base_install_reads_every_listed_format():
    """Every third-party module the log readers import is a base dependency, not an extra."""
    block = re.search(r"^dependencies = \[(.*?)^\]", (REPO / "pyproject.toml").read_text(), re.M | re.S).group(1)
    deps = re.findall(r'^\s*"([^"]+)"', block, re.M)  # [project].dependencies (no tomllib on Python 3.10)
    base = {re.split(r"[<>=!~ \[]", d)[0].lower() for d in deps}
    dist = {"yaml": "pyyaml"}
    needed = set()
    for f in (REPO / "monitor" / "logs").glob("*.py"):
        for node in ast.walk(ast.parse(f.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            names += [node.module] if isinstance(node, ast.ImportFrom) and node.module and node.level == 0 else []
            for n in names:
                top = n.split(".")[0]
                if top not in sys.stdlib_module_names and top not in ("monitor", "__future__"):
                    needed.add(dist.get(top, top).lower())
    assert "pyulog" in needed and "pymavlink" in needed  # the scan sees the readers' imports
    assert needed <= base, f"log readers need {sorted(needed - base)} outside [project].dependencies"
    readme = (REPO / "README.md").read_text()
    assert ".ulg" in readme and "[logs]" not in readme  # no extra is needed to read what the README lists


def test_a_closed_pipe_ends_quietly(simulated):
    out, _ = simulated
    p = subprocess.Popen(
        [sys.executable, "-m", "monitor.cli", "diagnose", str(out / "flight_000.tlog"), str(out / "flight_001.tlog")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO,
    )  # fmt: skip
    p.stdout.close()  # `| head -0`: the reader is gone before the first line
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141 and "Traceback" not in err and "BrokenPipe" not in err, err


def test_version_after_a_commands_arguments(capsys):
    from monitor import version

    for argv in (["diagnose", "x.tlog", "--json", "--version"], ["fleet", "report", "--db", "x", "--version"]):
        assert propwatch(argv) == 0
        assert capsys.readouterr().out.strip() == f"propwatch {version()}"


def test_a_wrong_format_is_named_as_such(tmp_path, capsys):
    fake = tmp_path / "notes.tlog"
    fake.write_text("flight notes: prop 3 chipped\n")
    assert propwatch(["diagnose", str(fake)]) == 2
    err = capsys.readouterr().err
    assert "named as a MAVLink telemetry log (.tlog) but not one, it starts with text ('flight notes: pr'" in err, err


def test_a_truncated_ulog_is_named_truncated(tmp_path, capsys):
    if not EVENTS_ULOG.is_file():
        pytest.skip(f"{EVENTS_ULOG} not found")
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(EVENTS_ULOG.read_bytes()[:20_000])
    assert propwatch(["diagnose", str(cut)]) == 2
    err = capsys.readouterr().err
    assert "truncated ULog (20000 bytes" in err and "actuator_outputs" in err, err


def test_a_failed_ingest_leaves_no_empty_store(simulated, tmp_path, capsys):
    pytest.importorskip("duckdb")
    out, _ = simulated
    db = tmp_path / "fleet.duckdb"
    code = propwatch(["fleet", "ingest", str(out), "--db", str(db), "--ray", "127.0.0.1:1", "--no-progress"])
    assert code == 2 and "127.0.0.1:1" in capsys.readouterr().err
    assert not db.exists() and not db.with_name(db.name + ".wal").exists()
