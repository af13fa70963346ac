"""Calibration model invariants: trim, the motor lag, the unbalance ratio, term round trips (fast, no simulation)."""

import dataclasses
import math

import numpy as np
import pytest

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.calibrate.physics import G_M_S2, first_order_lag, trim_commands, trim_thrusts
from offline.calibrate.prepare import FINE, euler_rates, rotation_world_body, sg_deriv, upsample
from offline.calibrate.terms import TERMS, apply_terms
from offline.calibrate.unbalance import UnbalanceRatio

NOM = load_vehicle(DEFAULT_VEHICLE)
WEIGHT_N = NOM.mass_kg * G_M_S2


def test_trim_of_symmetric_vehicle_is_equal_thrust_equal_command():
    f = trim_thrusts(NOM, np.array([WEIGHT_N]))[0]
    np.testing.assert_allclose(f, WEIGHT_N / 4, rtol=1e-12)
    cmd = trim_commands(NOM, np.array([WEIGHT_N]))[0]
    assert np.ptp(cmd) < 1e-9
    # and that command gives the paper's hover speed through the ESC curve
    assert float(NOM.esc.cmd_to_omega_rad_s(cmd[0])) == pytest.approx(NOM.hover_omega_rad_s, rel=1e-9)


def test_cg_offset_along_a_diagonal_moves_thrust_within_that_same_spin_pair():
    # Rotor 3 sits front-left (x>0, y<0); a CG towards it loads rotor 3 and unloads rotor 4 (both CW),
    # leaving rotors 1 and 2 alone: the only split that keeps the yaw torques balanced.
    veh = dataclasses.replace(NOM, cg_offset_frd_m=(0.01, -0.01, 0.0))
    f = trim_thrusts(veh, np.array([WEIGHT_N]))[0]
    assert f[2] > WEIGHT_N / 4 > f[3]
    np.testing.assert_allclose(f[:2], WEIGHT_N / 4, rtol=1e-9)
    r = np.array(veh.rotor_positions_frd_m) - np.array(veh.cg_offset_frd_m)
    assert abs(np.sum(-r[:, 1] * f)) < 1e-9 and abs(np.sum(r[:, 0] * f)) < 1e-9
    assert abs(np.sum(veh.spin_sign * f)) < 1e-9


def test_weak_motor_raises_only_its_own_trim_command():
    veh = dataclasses.replace(NOM, motor_efficiency=(1.0, 1.0, 0.9, 1.0))
    base = trim_commands(NOM, np.array([WEIGHT_N]))[0]
    cmd = trim_commands(veh, np.array([WEIGHT_N]))[0]
    assert cmd[2] > base[2] + 20.0
    np.testing.assert_allclose(cmd[[0, 1, 3]], base[[0, 1, 3]], atol=1e-9)


def test_first_order_lag_is_exact_for_a_ramp_and_settles_on_a_step():
    dt, tau = 0.05, 0.03
    t = np.arange(40) * dt
    u = np.where(t > 0, 100.0 + 50.0 * t, 100.0)[:, None] * np.ones(4)
    y = first_order_lag(u, tau, dt)
    # analytic response to 100 + 50 t from rest at 100: u - 50 tau (1 - exp(-t/tau))
    expect = 100.0 + 50.0 * t - 50.0 * tau * (1 - np.exp(-t / tau))
    np.testing.assert_allclose(y[:, 0], expect, rtol=1e-12)
    step = first_order_lag(np.r_[np.zeros(1), np.ones(60)][:, None], tau, 0.005)
    assert step[-1, 0] == pytest.approx(1.0, abs=1e-3)


