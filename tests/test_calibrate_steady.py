"""The calibrator's steady-state view: what no library term explains is reported, not forced."""

from __future__ import annotations

import numpy as np

from monitor.vehicle import REPO_ROOT, load_vehicle
from offline.calibrate.fit import calibrate_steady, predicted_commands

NOM = load_vehicle(REPO_ROOT / "models" / "crazyflie.yaml")


def _flights(pattern, n=6, noise=0.003, seed=0):
    rng = np.random.default_rng(seed)
    base = predicted_commands(NOM)
    return base * (1.0 + np.asarray(pattern)) * (1.0 + noise * rng.standard_normal((n, 4)))


def test_a_yaw_pair_pattern_outside_the_library_is_an_unexplained_residual():
    # Same-spin rotors (PX4 1, 2 CCW; 3, 4 CW) pulled apart: a CG offset, a mass or an ESC
    # curve cannot make it. Without motor_efficiency in the library it must stay unexplained.
    fit = _flights([0.05, 0.05, -0.05, -0.05])
    cal = calibrate_steady("x", NOM, fit, fit, ["f"] * len(fit), [], candidates=("cg_offset", "mass", "esc_curve"))
    un = cal.unexplained
    assert un["in_standard_errors"] > 10.0
    # Its size is the pattern's: about 5 % of the hover command, RMS over the motors.
    assert abs(un["rms_cmd"] / np.mean(predicted_commands(NOM)) - 0.05) < 0.01


def test_an_effect_in_the_library_leaves_nothing_unexplained():
    fit = _flights([0.05, 0.05, -0.05, -0.05], seed=1)
    cal = calibrate_steady("x", NOM, fit, fit, ["f"] * len(fit), [])
    assert cal.cause == "motor_efficiency"
    assert cal.unexplained["in_standard_errors"] < 3.0


def test_nothing_hidden_nothing_named():
    fit = _flights([0.0, 0.0, 0.0, 0.0], seed=2)
    cal = calibrate_steady("x", NOM, fit, fit, ["f"] * len(fit), [])
    assert cal.cause is None and cal.unexplained["in_standard_errors"] < 3.0
