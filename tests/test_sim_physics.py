"""Physics of offline.sim.dynamics, checked against hand calculations."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from monitor.esc import PAPER_ESC
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.sim.dynamics import GRAVITY_M_S2, Dynamics, VehicleState
from offline.sim.propeller import QuadraticPropeller
from offline.sim.quat import quat_from_euler, quat_mul, quat_to_euler, rotate_body_to_world

DT = 1.0 / 400


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(DEFAULT_VEHICLE)


def rig(vehicle, omega=None, thrust_scale=None, torque_scale=None, n=1):
    omega = vehicle.hover_omega_rad_s if omega is None else omega
    dyn = Dynamics(vehicle, np.full(n, vehicle.mass_kg), DT)
    state = VehicleState.hover(n, (0.0, 0.0, -10.0), np.full(4, omega, dtype=float))
    prop = QuadraticPropeller.for_vehicle(vehicle, thrust_scale, torque_scale)
    prop.reset(state.omega_rad_s)
    return dyn, state, prop


def test_hover_equilibrium_matches_the_paper(vehicle):
    # 4 kF w^2 = m g  ->  w = sqrt(1.5 * 9.80665 / (4 * 1.076e-5)) = 583.8 rad/s ("about 585").
    w = math.sqrt(1.5 * 9.80665 / (4 * 1.076e-5))
    assert vehicle.hover_omega_rad_s == pytest.approx(w)
    assert 580 < w < 590
    pwm = float(PAPER_ESC.omega_rad_s_to_cmd(w))
    assert 1360 < pwm < 1375  # the paper's "about 1368"
    dyn, s, prop = rig(vehicle)
    target = s.omega_rad_s.copy()
    for _ in range(400):
        dyn.step(s, target, prop)
    # Weight balanced: the vehicle neither climbs nor sinks, nor turns.
    assert np.abs(s.vel_ned_m_s).max() < 1e-9
    assert np.abs(s.rates_frd_rad_s).max() < 1e-12


def test_free_fall_accelerates_at_g(vehicle):
    dyn, s, prop = rig(vehicle, omega=0.0)
    target = np.zeros((1, 4))
    n = 400
    for _ in range(n):
        dyn.step(s, target, prop)
    t = n * DT
    assert s.vel_ned_m_s[0, 2] == pytest.approx(GRAVITY_M_S2 * t, rel=1e-12)
    # Semi-implicit Euler: z_n = g dt^2 n (n + 1) / 2, within dt of 1/2 g t^2.
    assert s.pos_ned_m[0, 2] - (-10.0) == pytest.approx(GRAVITY_M_S2 * DT**2 * n * (n + 1) / 2, rel=1e-12)
    assert s.pos_ned_m[0, 2] - (-10.0) == pytest.approx(0.5 * GRAVITY_M_S2 * t * t, rel=2 / n)
    assert np.abs(s.pos_ned_m[0, :2]).max() == 0.0


def test_known_thrust_imbalance_gives_tau_over_inertia(vehicle):
    # Rotor 1 (front right, at x = y = +0.1131 m) makes 10 % more thrust.
    scale = np.array([[1.1, 1.0, 1.0, 1.0]])
    dyn, s, prop = rig(vehicle, thrust_scale=scale)
    w = vehicle.hover_omega_rad_s
    dyn.step(s, s.omega_rad_s.copy(), prop)
    extra = 0.1 * vehicle.kf_n_per_rad_s2 * w * w
    d = 0.16 / math.sqrt(2)
    ixx, iyy, _ = vehicle.inertia_diag_kg_m2
    # The right side lifts: roll left (negative in FRD); the nose lifts: pitch up (positive).
    assert s.rates_frd_rad_s[0, 0] == pytest.approx(-extra * d / ixx * DT, rel=1e-4)
    assert s.rates_frd_rad_s[0, 1] == pytest.approx(extra * d / iyy * DT, rel=1e-4)
    assert abs(s.rates_frd_rad_s[0, 2]) < 1e-15


def test_symmetric_rotors_give_zero_moment(vehicle):
    for omega in (300.0, vehicle.hover_omega_rad_s, 900.0):
        dyn, s, prop = rig(vehicle, omega=omega)
        for _ in range(200):
            dyn.step(s, s.omega_rad_s.copy(), prop)
        assert np.abs(s.rates_frd_rad_s).max() < 1e-12
        np.testing.assert_allclose(s.q_world_body[0], [1, 0, 0, 0], atol=1e-12)


def test_more_ccw_torque_yaws_nose_right(vehicle):
    # Rotors 1 and 2 spin CCW (PX4 quad-X): their reaction torque turns the body clockwise seen
    # from above, i.e. nose right, +z in FRD.
    assert list(vehicle.rotor_spin) == ["ccw", "ccw", "cw", "cw"]
    scale = np.array([[1.2, 1.2, 1.0, 1.0]])
    dyn, s, prop = rig(vehicle, torque_scale=scale)
    w = vehicle.hover_omega_rad_s
    for _ in range(40):
        dyn.step(s, s.omega_rad_s.copy(), prop)
    net = 2 * 0.2 * vehicle.ktau_nm_per_rad_s2 * w * w
    assert s.rates_frd_rad_s[0, 2] == pytest.approx(net / vehicle.inertia_diag_kg_m2[2] * 40 * DT, rel=1e-9)
    assert quat_to_euler(s.q_world_body)[2][0] > 0
    # And the opposite pair the other way.
    dyn, s, prop = rig(vehicle, torque_scale=np.array([[1.0, 1.0, 1.2, 1.2]]))
    for _ in range(40):
        dyn.step(s, s.omega_rad_s.copy(), prop)
    assert s.rates_frd_rad_s[0, 2] < 0


def test_torque_free_rotation_conserves_world_angular_momentum(vehicle):
    # With no forces, L_world = R I w is constant (Euler's equations); a wrong-signed gyroscopic
    # term keeps |L| and the energy but turns L in the world.
    dyn, s, prop = rig(vehicle, omega=0.0)
    s.rates_frd_rad_s[:] = [[3.0, 0.5, 2.0]]
    inertia = np.array(vehicle.inertia_diag_kg_m2)
    l0 = rotate_body_to_world(s.q_world_body, inertia * s.rates_frd_rad_s)
    dyn400 = Dynamics(vehicle, np.array([vehicle.mass_kg]), 1.0 / 4000)  # small step for a tight check
    for _ in range(4000):
        dyn400.step(s, np.zeros((1, 4)), prop)
    l1 = rotate_body_to_world(s.q_world_body, inertia * s.rates_frd_rad_s)
    np.testing.assert_allclose(l1, l0, atol=5e-3 * np.linalg.norm(l0))
    assert np.linalg.norm(s.q_world_body) == pytest.approx(1.0, abs=1e-12)


def test_motor_lag_is_first_order_with_the_configured_time_constant(vehicle):
    dyn, s, prop = rig(vehicle, omega=400.0)
    tau = vehicle.motor_time_constant_s
    steps = int(round(tau / DT))
    target = np.full((1, 4), 800.0)
    for _ in range(steps):
        dyn.step(s, target, prop)
    # After one time constant: 1 - 1/e of the step.
    assert s.omega_rad_s[0, 0] == pytest.approx(400 + 400 * (1 - math.exp(-1)), rel=1e-9)


def test_thrust_tilted_by_attitude(vehicle):
    # Rolled 30 deg right at hover speed: the thrust's horizontal part pushes east.
    dyn, s, prop = rig(vehicle)
    s.q_world_body[:] = quat_from_euler(math.radians(30), 0.0, 0.0)
    dyn.step(s, s.omega_rad_s.copy(), prop)
    acc = s.vel_ned_m_s[0] / DT
    g = GRAVITY_M_S2
    np.testing.assert_allclose(acc, [0.0, g * math.sin(math.radians(30)), g * (1 - math.cos(math.radians(30)))], atol=1e-9)


def test_quaternion_helpers_agree():
    rng = np.random.default_rng(0)
    e = rng.uniform(-1, 1, (5, 3))
    q = quat_from_euler(e[:, 0], e[:, 1], e[:, 2])
    np.testing.assert_allclose(np.stack(quat_to_euler(q), axis=1), e, atol=1e-12)
    qz = quat_from_euler(0.0 * e[:, 0], 0.0 * e[:, 0], e[:, 2])
    qy = quat_from_euler(0.0 * e[:, 0], e[:, 1], 0.0 * e[:, 0])
    qx = quat_from_euler(e[:, 0], 0.0 * e[:, 0], 0.0 * e[:, 0])
    np.testing.assert_allclose(quat_mul(quat_mul(qz, qy), qx), q, atol=1e-12)


@pytest.mark.parametrize(
    "term,value",
    [
        ("cg_offset_frd_m", (0.01, 0.0, 0.0)),
        ("motor_efficiency", (0.9, 1.0, 1.0, 1.0)),
    ],
)
def test_calibration_terms_change_the_moments(vehicle, term, value):
    v = dataclasses.replace(vehicle, **{term: value})
    dyn = Dynamics(v, np.array([v.mass_kg]), DT)
    s = VehicleState.hover(1, (0, 0, -10), np.full(4, v.hover_omega_rad_s))
    prop = QuadraticPropeller.for_vehicle(v)
    prop.reset(s.omega_rad_s)
    for _ in range(20):
        dyn.step(s, dyn.motor_target(np.full((1, 4), v.hover_omega_rad_s)), prop)
    assert np.abs(s.rates_frd_rad_s).max() > 1e-4
    if term == "cg_offset_frd_m":
        # CG moved forward: the rear rotors get longer arms, the nose drops (negative pitch rate).
        assert s.rates_frd_rad_s[0, 1] < 0
    else:
        # Rotor 1 (front right) slower: right side and nose drop (positive roll, negative pitch).
        assert s.rates_frd_rad_s[0, 0] > 0 and s.rates_frd_rad_s[0, 1] < 0


def test_drag_and_wind_push_a_level_vehicle_downwind(vehicle):
    v = dataclasses.replace(vehicle, linear_drag_n_per_m_s=(0.3, 0.3, 0.0), wind_ned_m_s=(5.0, 0.0, 0.0))
    dyn = Dynamics(v, np.array([v.mass_kg]), DT)
    s = VehicleState.hover(1, (0, 0, -10), np.full(4, v.hover_omega_rad_s))
    prop = QuadraticPropeller.for_vehicle(v)
    prop.reset(s.omega_rad_s)
    dyn.step(s, s.omega_rad_s.copy(), prop)
    assert s.vel_ned_m_s[0, 0] == pytest.approx(0.3 * 5.0 / v.mass_kg * DT, rel=1e-9)
    assert abs(s.vel_ned_m_s[0, 1]) < 1e-15
