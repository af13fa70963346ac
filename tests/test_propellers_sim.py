"""Learned propellers inside the batched simulator: hover command, and a damaged rotor working harder."""

import numpy as np
import pytest

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.propellers import build_propellers

sim = pytest.importorskip("offline.sim.simulator", reason="the simulator is not in this tree")
from offline.sim.propeller import PropellerModel, QuadraticPropeller  # noqa: E402

VEHICLE = load_vehicle(DEFAULT_VEHICLE)
CFG = sim.SimConfig(duration_s=6.0, gyro_noise_std_rad_s=0.0, attitude_noise_std_rad=0.0)


def _hover(propellers, n: int):
    wps = np.broadcast_to(np.array(CFG.start_ned_m), (n, 1, 3)).copy()
    log = sim.simulate(VEHICLE, wps, propellers, CFG, seed=0)
    late = log.time_s > 3.0
    return log.pwm_us[:, late].mean(axis=1), log.pos_ned_m[:, late]


def test_protocol():
    assert isinstance(build_propellers(VEHICLE, np.zeros((1, 4), dtype=int), kind="lstm"), PropellerModel)
    assert isinstance(build_propellers(VEHICLE, np.zeros((1, 4), dtype=int), kind="quadratic"), PropellerModel)


def test_hover_pwm_lstm_matches_quadratic_in_closed_loop():
    pwm_quad, _ = _hover(QuadraticPropeller.for_vehicle(VEHICLE), 1)
    pwm_lstm, pos = _hover(build_propellers(VEHICLE, np.zeros((1, 4), dtype=int), kind="lstm", rng_seed=0), 1)
    np.testing.assert_allclose(pwm_lstm, pwm_quad, rtol=0.02)
    # And it hovers where it was asked to.
    np.testing.assert_allclose(pos[0, -1], CFG.start_ned_m, atol=0.2)


@pytest.mark.parametrize("kind", ["lstm", "quadratic"])
def test_damaged_rotor_needs_more_command(kind):
    # Flight 0 all normal; flight 1 rotor 1 bent; flight 2 rotor 3 cracked.
    cond = np.array([[0, 0, 0, 0], [1, 0, 0, 0], [0, 0, 2, 0]])
    pwm, pos = _hover(build_propellers(VEHICLE, cond, kind=kind, rng_seed=1), 3)
    assert np.all(np.isfinite(pos))
    np.testing.assert_allclose(pos[:, -1], np.broadcast_to(CFG.start_ned_m, (3, 3)), atol=0.5)
    # The damaged rotor's command sits above the mean of the others' (it loses 8-12 % thrust).
    assert pwm[1, 0] > pwm[1, 1:].mean() + 5.0
    assert pwm[2, 2] > np.delete(pwm[2], 2).mean() + 2.0
    assert np.ptp(pwm[0]) < 5.0
