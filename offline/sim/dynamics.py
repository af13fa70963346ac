"""6-DOF rigid-body dynamics of a quadrotor, batched over flights (leading axis).

World NED, body FRD, quaternion scalar-first rotating body into world. One
``step`` advances every flight by ``dt_s`` with semi-implicit (symplectic)
Euler: velocity first, then position with the new velocity, which keeps a
hovering vehicle's energy from drifting; the attitude advances with the rates
at the start of the step and is renormalised every step.

Every calibration term of ``VehicleConfig`` acts here:
- ``motor_time_constant_s``: first-order lag of rotor speed towards its target
  (rotor i: times ``motor_time_constant_ratio[i]``),
  discretised exactly (zero-order hold) so any physics rate is stable;
- ``motor_efficiency``: scales the speed a rotor reaches for its command (the
  ESC/motor gives less speed than the fit says, as a worn motor or sagging ESC);
- ``cg_offset_frd_m``: the rotors' lever arms are measured from the shifted CG;
- ``linear_drag_n_per_m_s``: body-axis drag on the airspeed (velocity minus
  ``wind_ned_m_s``); with zero drag the wind cannot act and is skipped;
- per-flight physics only: parasitic drag ``-c |v_air| v_air`` per body axis
  (``quadratic_drag_n_per_m2_s2``) and blade flapping;
- ``rotor_inertia_kg_m2``: the spin-up yaw reaction J dω/dt (a rotor accelerated by its motor twists the body
  the way its drag torque does);
- mass (plus per-flight payload, a point mass at the CG) and inertia.
``gyro_bias_frd_rad_s`` is a sensor term and acts in ``simulator``.

The step is written for speed with few, large numpy operations into
preallocated buffers: products of quaternions and rates are bilinear maps
(outer product, then one matmul; see ``quat``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from monitor.vehicle import GRAVITY_M_S2, VehicleConfig
from offline.sim.quat import rotate_body_to_world, rotate_world_to_body, rotation_matrices, state_products_map


@dataclass
class VehicleState:
    """Mutable state of B flights, updated in place.

    Position, velocity, attitude and rates live side by side in ``packed`` (B, 13) and the
    named fields are views of it, so one step can update attitude and rates in one operation.
    """

    packed: np.ndarray  # (B, 13): pos_ned_m (3), vel_ned_m_s (3), q_world_body (4), rates_frd_rad_s (3)
    omega_rad_s: np.ndarray  # (B, 4) actual rotor speeds
    pos_ned_m: np.ndarray = field(init=False, repr=False)  # (B, 3)
    vel_ned_m_s: np.ndarray = field(init=False, repr=False)  # (B, 3)
    q_world_body: np.ndarray = field(init=False, repr=False)  # (B, 4)
    rates_frd_rad_s: np.ndarray = field(init=False, repr=False)  # (B, 3) true body rates

    def __post_init__(self) -> None:
        p = self.packed
        if p.ndim != 2 or p.shape[1] != 13:
            raise ValueError(f"VehicleState.packed: expected (B, 13), got {p.shape}")
        self.pos_ned_m, self.vel_ned_m_s = p[:, 0:3], p[:, 3:6]
        self.q_world_body, self.rates_frd_rad_s = p[:, 6:10], p[:, 10:13]

    @classmethod
    def hover(cls, n: int, pos_ned_m, omega_rad_s: np.ndarray, yaw_rad: float = 0.0) -> VehicleState:
        packed = np.zeros((n, 13))
        packed[:, 0:3] = np.asarray(pos_ned_m, dtype=np.float64)
        packed[:, 6], packed[:, 9] = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
        return cls(packed, np.broadcast_to(np.asarray(omega_rad_s, dtype=np.float64), (n, 4)).copy())


def _step_map(dt: float, inertia_diag_kg_m2: np.ndarray, arms: np.ndarray, spin_sign) -> np.ndarray:
    """(57, 11): features [vec(x outer x) (49), thrust (4), drag torque (4)], x = [q, w], map to
    [dq (4), dw (3), -dt R[:, 2] (3), total thrust (1)]."""
    ixx, iyy, izz = inertia_diag_kg_m2
    # Euler's equations for a diagonal inertia: wdot_i += k_i w_j w_k (i, j, k cyclic).
    gyro = np.zeros((3, 3, 3))
    gyro[1, 2, 0] = (iyy - izz) / ixx
    gyro[2, 0, 1] = (izz - ixx) / iyy
    gyro[0, 1, 2] = (ixx - iyy) / izz
    # A thrust T along -z at (x, y, z) from the CG gives the moment (x, y, z) x (0, 0, -T) = (-y T, x T, 0); a drag
    # torque's yaw moment is spin_sign * torque (a CCW rotor yaws the nose right, +z FRD).
    products = state_products_map(dt, gyro.reshape(9, 3))  # (49, 10): [-dt z (3), dq (4), gyro dw (3)]
    m = np.zeros((57, 11))
    m[:49, 0:4] = products[:, 3:7]
    m[:49, 4:7] = products[:, 7:10]
    m[:49, 7:10] = products[:, 0:3]
    m[49:53, 4] = -dt * arms[:, 1] / ixx
    m[49:53, 5] = dt * arms[:, 0] / iyy
    m[49:53, 10] = 1.0
    m[53:57, 6] = dt * np.asarray(spin_sign) / izz
    return m


class Dynamics:
    """Forces, moments and integration for a batch of one vehicle type."""

    def __init__(self, vehicle: VehicleConfig, mass_kg: np.ndarray, dt_s: float, per_flight=None):
        """``per_flight`` (``offline.sim.perflight.PerFlightTerms``): each flight's own inertia, arms, motor,
        drag and wind instead of the vehicle's; None keeps the fixed path (bit-identical to before)."""
        self.dt_s = dt = float(dt_s)
        self.mass_kg = np.asarray(mass_kg, dtype=np.float64).reshape(-1)
        n = len(self.mass_kg)
        self.inv_mass = (1.0 / self.mass_kg)[:, None]
        self.per_flight = per_flight
        if per_flight is None:
            arms = np.array(vehicle.rotor_positions_frd_m, dtype=np.float64) - np.array(vehicle.cg_offset_frd_m)
            self.step_map = _step_map(dt, np.array(vehicle.inertia_diag_kg_m2, dtype=np.float64), arms, vehicle.spin_sign)
        else:
            if per_flight.n != n:
                raise ValueError(f"per_flight: {per_flight.n} flights for a batch of {n}")
            arms = per_flight.rotor_positions_frd_m - per_flight.cg_offset_frd_m[:, None, :]
            self.step_map = np.stack(
                [_step_map(dt, per_flight.inertia_diag_kg_m2[b], arms[b], vehicle.spin_sign) for b in range(n)]
            )  # (B, 57, 11): one map per flight, applied as a batched matmul
        # One slow motor (a calibrated motor_time_constant_ratio) gets its own lag; else one scalar.
        ratio = np.asarray(vehicle.motor_time_constant_ratio, dtype=np.float64)
        self.motor_alpha = 1.0 - math.exp(-dt / vehicle.motor_time_constant_s)
        if np.any(ratio != 1.0):
            self.motor_alpha = 1.0 - np.exp(-dt / (vehicle.motor_time_constant_s * ratio))
        self.efficiency = np.array(vehicle.motor_efficiency, dtype=np.float64)
        self.drag = np.array(vehicle.linear_drag_n_per_m_s, dtype=np.float64)
        self.wind_ned_m_s = np.array(vehicle.wind_ned_m_s, dtype=np.float64)
        self.has_drag = bool(np.any(self.drag > 0))
        self.gravity_dt = np.array([0.0, 0.0, GRAVITY_M_S2 * dt])
        # Preallocated work buffers; the outer product is written straight into the features.
        self._features = np.zeros((n, 57))
        self._outer = self._features[:, :49].reshape(n, 7, 7)
        assert np.shares_memory(self._outer, self._features)
        self._out = np.empty((n, 11))
        self._q4 = np.empty((n, 4))
        self._ones4 = np.ones(4)
        # Fixed views of the buffers, made once: at a handful of flights a view costs as much as the
        # arithmetic it feeds.
        self._f_thrust, self._f_torque = self._features[:, 49:53], self._features[:, 53:57]
        self._d_att, self._d_zdt, self._d_total = self._out[:, :7], self._out[:, 7:10], self._out[:, 10:11]
        self._total_thrust = self._out[:, 10]
        self._om4 = np.empty((n, 4))
        self._t1 = np.empty((n, 1))
        self._dv = np.empty((n, 3))
        self._v3 = np.empty((n, 3))
        self._norm = np.empty(n)
        self._norm_col = self._norm[:, None]
        self._state_views = (None, None, None, None)  # (packed, [q, w] view, as a column, as a row)
        # Scalars as 0-d arrays: numpy takes those faster than Python floats (same float64 values).
        self._alpha0, self._dt0 = np.array(self.motor_alpha), np.array(dt)
        self.force_body_n = np.zeros((n, 3))  # non-gravity force of the last step with drag, body FRD
        self.last_total_thrust_n = np.zeros(n)
        self.esc_offset_rad_s = None
        self.spin_up = None  # rotor inertia / dt, (B, 1): the spin-up yaw reaction J dω/dt
        if vehicle.rotor_inertia_kg_m2 > 0:
            self.spin_up = np.full((n, 1), vehicle.rotor_inertia_kg_m2 / dt)
        self.flap_dt_over_inertia = None  # (B, 2) k dt / (Ixx, Iyy): blade flapping (per-flight physics only)
        self.quad_drag = None  # (B, 3) parasitic drag, N per (m/s)^2 (per-flight physics only)
        if per_flight is not None:
            pf = per_flight
            self.motor_alpha = 1.0 - np.exp(-dt / (pf.motor_time_constant_s[:, None] * (ratio if np.any(ratio != 1.0) else 1.0)))
            self._alpha0 = self.motor_alpha
            self.efficiency = pf.motor_efficiency.copy()
            self.esc_offset_rad_s = pf.esc_offset_rad_s.copy()
            self.drag = pf.linear_drag_n_per_m_s.copy()
            self.wind_ned_m_s = np.broadcast_to(pf.wind_mean_ned_m_s, (n, 3)).copy()  # rewritten with gusts
            qd = pf.quadratic_drag_n_per_m2_s2
            self.quad_drag = qd.copy() if qd is not None and np.any(qd > 0) else None  # (B, 3), N per (m/s)^2
            self.has_drag = bool(np.any(self.drag > 0)) or self.quad_drag is not None
            self.voltage_scale = np.ones((n, 1))  # (V / V_full)^k, rewritten by the simulator
            self.spin_up = (pf.rotor_inertia_kg_m2 / dt)[:, None] if np.any(pf.rotor_inertia_kg_m2 > 0) else None
            k = pf.flapping_nm_per_rad_s_m_s
            if k is not None and np.any(k > 0):
                # Blade flapping's moment k sum(omega) (-v_right, +v_forward, 0) (body FRD airspeed) turned into
                # a rate increment per step: dt / I per axis.
                self.flap_dt_over_inertia = (np.asarray(k, dtype=np.float64) * dt)[:, None] / pf.inertia_diag_kg_m2[:, :2]
            self._out3 = np.empty((n, 1, 11))
            self._out = self._out3[:, 0, :]
            self._d_att, self._d_zdt, self._d_total = self._out[:, :7], self._out[:, 7:10], self._out[:, 10:11]
            self._total_thrust = self._out[:, 10]
            self._features3 = self._features[:, None, :]

    def specific_force_frd_m_s2(self) -> np.ndarray:
        """What an IMU at the CG measures after the last step: non-gravity force / mass, body FRD."""
        if not self.has_drag:
            self.force_body_n[:, 2] = -self.last_total_thrust_n
        return self.force_body_n * self.inv_mass

    def motor_target(self, omega_cmd_rad_s: np.ndarray) -> np.ndarray:
        """Speed each rotor settles at for a commanded speed (per-motor efficiency; per flight also the
        ESC offset and the battery-voltage scale)."""
        if self.esc_offset_rad_s is None:
            return omega_cmd_rad_s * self.efficiency
        out = omega_cmd_rad_s * self.efficiency
        out += self.esc_offset_rad_s
        out *= self.voltage_scale
        return np.maximum(out, 0.0, out=out)

    def step(self, s: VehicleState, omega_target_rad_s: np.ndarray, propellers) -> tuple[np.ndarray, np.ndarray]:
        """Advance ``s`` by dt in place; returns this step's (thrust_n, torque_nm)."""
        dt = self.dt_s
        om = s.omega_rad_s
        # Outputs are passed positionally (out=... costs a keyword parse on every call).
        d = np.subtract(omega_target_rad_s, om, self._om4)
        d *= self._alpha0
        om += d
        thrust, torque = propellers(om, dt)
        self._f_thrust[...] = thrust
        self._f_torque[...] = torque
        if self.spin_up is not None:
            # Accelerating a rotor takes motor torque; its reaction on the body has the drag torque's sign.
            self._f_torque += np.multiply(self.spin_up, d, d)
        p, x, x_col, x_row = self._state_views
        if p is not s.packed:  # [q, w] and its broadcasting views, made once per state array
            p = s.packed
            x = p[:, 6:13]
            p, x, x_col, x_row = self._state_views = (p, x, x[:, :, None], x[:, None, :])
        np.multiply(x_col, x_row, self._outer)
        if self.per_flight is None:
            out = np.matmul(self._features, self.step_map, self._out)
        else:
            np.matmul(self._features3, self.step_map, self._out3)
            out = self._out
        self.last_total_thrust_n = self._total_thrust

        # Linear, with the attitude at the start of the step: dv = dt (R f_body / m + g).
        v_air = None  # body-frame airspeed, when a per-flight term needs it (drag, blade flapping)
        if self.per_flight is not None and (self.has_drag or self.flap_dt_over_inertia is not None):
            rot = rotation_matrices(s.q_world_body)
            v_air = np.matmul((s.vel_ned_m_s - self.wind_ned_m_s)[:, None, :], rot)[:, 0]
        if self.has_drag and self.per_flight is not None:
            # The same formula through one rotation matrix per flight (np.cross is slow on small batches).
            f_body = self.force_body_n
            f_body[:, :2] = 0.0
            f_body[:, 2] = -out[:, 10]
            f_body -= self.drag * v_air
            if self.quad_drag is not None:  # parasitic drag: -c |v| v per body axis
                f_body -= self.quad_drag * np.sqrt(np.einsum("bi,bi->b", v_air, v_air))[:, None] * v_air
            dv = np.matmul(rot, f_body[:, :, None])[:, :, 0] * (self.inv_mass * dt)
        elif self.has_drag:
            q, v = s.q_world_body, s.vel_ned_m_s
            f_body = self.force_body_n
            f_body[:, :2] = 0.0
            f_body[:, 2] = -out[:, 10]
            f_body -= self.drag * rotate_world_to_body(q, v - self.wind_ned_m_s)
            dv = rotate_body_to_world(q, f_body) * (self.inv_mass * dt)
        else:
            dv = np.multiply(self._d_zdt, np.multiply(self._d_total, self.inv_mass, self._t1), self._dv)
        dv += self.gravity_dt

        if self.flap_dt_over_inertia is not None:
            # Blowback: nose-up flying forward, rolled away from a side flow (left for flow from the right).
            sum_om = om.sum(axis=1)
            self._d_att[:, 4] -= self.flap_dt_over_inertia[:, 0] * sum_om * v_air[:, 1]
            self._d_att[:, 5] += self.flap_dt_over_inertia[:, 1] * sum_om * v_air[:, 0]
        x += self._d_att  # attitude and rates, explicit Euler from the start-of-step values
        v = s.vel_ned_m_s
        v += dv
        s.pos_ned_m += np.multiply(self._dt0, v, self._v3)  # semi-implicit: the new velocity moves the vehicle
        q = s.q_world_body
        # Row norms through a matmul: several times cheaper than einsum on small batches.
        norm = np.matmul(np.multiply(q, q, self._q4), self._ones4, self._norm)
        np.sqrt(norm, norm)
        q /= self._norm_col
        return thrust, torque
