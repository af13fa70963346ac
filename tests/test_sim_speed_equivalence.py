"""The simulator's fast paths keep views and work buffers between calls; these check that
one Dynamics/Controller driven with several states gives exactly what fresh objects give."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.sim.controller import Controller, ControllerConfig
from offline.sim.dynamics import Dynamics, VehicleState
from offline.sim.mission import random_waypoints
from offline.sim.propeller import QuadraticPropeller

DT = 1.0 / 400


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(DEFAULT_VEHICLE)


def _state(vehicle, yaw_rad):
    s = VehicleState.hover(2, (0.0, 0.0, -10.0), np.full(4, vehicle.hover_omega_rad_s), yaw_rad=yaw_rad)
    s.rates_frd_rad_s[:] = [[0.3, -0.2, 0.1], [-0.1, 0.4, -0.3]]
    return s


def test_one_dynamics_stepping_two_states_equals_two_dynamics(vehicle):
    mass = np.full(2, vehicle.mass_kg)
    shared, own_a, own_b = (Dynamics(vehicle, mass, DT) for _ in range(3))
    a1, b1, a2, b2 = _state(vehicle, 0.2), _state(vehicle, -1.0), _state(vehicle, 0.2), _state(vehicle, -1.0)
    props = [QuadraticPropeller.for_vehicle(vehicle) for _ in range(4)]
    target = np.array([[600.0, 560.0, 590.0, 575.0], [550.0, 610.0, 580.0, 600.0]])
    for _ in range(50):  # alternate states on the shared object
        shared.step(a1, target, props[0])
        shared.step(b1, target * 0.98, props[1])
        own_a.step(a2, target, props[2])
        own_b.step(b2, target * 0.98, props[3])
    np.testing.assert_array_equal(a1.packed, a2.packed)
    np.testing.assert_array_equal(b1.packed, b2.packed)
    assert not np.array_equal(a1.packed, b1.packed)  # the two states really differ


def test_one_controller_driving_two_states_equals_two_controllers(vehicle):
    mass = np.full(2, vehicle.mass_kg)
    shared, own_a, own_b = (Controller(ControllerConfig(), vehicle, mass, 1 / 50, 1 / 200) for _ in range(3))
    wps = random_waypoints(2, 4, seed=5)
    sa, sb = _state(vehicle, 0.2), _state(vehicle, -1.0)
    sa.vel_ned_m_s[:] = [[1.0, -0.5, 0.2], [0.0, 0.3, -0.1]]
    ca1, cb1, ca2, cb2 = shared.initial_state(2), shared.initial_state(2), own_a.initial_state(2), own_b.initial_state(2)
    gyro = np.array([[0.01, -0.02, 0.005], [0.0, 0.01, -0.01]])
    for _ in range(5):
        for ctrl, c, s in ((shared, ca1, sa), (shared, cb1, sb), (own_a, ca2, sa), (own_b, cb2, sb)):
            err = ctrl.update_position(c, s.pos_ned_m, s.vel_ned_m_s, wps)
            err_copy = err.copy()
            cmd = ctrl.update_attitude(c, s.q_world_body, gyro).copy()
            np.testing.assert_array_equal(err, err_copy)  # the returned error is not a reused buffer
            c.last_cmd = cmd
    for c1, c2 in ((ca1, ca2), (cb1, cb2)):
        np.testing.assert_array_equal(c1.last_cmd, c2.last_cmd)
        np.testing.assert_array_equal(c1.q_sp, c2.q_sp)
        np.testing.assert_array_equal(c1.rate_int, c2.rate_int)
        np.testing.assert_array_equal(c1.vel_int_ned_m_s2, c2.vel_int_ned_m_s2)
    assert not np.array_equal(ca1.q_sp, cb1.q_sp)
