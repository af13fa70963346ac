"""Every healthy CrazyPAD flight, diagnosed without history on the Crazyflie's own model, asks for no propeller: the
classifier's flags alone are a note where physics names none of them (``monitor.diagnose.physics_first``)."""

from __future__ import annotations

import csv
import json

import pytest

from monitor.cli import main
from monitor.vehicle import REPO_ROOT

CRAZYPAD = REPO_ROOT.parent / "shared" / "data" / "crazypad"
pytestmark = pytest.mark.skipif(
    not (CRAZYPAD / "manifest.csv").is_file(), reason=f"CrazyPAD data not found at {CRAZYPAD} (../shared/data/crazypad)"
)


def test_healthy_crazypad_flights_name_no_propeller(capsys):
    rows = [r for r in csv.DictReader((CRAZYPAD / "manifest.csv").open()) if r["fault_kind"] == "healthy"]
    assert len(rows) >= 10
    results = []
    for log_type, fmt in (("motor", "crazypad"), ("controller", "crazypad-controller")):
        paths = [str(CRAZYPAD / r["file"]) for r in rows if r["log_type"] == log_type]
        if not paths:
            continue
        vehicle = str(REPO_ROOT / "models" / "crazyflie.yaml")
        # 0 healthy, 3 not confident ("no damage seen" on a first flight); never 1 (damaged) or 2 (an error)
        assert main(["diagnose", *paths, "--format", fmt, "--json", "--vehicle", vehicle]) in (0, 3)
        out = json.loads(capsys.readouterr().out)
        results += out.get("results", [out])
    assert len(results) == len(rows)
    asked = {r["log"]: (r["summary"].get("replace") or []) + (r["summary"].get("inspect") or []) for r in results}
    assert not any(asked.values()), {k: v for k, v in asked.items() if v}
    # the classifier was heard (its flags, where it raised any, are a warning), not silenced
    assert all(r.get("network", {}).get("used") for r in results), [r.get("network") for r in results]
