"""deploy/README.md section 5's two try-outs, run exactly as written there (only /tmp/tryout and the UDP port
changed to this test's own): a propeller that bends in the air reaches the ground-station stand-in as PROP 3 FAULT;
a vehicle's three healthy flights are learnt and a propeller damaged from take-off is then named against them."""

from __future__ import annotations

import os
import re
import socket
import stat
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CLASSIFIER = REPO / "models" / "classifier.onnx"
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not CLASSIFIER.is_file(), reason="models/classifier.onnx not built"),
]


def tryout_blocks() -> list[str]:
    text = (REPO / "deploy" / "README.md").read_text()
    section = text[text.index("## 5. Trying it without a vehicle") : text.index("## 6.")]
    return re.findall(r"```sh\n(.*?)```", section, re.S)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_block(block: str, tmp_path: Path) -> str:
    """The block in bash, with ``propwatch`` this checkout's command; its stdout and stderr."""
    pytest.importorskip("torch")  # simulate's learnt propellers
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir(exist_ok=True)
    shim = bin_dir / "propwatch"
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m monitor.cli "$@"\n')
    shim.chmod(shim.stat().st_mode | stat.S_IXUSR)
    script = block.replace("/tmp/tryout", str(tmp_path / "tryout")).replace("14540", str(free_udp_port()))
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}"}
    r = subprocess.run(["bash", "-c", script], cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    return r.stdout + r.stderr


def test_the_section_has_the_two_tryouts():
    blocks = tryout_blocks()
    assert len(blocks) == 2 and "--onset" in blocks[0] and "--state-dir" in blocks[1]


def test_a_propeller_that_bends_in_the_air_reaches_the_ground_station_as_prop_3_fault(tmp_path):
    out = run_block(tryout_blocks()[0], tmp_path)
    texts = re.findall(r'"text": "(PROP [^"]*)"', out)
    assert any(t.startswith("PROP 3 FAULT") for t in texts), out + (tmp_path / "tryout" / "journal.txt").read_text()
    assert all(t.startswith("PROP 3 ") for t in texts), texts


def test_three_healthy_flights_learnt_then_a_propeller_damaged_from_take_off_named(tmp_path):
    out = run_block(tryout_blocks()[1], tmp_path)
    assert out.count("vehicle memory: flight learnt") == 3, out
    assert "against 3 healthy flights of this vehicle" in out, out
    assert re.search(r"FAULT .*PROP 2 DAMAGED vs vehicle history", out), out
    assert "flight not learnt: it raised an alert" in out, out
