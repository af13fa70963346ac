"""6-DOF rigid-body dynamics of a quadrotor, batched over flights (leading axis).

World NED, body FRD, quaternion scalar-first rotating body into world. One
``step`` advances every flight by ``dt_s`` with semi-implicit (symplectic)
Euler: velocity first, then position with the new velocity, which keeps a
hovering vehicle's energy from drifting; the attitude advances with the rates
at the start of the step and is renormalised every step.

Every calibration term of ``VehicleConfig`` acts here:
- ``motor_time_constant_s``: first-order lag of rotor speed towards its target,
  discretised exactly (zero-order hold) so any physics rate is stable;
- ``motor_efficiency``: scales the speed a rotor reaches for its command (the
  ESC/motor gives less speed than the fit says, as a worn motor or sagging ESC);
- ``cg_offset_frd_m``: the rotors' lever arms are measured from the shifted CG;
- ``linear_drag_n_per_m_s``: body-axis drag on the airspeed (velocity minus
  ``wind_ned_m_s``); with zero drag the wind cannot act and is skipped;
- mass (plus per-flight payload, a point mass at the CG) and inertia.
``gyro_bias_frd_rad_s`` is a sensor term and acts in ``simulator``.

The step is written for speed with few, large numpy operations into
preallocated buffers: products of quaternions and rates are bilinear maps
(outer product, then one matmul; see ``quat``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from monitor.vehicle import VehicleConfig
from offline.sim.quat import rotate_body_to_world, rotate_world_to_body, state_products_map

GRAVITY_M_S2 = 9.80665  # standard gravity (ISO 80000-3), PX4 CONSTANTS_ONE_G


@dataclass
class VehicleState:
    """Mutable state of B flights; the arrays are updated in place."""

    pos_ned_m: np.ndarray  # (B, 3)
    vel_ned_m_s: np.ndarray  # (B, 3)
    q_world_body: np.ndarray  # (B, 4)
    rates_frd_rad_s: np.ndarray  # (B, 3) true body rates
    omega_rad_s: np.ndarray  # (B, 4) actual rotor speeds

    @classmethod
    def hover(cls, n: int, pos_ned_m, omega_rad_s: np.ndarray, yaw_rad: float = 0.0) -> VehicleState:
        q = np.zeros((n, 4))
        q[:, 0], q[:, 3] = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
        return cls(
            pos_ned_m=np.broadcast_to(np.asarray(pos_ned_m, dtype=np.float64), (n, 3)).copy(),
            vel_ned_m_s=np.zeros((n, 3)),
            q_world_body=q,
            rates_frd_rad_s=np.zeros((n, 3)),
            omega_rad_s=np.broadcast_to(np.asarray(omega_rad_s, dtype=np.float64), (n, 4)).copy(),
        )


class Dynamics:
    """Forces, moments and integration for a batch of one vehicle type."""

    def __init__(self, vehicle: VehicleConfig, mass_kg: np.ndarray, dt_s: float):
        self.dt_s = dt = float(dt_s)
        self.mass_kg = np.asarray(mass_kg, dtype=np.float64).reshape(-1)
        n = len(self.mass_kg)
        self.inv_mass = (1.0 / self.mass_kg)[:, None]
        inertia = np.array(vehicle.inertia_diag_kg_m2, dtype=np.float64)
        ixx, iyy, izz = inertia
        arms = np.array(vehicle.rotor_positions_frd_m, dtype=np.float64) - np.array(vehicle.cg_offset_frd_m)
        # [thrust (4), drag torque (4)] @ wrench_map = [total thrust, I^-1 M]. Thrust T along -z at
        # (x, y, z) gives the moment (x, y, z) x (0, 0, -T) = (-y T, x T, 0); the drag torque's yaw
        # moment is spin_sign * torque (a CCW rotor yaws the nose right, +z FRD).
        wm = np.zeros((8, 4))
        wm[:4, 0] = 1.0
        wm[:4, 1] = -arms[:, 1] / ixx
        wm[:4, 2] = arms[:, 0] / iyy
        wm[4:, 3] = np.asarray(vehicle.spin_sign) / izz
        self.wrench_map = wm
        # Euler's equations for a diagonal inertia: wdot_i += k_i w_j w_k (i, j, k cyclic).
        gyro = np.zeros((3, 3, 3))
        gyro[1, 2, 0] = (iyy - izz) / ixx
        gyro[2, 0, 1] = (izz - ixx) / iyy
        gyro[0, 1, 2] = (ixx - iyy) / izz
        self.gyro_map = gyro.reshape(9, 3)
        self.motor_alpha = 1.0 - math.exp(-dt / vehicle.motor_time_constant_s)
        self.efficiency = np.array(vehicle.motor_efficiency, dtype=np.float64)
        self.drag = np.array(vehicle.linear_drag_n_per_m_s, dtype=np.float64)
        self.wind_ned_m_s = np.array(vehicle.wind_ned_m_s, dtype=np.float64)
        self.has_drag = bool(np.any(self.drag > 0))
        self.gravity_dt = np.array([0.0, 0.0, GRAVITY_M_S2 * dt])
        # All products of the state with itself that a step needs, as one bilinear map.
        self.products_map = state_products_map(dt, self.gyro_map)
        # Preallocated work buffers.
        self._forces = np.empty((n, 8))
        self._wrench = np.empty((n, 4))
        self._x = np.empty((n, 7))
        self._xx = np.empty((n, 7, 7))
        self._prod = np.empty((n, 10))
        self.force_body_n = np.zeros((n, 3))  # non-gravity force of the last step with drag, body FRD
        self.last_total_thrust_n = np.zeros(n)

    def specific_force_frd_m_s2(self) -> np.ndarray:
        """What an IMU at the CG measures after the last step: non-gravity force / mass, body FRD."""
        if not self.has_drag:
            self.force_body_n[:, 2] = -self.last_total_thrust_n
        return self.force_body_n * self.inv_mass

    def motor_target(self, omega_cmd_rad_s: np.ndarray) -> np.ndarray:
        """Speed each rotor settles at for a commanded speed (per-motor efficiency)."""
        return omega_cmd_rad_s * self.efficiency

    def step(self, s: VehicleState, omega_target_rad_s: np.ndarray, propellers) -> tuple[np.ndarray, np.ndarray]:
        """Advance ``s`` by dt in place; returns this step's (thrust_n, torque_nm)."""
        dt, n = self.dt_s, len(self.mass_kg)
        om = s.omega_rad_s
        om += self.motor_alpha * (omega_target_rad_s - om)
        thrust, torque = propellers(om, dt)
        q, w, v = s.q_world_body, s.rates_frd_rad_s, s.vel_ned_m_s
        f = self._forces
        f[:, :4] = thrust
        f[:, 4:] = torque
        wr = np.matmul(f, self.wrench_map, out=self._wrench)  # [total thrust, I^-1 M]

        # One outer product of x = [q, w] gives the thrust direction, the quaternion rate and the
        # gyroscopic term: prod = [-dt R[:, 2], dt/2 q ⊗ (0, w), -dt I^-1 (w x I w)].
        x = self._x
        x[:, :4] = q
        x[:, 4:] = w
        np.multiply(x[:, :, None], x[:, None, :], out=self._xx)
        prod = np.matmul(self._xx.reshape(n, 49), self.products_map, out=self._prod)

        # Linear: dv = dt (R f_body / m + g).
        if self.has_drag:
            f_body = self.force_body_n
            f_body[:, :2] = 0.0
            f_body[:, 2] = -wr[:, 0]
            f_body -= self.drag * rotate_world_to_body(q, v - self.wind_ned_m_s)
            dv = rotate_body_to_world(q, f_body) * (self.inv_mass * dt)
        else:
            dv = prod[:, :3] * (wr[:, :1] * self.inv_mass)
        dv += self.gravity_dt

        # Angular: dw = dt I^-1 M + gyroscopic term.
        dw = prod[:, 7:]
        dw += dt * wr[:, 1:]
        w += dw
        v += dv
        s.pos_ned_m += dt * v

        # q += dt/2 q ⊗ (0, w) (with the rates at the start of the step), renormalised.
        q += prod[:, 3:7]
        q /= np.sqrt(np.einsum("ij,ij->i", q, q))[:, None]
        self.last_total_thrust_n = wr[:, 0]
        return thrust, torque
