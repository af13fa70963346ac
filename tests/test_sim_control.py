"""The PX4-like controller flies the simulated vehicle: hover, missions, a weak rotor, seeds, batches."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from monitor.esc import RPM_PER_RAD_S
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.sim.mission import START_NED_M, random_waypoints, waypoint_set
from offline.sim.propeller import QuadraticPropeller
from offline.sim.simulator import SimConfig, simulate

QUIET = SimConfig(gyro_noise_std_rad_s=0.0, attitude_noise_std_rad=0.0)


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(DEFAULT_VEHICLE)


def hover_waypoints(n=1):
    return np.broadcast_to(START_NED_M, (n, 1, 3)).copy()


def fly(vehicle, wps, sim=QUIET, thrust_scale=None, **kw):
    return simulate(vehicle, wps, QuadraticPropeller.for_vehicle(vehicle, thrust_scale), sim, **kw)


def test_hover_holds_position_at_the_paper_hover_point(vehicle):
    log = fly(vehicle, hover_waypoints(2), dataclasses.replace(QUIET, duration_s=5.0), payload_kg=np.array([0.0, 0.45]))
    tail = slice(-40, None)
    pwm = log.pwm_us[:, tail].mean(axis=(1, 2))
    omega = log.motor_omega_rad_s[:, tail].mean(axis=(1, 2))
    g = 9.80665
    for i, m in enumerate((1.5, 1.95)):
        assert omega[i] == pytest.approx(math.sqrt(m * g / (4 * vehicle.kf_n_per_rad_s2)), rel=2e-3)
        assert np.abs(log.pos_ned_m[i] - START_NED_M).max() < 0.02
        assert log.thrust_n[i, tail].sum(axis=1).mean() == pytest.approx(m * g, rel=1e-3)
    assert 1363 < pwm[0] < 1373  # the paper's hover PWM, about 1368
    assert pwm[1] > pwm[0] + 40
    # The logged target RPM is the ESC fit of the logged PWM, and matches the real speed in hover.
    np.testing.assert_allclose(log.motor_rpm[0, tail], log.motor_omega_rad_s[0, tail] * RPM_PER_RAD_S, rtol=2e-3)


def test_mission_visits_every_waypoint_within_half_a_metre(vehicle):
    wps = np.concatenate([random_waypoints(2, 5, seed=7), waypoint_set("A")[None], waypoint_set("B")[None]])
    log = fly(vehicle, wps, SimConfig(duration_s=80.0))  # default sensor noise on
    for i in range(len(wps)):
        d = np.linalg.norm(log.pos_ned_m[i][:, None, :] - wps[i][None], axis=-1)  # (T, N)
        assert d.min(axis=0).max() <= 0.5, f"flight {i}: closest approach {d.min(axis=0)}"
        # The route is repeated: the first waypoint is flown to again after the fifth.
        idx = log.waypoint_index[i]
        assert np.any((idx[:-1] == 4) & (idx[1:] == 0))
    tilt = np.degrees(np.maximum(np.abs(log.roll_rad), np.abs(log.pitch_rad)))
    assert tilt.max() < 45.0  # MPC_TILTMAX_AIR


def test_stable_with_one_rotor_at_minus_20_percent_thrust(vehicle):
    wps = np.broadcast_to(waypoint_set("A"), (4, 5, 3)).copy()
    scale = np.ones((4, 4)) - 0.2 * np.eye(4)  # flight i has rotor i+1 weakened
    log = fly(vehicle, wps, dataclasses.replace(QUIET, duration_s=40.0), thrust_scale=scale)
    assert np.all(np.isfinite(log.pos_ned_m))
    for i in range(4):
        d = np.linalg.norm(log.pos_ned_m[i][:, None, :] - wps[i][None], axis=-1)
        assert d.min(axis=0).max() <= 0.5
        # The weak rotor is driven harder than the mean of the others: the signature a classifier sees.
        rpm = log.motor_rpm[i, -200:].mean(axis=0)
        assert rpm[i] > np.delete(rpm, i).mean() * 1.05
    assert np.degrees(np.abs(log.roll_rad)).max() < 45 and np.degrees(np.abs(log.pitch_rad)).max() < 45


def test_batch_equals_flights_one_at_a_time(vehicle):
    sim = dataclasses.replace(SimConfig(), duration_s=8.0)
    wps = random_waypoints(3, 5, seed=11)
    payload = np.array([0.0, 0.3, 0.45])
    seeds = np.array([5, 6, 7])
    batch = fly(vehicle, wps, sim, payload_kg=payload, seed=seeds)
    for i in range(3):
        one = fly(vehicle, wps[i : i + 1], sim, payload_kg=payload[i : i + 1], seed=seeds[i : i + 1])
        for name in batch.array_fields():
            a, b = getattr(batch, name), getattr(one, name)
            if name in ("time_s", "timestamp_us"):
                np.testing.assert_array_equal(a, b)
            else:
                np.testing.assert_allclose(a[i], b[0], rtol=1e-9, atol=1e-9, err_msg=name)


def test_same_seed_same_flight_and_seeds_matter(vehicle):
    sim = dataclasses.replace(SimConfig(), duration_s=4.0)
    wps = random_waypoints(2, 5, seed=3)
    a = fly(vehicle, wps, sim, seed=42)
    b = fly(vehicle, wps, sim, seed=42)
    c = fly(vehicle, wps, sim, seed=43)
    for name in a.array_fields():
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert not np.array_equal(a.rates_frd_rad_s, c.rates_frd_rad_s)
    # Flight 0 of an integer seed is the single flight with that seed.
    one = fly(vehicle, wps[:1], sim, seed=42)
    np.testing.assert_allclose(one.pwm_us[0], a.pwm_us[0], rtol=1e-9, atol=1e-9)


def test_gyro_bias_shows_in_the_logged_rates(vehicle):
    bias = (0.02, -0.01, 0.015)
    v = dataclasses.replace(vehicle, gyro_bias_frd_rad_s=bias)
    log = fly(v, hover_waypoints(), dataclasses.replace(QUIET, duration_s=10.0))
    np.testing.assert_allclose(log.rates_frd_rad_s[0, -60:].mean(axis=0), bias, atol=2e-3)
    assert np.abs(log.pos_ned_m[0] - START_NED_M).max() < 0.5


def test_wind_with_drag_tilts_the_hovering_vehicle_into_the_wind(vehicle):
    v = dataclasses.replace(vehicle, linear_drag_n_per_m_s=(0.3, 0.3, 0.1), wind_ned_m_s=(4.0, 0.0, 0.0))
    log = fly(v, hover_waypoints(), dataclasses.replace(QUIET, duration_s=10.0))
    # Air moving north at 4 m/s drags the vehicle north; holding position needs a southward
    # thrust component: nose up, pitch > 0, by atan(D w / (m g)) = atan(0.3 * 4 / (1.5 * 9.81)) = 4.7 deg.
    pitch = np.degrees(log.pitch_rad[0, -40:].mean())
    assert pitch == pytest.approx(math.degrees(math.atan(0.3 * 4.0 / (1.5 * 9.80665))), abs=0.5)
    assert np.abs(log.pos_ned_m[0, -40:] - START_NED_M).max() < 0.2


def test_log_timing_and_shapes(vehicle):
    log = fly(vehicle, hover_waypoints(2), dataclasses.replace(QUIET, duration_s=2.0))
    assert log.timestamp_us.dtype == np.int64
    assert np.all(np.diff(log.timestamp_us) == 50_000)
    assert log.timestamp_us[0] > 1_000_000  # boot clock, not zero at the start
    assert log.pos_ned_m.shape == (2, 40, 3) and log.motor_rpm.shape == (2, 40, 4) and len(log) == 2
    sig = log.signals()
    assert set(sig) == {"motor_rpm", "roll_rad", "pitch_rad", "yaw_rad", "roll_rate_rad_s", "pitch_rate_rad_s", "yaw_rate_rad_s"}
    table = log.select([1]).to_flight_table(0)
    assert table.airborne.all() and len(table) == 40
    np.testing.assert_array_equal(table.motor_cmd, log.pwm_us[1])
    np.testing.assert_array_equal(table.pos_ned_m, log.pos_ned_m[1])
    np.testing.assert_allclose(table.extras["esc_rpm"], log.motor_omega_rad_s[1] * RPM_PER_RAD_S)


def test_bad_propeller_model_and_divergence_fail_by_name(vehicle):
    from monitor.errors import ModelError

    class Flat:
        def reset(self, omega_rad_s):
            pass

        def __call__(self, omega_rad_s, dt_s):
            return np.ones(4), np.ones(4)  # forgot the batch axis

    with pytest.raises(ModelError, match="thrust_n has shape"):
        simulate(vehicle, hover_waypoints(2), Flat(), dataclasses.replace(QUIET, duration_s=1.0))

    class Explodes(QuadraticPropeller):
        def __call__(self, omega_rad_s, dt_s):
            t, q = super().__call__(omega_rad_s, dt_s)
            return t * np.array([[1.0], [np.nan]]), q

    with pytest.raises(ModelError, match=r"flight\(s\) \[1\] diverged"):
        simulate(
            vehicle,
            hover_waypoints(2),
            Explodes(vehicle.kf_n_per_rad_s2, vehicle.ktau_nm_per_rad_s2),
            dataclasses.replace(QUIET, duration_s=1.0),
        )
