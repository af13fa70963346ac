"""One meaning per word: ``propwatch evaluate SUITE`` and ``propwatch tune sets|alerts``; former entry points
still run, after one line on stderr naming the new form."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def propwatch(*args: str) -> subprocess.CompletedProcess:
    code = "import sys; sys.modules['torch'] = None; from monitor.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, cwd=REPO, timeout=60)


@pytest.mark.parametrize(
    ("args", "usage", "deprecated"),
    [
        (("evaluate", "--help"), "usage: propwatch evaluate [-h] {alerts,classifier,evalsim}", ""),
        (("evaluate", "classifier", "--help"), "usage: propwatch evaluate classifier", ""),
        (("evaluate", "evalsim", "--help"), "usage: propwatch evaluate evalsim", ""),
        (("evalsim", "--help"), "usage: propwatch evaluate evalsim", "use 'propwatch evaluate evalsim'"),
        (("evaluate", "--hop", "20", "--help"), "usage: propwatch evaluate classifier", "'propwatch evaluate classifier"),
        (("tune", "sets", "--help"), "usage: propwatch tune sets", ""),
        (("tune", "noise", "--help"), "usage: propwatch tune noise", ""),
        (("tune", "alerts", "--help"), "usage: propwatch tune alerts", ""),
        (("evaluate", "alerts", "--help"), "usage: propwatch evaluate alerts", ""),
    ],
)
def test_each_form_reaches_its_tool(args, usage, deprecated):
    r = propwatch(*args)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(usage), r.stdout[:200]
    assert (deprecated in r.stderr) if deprecated else "deprecated" not in r.stderr


def test_tune_alerts_is_the_alert_evaluation_that_rewrites_the_calibration(monkeypatch):
    import offline.tune.alerts as tune_alerts
    from offline.alerts.evaluate import main as evaluate_alerts
    from offline.tune.cli import main

    seen = []
    monkeypatch.setattr(tune_alerts, "main", lambda argv: seen.append(argv) or 0)
    assert main(["alerts", "--calibration-hours", "1"]) == 0
    assert evaluate_alerts(["--calibrate", "--calibration-hours", "2"]) == 0  # the evaluation's own --calibrate
    assert seen == [["--calibration-hours", "1"], ["--calibration-hours", "2"]]


def test_an_unknown_suite_is_refused_with_the_choices():
    r = propwatch("evaluate", "nonsense")
    assert r.returncode == 2 and "alerts" in r.stderr and "classifier" in r.stderr and "evalsim" in r.stderr
