"""Native-rate evidence: motor command activity, vibration energy, the Crazyflie mixer."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.errors import ModelError
from monitor.features import motor_command_activity, vibration_energy
from monitor.logs import read_log
from monitor.logs.mixers import crazyflie_legacy
from monitor.vehicle import REPO_ROOT

CRAZYPAD = REPO_ROOT.parent / "shared" / "data" / "crazypad"
needs_crazypad = pytest.mark.skipif(
    not (CRAZYPAD / "manifest.csv").is_file(), reason=f"CrazyPAD data not found at {CRAZYPAD} (../shared/data/crazypad)"
)


def test_activity_is_std_of_the_step_over_the_mean_command():
    # Motor 1 alternates 1000, 1010 (200 steps of +-10: std 10); the others are constant.
    n = 201
    cmd = np.full((n, 4), 2000.0)
    cmd[:, 0] = 1000.0 + 10.0 * (np.arange(n) % 2)
    act = motor_command_activity(cmd, rate_hz=100.0)
    assert act[0] == pytest.approx(10.0 / np.mean(cmd[:, 0]), rel=1e-12)
    np.testing.assert_array_equal(act[1:], 0.0)
    # Doubling every command (another unit, another weight) leaves it unchanged.
    np.testing.assert_allclose(motor_command_activity(2 * cmd, rate_hz=100.0), act)


def test_activity_ignores_steps_that_leave_the_mask():
    n = 100
    cmd = np.full((n, 4), 1000.0)
    cmd[50:, :] = 0.0  # landed: a 1000-unit step that is not flight
    mask = np.arange(n) < 50
    np.testing.assert_array_equal(motor_command_activity(cmd, 100.0, mask), 0.0)
    assert motor_command_activity(cmd, 100.0)[0] > 0.0


def test_vibration_energy_is_the_mean_square_above_the_band():
    rate, n = 100.0, 1000
    t = np.arange(n) / rate
    slow = 3.0 * np.sin(2 * np.pi * 1.0 * t)  # manoeuvre: below the band
    fast = 0.5 * np.sin(2 * np.pi * 30.0 * t)  # vibration: A^2/2 = 0.125
    acc = np.stack([slow + fast, slow, np.zeros(n)], axis=1)
    assert vibration_energy(acc, rate) == pytest.approx(0.125, rel=1e-9)
    assert vibration_energy(np.stack([slow] * 3, axis=1), rate) == pytest.approx(0.0, abs=1e-20)
    # Batched: a leading flight axis.
    both = np.stack([acc, 2 * acc])
    np.testing.assert_allclose(vibration_energy(both, rate), [0.125, 0.5])


def test_native_features_refuse_a_slow_stream():
    with pytest.raises(ModelError, match="50 Hz"):
        motor_command_activity(np.ones((10, 4)), rate_hz=20.0)
    with pytest.raises(ModelError, match="band_hz"):
        vibration_energy(np.ones((10, 3)), rate_hz=100.0, band_hz=60.0)


def test_crazyflie_mixer_by_hand():
    # powerDistributionLegacy: r = trunc(roll/2), p = trunc(pitch/2).
    m = crazyflie_legacy([40000.0], [1001.0], [-301.0], [200.0])[0]
    r, p, y = 500.0, -150.0, 200.0
    np.testing.assert_array_equal(m, [40000 - r + p + y, 40000 - r - p - y, 40000 + r - p + y, 40000 + r + p - y])
    # Positive roll (right wing down) lowers the right motors M1, M2; a symmetric command gives equal motors.
    assert m[0] < m[3] and m[1] < m[2]
    np.testing.assert_array_equal(crazyflie_legacy([30000.0], [0.0], [0.0], [0.0])[0], 30000.0)
    # powerDistributionCap: above 65535 every motor drops by the excess, none goes below 0.
    capped = crazyflie_legacy([65000.0], [0.0], [0.0], [2000.0])[0]
    np.testing.assert_array_equal(capped, [65535.0, 61535.0, 65535.0, 61535.0])
    assert crazyflie_legacy([100.0], [0.0], [0.0], [500.0])[0].min() == 0.0


@pytest.mark.realdata
@needs_crazypad
@pytest.mark.parametrize("condition", ["normal_flight", "cut_propeller_M3_3mm"])
def test_rebuilt_commands_match_motor_logs_of_the_same_condition(condition):
    # Controller and motor logs are separate flights of the same script: the rebuilt per-motor
    # shares (airborne means) must agree with the logged ones within the flight-to-flight spread.
    def shares(log_type, fmt, airframe):
        out = []
        for path in sorted((CRAZYPAD / log_type / condition).glob(f"{airframe}_log*.csv.gz"))[:3]:
            try:
                t = read_log(path, fmt=fmt)
            except Exception:
                continue  # the README's quirky files hold the other config
            c = np.nanmean(t.motor_cmd[t.airborne], axis=0)
            out.append(c / c.mean())
        return np.mean(out, axis=0)

    for airframe in ("E8", "E9"):
        rebuilt = shares("controller", "crazypad-controller", airframe)
        logged = shares("motor", "crazypad", airframe)
        np.testing.assert_allclose(rebuilt, logged, atol=0.025, err_msg=f"{condition} {airframe}")
        # The pattern, not just the level: M3 (PX4 rotor 2) is each airframe's strongest-loaded motor.
        assert np.argmax(rebuilt) == np.argmax(logged) == 1


def test_best_threshold_counts_the_misplaced_flights():
    from offline.crazypad.evidence import _best_threshold_errors

    assert _best_threshold_errors(np.array([0.0, 1.0, 2.0]), np.array([3.0, 4.0])) == 0
    assert _best_threshold_errors(np.array([3.0, 4.0]), np.array([0.0, 1.0, 2.0])) == 0  # either direction
    assert _best_threshold_errors(np.array([0.0, 3.5, 2.0]), np.array([3.0, 4.0])) == 1


@pytest.mark.realdata
@needs_crazypad
def test_flight_evidence_of_a_real_flight():
    from offline.crazypad.data import load_manifest
    from offline.crazypad.evidence import flight_evidence

    flights = {f.file: f for f in load_manifest(CRAZYPAD)}
    healthy = flight_evidence(flights["motor/normal_flight/E9_log00.csv.gz"], CRAZYPAD)
    heavy = flight_evidence(flights["motor/add_weight_W3_near_M3/E9_log00.csv.gz"], CRAZYPAD)
    assert healthy.shares.sum() == pytest.approx(4.0)
    assert np.all(np.isfinite(healthy.activity)) and healthy.vibration > 0
    # A 3-g mass near M3 loads M3 (README: share 1.204 vs 1.080 healthy).
    assert heavy.shares[2] > healthy.shares[2] + 0.1
    # The 100 Hz response-gain fit (estimator roll twice differentiated: motor logs hold no rate) explains part of
    # the roll acceleration (R^2 0.3-0.5 on the healthy motor logs) and gives four relative gains averaging 1.
    assert 0.1 < healthy.roll_gain_r2 < 1.0
    assert np.mean(healthy.roll_gain) == pytest.approx(1.0)
    assert all(np.isfinite(v) for v in healthy.couplings.values())
