"""A wheel installed outside the checkout finds its shipped models and configs (package data).

Builds the wheel with ``pip wheel --no-deps``, installs it without dependencies
into a fresh venv that sees this interpreter's packages (numpy, onnxruntime,
pymavlink ...) through a plain ``.pth`` path, and runs ``propwatch diagnose``
on a shared real log from ``/``: nothing of the checkout is on its path.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
LOG171 = REPO.parent / "shared" / "data" / "ardupilot_log171" / "log171.bin"


# No PYTHONPATH: the checkout must not be importable (nor its build's propwatch.egg-info seen by pip).
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}


def _run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=ENV, **kw)


@pytest.mark.realdata
@pytest.mark.skipif(not LOG171.is_file(), reason=f"real ArduPilot log not found at {LOG171} (../shared/data)")
def test_installed_wheel_diagnoses_a_shared_log_from_root(tmp_path):
    # Build from a clean copy: setuptools' build/ in the checkout may hold stale files from earlier builds.
    src = tmp_path / "src"
    shutil.copytree(
        REPO, src, ignore=shutil.ignore_patterns(".git", ".venv", "build", "*.egg-info", "out", "__pycache__", ".*_cache")
    )
    wheels = tmp_path / "wheels"
    r = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(wheels), str(src)])
    assert r.returncode == 0, r.stderr
    (wheel,) = wheels.glob("propwatch-*.whl")

    venv = tmp_path / "venv"
    r = _run([sys.executable, "-m", "venv", "--without-pip", str(venv)])
    assert r.returncode == 0, r.stderr
    py = venv / "bin" / "python"
    site = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    # A plain path line: this interpreter's third-party packages, but not its .pth hooks (no editable propwatch).
    (site / "shared-deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    r = _run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(py),
            "install",
            "-q",
            "--no-deps",
            "--no-index",
            "--force-reinstall",
            str(wheel),
        ]
    )
    assert r.returncode == 0, r.stderr

    where = _run(
        [str(py), "-c", "import monitor, monitor.resources as r; print(monitor.__file__); print(r.models_dir())"], cwd="/"
    )
    assert where.returncode == 0, where.stderr
    monitor_file, models = where.stdout.split()
    assert monitor_file.startswith(str(site)) and models.startswith(str(site)), where.stdout + where.stderr

    # declared the paper's quad with the installed vehicle file, so the installed classifier reads the log too
    declared = ["--vehicle", str(Path(models) / "vehicle.yaml")]
    r = _run([str(venv / "bin" / "propwatch"), "diagnose", str(LOG171), "--json", *declared], cwd="/")
    assert r.returncode in (0, 1, 3), r.stderr  # a verdict or a stated refusal, never a missing file (2)
    out = json.loads(r.stdout)
    assert out["log"] == str(LOG171) and "error" not in out
    assert out["windows"] > 0
    # The in-flight decision (daemon and diagnose) reads the shipped threshold calibration, not the analytic fallback.
    cal = _run([str(py), "-c", "from monitor.decision.thresholds import load_calibration as c; print(c().model_sha256)"], cwd="/")
    assert cal.returncode == 0 and len(cal.stdout.strip()) == 64, cal.stdout + cal.stderr
    # simulate reads the shipped vehicle.yaml (and propeller models) the same way.
    r = _run(
        [
            str(venv / "bin" / "propwatch"),
            "simulate",
            "--out",
            str(tmp_path / "sim"),
            "--flights",
            "1",
            "--duration-s",
            "10",
            "--format",
            "npz",
        ],
        cwd="/",
    )
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "sim" / "flights.npz").is_file()