def test_euler_kinematics_inverts_a_known_rotation_and_cubic_upsampling_keeps_samples():
    t = np.arange(200) * 0.05
    euler = np.stack([0.2 * np.sin(t), 0.15 * np.cos(0.7 * t), 0.3 * t], axis=1)
    deriv = np.stack([0.2 * np.cos(t), -0.105 * np.sin(0.7 * t), 0.3 * np.ones_like(t)], axis=1)
    # body rates from the inverse map, then back: euler_rates must reproduce the derivative
    phi, th = euler[:, 0], euler[:, 1]
    p = deriv[:, 0] - deriv[:, 2] * np.sin(th)
    q = deriv[:, 1] * np.cos(phi) + deriv[:, 2] * np.sin(phi) * np.cos(th)
    r = -deriv[:, 1] * np.sin(phi) + deriv[:, 2] * np.cos(phi) * np.cos(th)
    np.testing.assert_allclose(euler_rates(euler, np.stack([p, q, r], axis=1)), deriv, atol=1e-12)
    R = rotation_world_body(euler)
    np.testing.assert_allclose(np.einsum("tij,tkj->tik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    up = upsample(euler)
    np.testing.assert_allclose(up[::FINE], euler, atol=1e-12)
    d = sg_deriv(euler, 0.05)
    np.testing.assert_allclose(d[10:-10], deriv[10:-10], atol=2e-3)


def test_unbalance_ratio_is_neutral_for_equal_motors_and_slows_a_fast_one():
    w_max = np.full(4, 900.0)
    equal = UnbalanceRatio(ratio=np.ones(4), omega_max_rad_s=w_max)
    np.testing.assert_allclose(equal.speed_scale(np.full((3, 4), 600.0)), 1.0)
    fast4 = UnbalanceRatio(ratio=np.array([1.0, 1.0, 1.0, 1.1]), omega_max_rad_s=w_max)
    s = fast4.speed_scale(np.full((1, 4), 900.0))[0]
    assert s[3] == pytest.approx(1 / 1.1) and np.allclose(s[:3], 1.0)


@pytest.mark.parametrize("name", sorted(TERMS))
def test_each_term_round_trips_through_the_vehicle(name):
    term = TERMS[name]
    x0 = term.get(NOM)
    x = x0 + 0.5 * term.scale(NOM)
    veh = apply_terms(NOM, [term], x)
    if name == "esc_curve":  # the ESC term is relative to the vehicle it is applied to
        rpm = veh.esc.cmd_to_rpm(1500.0)
        assert rpm == pytest.approx(x[0] * float(NOM.esc.cmd_to_rpm(1500.0)) + x[1])
    else:
        np.testing.assert_allclose(term.get(veh), x, rtol=1e-12)
    assert all(math.isfinite(v) for v in term.scale(NOM))


def test_a_signal_worsens_only_beyond_its_noise():
    """The consistency gate: an RMS rise above MAX_SIGNAL_WORSENING counts when it is beyond WORSENING_SE paired
    standard errors (the most our simulator's nominal flights show), and the verdict's figures say how far."""
    from offline.calibrate.fit import MAX_SIGNAL_WORSENING, WORSENING_SE, signal_worsening, worsened_signals

    def worse_of(base, new, corr):
        return worsened_signals(signal_worsening(base, new, mask, corr))

    rng = np.random.default_rng(1)
    n = 2000
    base = rng.normal(size=n)
    mask = [np.ones(n, dtype=bool)]
    # 2000 independent samples: a 10 % RMS rise is many standard errors.
    worse = base * 1.1
    assert worse_of([{"pitch_accel_rad_s2": base}], [{"pitch_accel_rad_s2": worse}], {}) == ["pitch_accel_rad_s2"]
    ratio, z = signal_worsening([{"pitch_accel_rad_s2": base}], [{"pitch_accel_rad_s2": worse}], mask, {})["pitch_accel_rad_s2"]
    assert ratio == pytest.approx(1.1, rel=1e-3) and z > WORSENING_SE
    # The same data as a 1 s-bandwidth channel (correlation time 400 samples: 5 independent ones): a 4 % rise
    # made of noise is not a worse fit.
    noisy = base + 0.3 * rng.normal(size=n)
    assert np.sqrt(np.mean(noisy**2) / np.mean(base**2)) > MAX_SIGNAL_WORSENING
    assert worse_of([{"accel_d_m_s2": base}], [{"accel_d_m_s2": noisy}], {"accel_d_m_s2": 400.0}) == []
    assert worse_of([{"accel_d_m_s2": base}], [{"accel_d_m_s2": noisy}], {"accel_d_m_s2": 1.0}) == ["accel_d_m_s2"]
    # Below the ratio nothing counts, however many samples.
    assert worse_of([{"accel_d_m_s2": base}], [{"accel_d_m_s2": base * 1.01}], {}) == []
