"""One calibrator: ``propwatch calibrate``, ``propwatch adapt`` and the CrazyPAD experiment fit with
``offline.calibrate`` and nothing else, and on an airframe with a hidden CG offset adapt and calibrate name the
same cause. The CG flights come from the evaluation-only simulator (``offline/evalsim``) through a .tlog, as a
user's would.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import io
import json
from pathlib import Path

import evalsim_flights
import numpy as np
import pytest

from monitor.vehicle import DEFAULT_VEHICLE, REPO_ROOT, load_vehicle

NOM = load_vehicle(DEFAULT_VEHICLE)
FITTING = {"scipy.optimize", "sklearn", "statsmodels", "lmfit"}
FITTING_CALLS = {"least_squares", "curve_fit", "minimize", "lstsq", "polyfit", "leastsq", "nnls"}


def _fitting_code(path: Path) -> list[str]:
    """Imports of fitting libraries and calls of fitting functions in one module."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names if any(a.name.startswith(f) for f in FITTING)]
        elif isinstance(node, ast.ImportFrom) and node.module:
            if any(node.module.startswith(f) for f in FITTING):
                found.append(node.module)
            found += [f"{node.module}.{a.name}" for a in node.names if a.name in FITTING_CALLS]
        elif isinstance(node, ast.Attribute) and node.attr in FITTING_CALLS:
            found.append(node.attr)
        elif isinstance(node, ast.Name) and node.id in FITTING_CALLS:
            found.append(node.id)
    return found


@pytest.mark.parametrize("package", ["offline/adapt", "offline/crazypad"])
def test_adapt_and_crazypad_import_no_other_fitting_code(package):
    modules = sorted((REPO_ROOT / package).glob("*.py"))
    assert modules
    offenders = {str(p.relative_to(REPO_ROOT)): f for p in modules if (f := _fitting_code(p))}
    assert not offenders, offenders
    # ... and the calibration they do use is offline.calibrate's.
    text = "".join(p.read_text(encoding="utf-8") for p in modules)
    assert "from offline.calibrate" in text


def test_the_scan_finds_fitting_code():
    """The scan is not blind: offline/calibrate/fit.py is the calibrator and fits."""
    assert "scipy.optimize" in _fitting_code(REPO_ROOT / "offline" / "calibrate" / "fit.py")


def test_steady_view_says_what_it_cannot_separate():
    """A log without body rates gets the steady-state view, which lists the terms it cannot tell apart."""
    from offline.adapt.pipeline import HealthyLog, calibrate_airframe

    tabs = _cg_flights_own_sim()
    no_rates = [dataclasses.replace(t, roll_rate_rad_s=np.full_like(t.roll_rate_rad_s, np.nan)) for t in tabs]
    cal, _ = calibrate_airframe(NOM, [HealthyLog(f"f{i}", t) for i, t in enumerate(no_rates)])
    assert cal.view == "steady-state"
    assert ["cg_offset", "motor_efficiency"] in cal.record["cannot_separate"]
    assert "motor_time_constant" in cal.record["not_observable"]
    dyn, _ = calibrate_airframe(NOM, [HealthyLog(f"f{i}", t) for i, t in enumerate(tabs)])
    assert dyn.view == "dynamic" and "cannot_separate" not in dyn.record


def _cg_flights_own_sim():
    from offline.sim.mission import random_waypoints
    from offline.sim.propeller import QuadraticPropeller
    from offline.sim.simulator import SimConfig, simulate

    true = dataclasses.replace(NOM, cg_offset_frd_m=(0.012, -0.009, 0.0))
    log = simulate(true, random_waypoints(2, 5, seed=3), QuadraticPropeller.for_vehicle(true), SimConfig(duration_s=30.0), seed=3)
    return [log.to_flight_table(i, source=f"cg-{i}") for i in range(2)]


def _cg_specs() -> list:
    from offline.evalsim.sets import motor_lag_specs

    return [
        dataclasses.replace(s, airframe=s.airframe.with_(cg_offset_frd_m=(0.012, -0.009, 0.0)))
        for s in motor_lag_specs([NOM.motor_time_constant_s] * 4, 2, 5, 30.0)
    ]


evalsim_flights.declare(__name__, "evalsim_cg_logs", _cg_specs)


@pytest.fixture(scope="module")
def evalsim_cg_logs(tmp_path_factory):
    """Two 30-s healthy evalsim flights of the paper quad with a hidden 15 mm CG offset, as .tlog files."""
    pytest.importorskip("rotorpy")
    from offline.sim.io_tlog import write_tlog

    logs = evalsim_flights.simulate_flights(_cg_specs())
    d = tmp_path_factory.mktemp("evalsim-cg")
    return [str(write_tlog(d / f"cg-{i}.tlog", log, 0)) for i, log in enumerate(logs)]


@pytest.mark.slow
def test_adapt_and_calibrate_name_the_same_cause_on_a_hidden_cg_offset(evalsim_cg_logs):
    from offline.adapt.pipeline import calibrate_airframe, read_healthy
    from offline.calibrate.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main([*evalsim_cg_logs, "--json"]) == 0
    by_calibrate = json.loads(out.getvalue())
    cal, _ = calibrate_airframe(NOM, read_healthy(evalsim_cg_logs, None, NOM))
    assert cal.view == "dynamic"
    assert by_calibrate["cause"] == "cg_offset", by_calibrate["notes"]
    assert cal.cause == by_calibrate["cause"]
    cg = np.array(cal.calibrated.cg_offset_frd_m[:2])
    np.testing.assert_allclose(cg, [0.012, -0.009], atol=0.004)
