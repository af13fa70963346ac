"""evalsim's own PX4-like cascaded controller, in NED/FRD and PX4 rotor order.

Structure as PX4's multicopter stack: position P -> velocity PID -> thrust
vector and attitude setpoint -> attitude P (quaternion error, yaw weighted
down) -> rate PID (derivative on measurement) -> quad-X allocation with yaw
given up first on saturation -> rotor speed -> ESC PWM through the paper's ESC
curve (``monitor.esc``, the shared PWM<->RPM boundary).

Gains are PX4's documented defaults where the parameter is unit-free
(``MPC_XY_P``, ``MPC_XY_VEL_*``, ``MPC_Z_VEL_*``, ``MC_*_P``); PX4's rate-loop
gains act on a normalised torque, so here the rate PID outputs angular
acceleration (1/s, 1/s², s) and is scaled by the nominal inertia, gains chosen
for this airframe's ~30 ms motors. The controller knows only the nominal
vehicle (vehicle.yaml): payload, CG, weak motors and damage are hidden from it
and show up only through its integrators and its commands, as on a real vehicle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.esc import PAPER_ESC, EscCurve
from monitor.vehicle import GRAVITY_M_S2


@dataclass(frozen=True)
class ControllerGains:
    pos_xy_p: float = 0.95  # PX4 MPC_XY_P
    pos_z_p: float = 1.0  # PX4 MPC_Z_P
    vel_xy_p: float = 1.8  # PX4 MPC_XY_VEL_P_ACC
    vel_xy_i: float = 0.4  # PX4 MPC_XY_VEL_I_ACC
    vel_xy_d: float = 0.2  # PX4 MPC_XY_VEL_D_ACC
    vel_z_p: float = 4.0  # PX4 MPC_Z_VEL_P_ACC
    vel_z_i: float = 2.0  # PX4 MPC_Z_VEL_I_ACC
    vel_xy_max_m_s: float = 3.0  # gentle routes (PX4 MPC_XY_VEL_MAX is 12)
    vel_d_lp_hz: float = 5.0  # PX4 MPC_VELD_LP
    vel_z_max_m_s: float = 1.5  # PX4 MPC_Z_VEL_MAX_UP/DN order
    tilt_max_rad: float = np.deg2rad(25.0)  # PX4 MPC_TILTMAX_AIR is 45; paper flights are gentle
    att_rp_p: float = 6.5  # PX4 MC_ROLL_P / MC_PITCH_P
    att_yaw_p: float = 2.8  # PX4 MC_YAW_P
    yaw_weight: float = 0.4  # PX4 MC_YAW_WEIGHT
    rate_rp_p: float = 22.0  # 1/s (angular-acceleration form of MC_ROLLRATE_P)
    rate_rp_i: float = 12.0  # 1/s²
    rate_rp_d: float = 0.35  # s
    rate_yaw_p: float = 8.0
    rate_yaw_i: float = 3.0
    rate_max_rad_s: float = np.deg2rad(180.0)
    yaw_rate_max_rad_s: float = np.deg2rad(60.0)
    integrator_limit: float = 0.3  # angular-acceleration integrator clamp, as a fraction of 10 rad/s²
    # On saturation, give up collective thrust before roll and pitch (PX4's control allocator desaturation): the
    # collective moves so the roll/pitch differential fits the rotors' range. False: the collective is clipped and the
    # differential scaled to the room left (the gentle sets' allocator; at full collective it keeps no attitude control).
    collective_yields: bool = False


class CascadeController:
    """B vehicles at once (leading axis = flight). ``position_step`` at the position rate,
    ``rate_step`` at the control rate. Quaternions scalar-first, R_ned_frd."""

    def __init__(
        self,
        n: int,
        mass_kg: float,
        inertia_diag_kg_m2,
        rotor_positions_frd_m: np.ndarray,
        spin_sign: np.ndarray,
        kf: float,
        ktau: float,
        omega_min_rad_s: float,
        omega_max_rad_s: float,
        gains: ControllerGains = ControllerGains(),
        esc: EscCurve = PAPER_ESC,
    ):
        self.g = gains
        self.mass_kg = mass_kg
        self.inertia = np.asarray(inertia_diag_kg_m2, dtype=np.float64)
        self.kf, self.esc = kf, esc
        self.t_min_n = kf * omega_min_rad_s**2
        self.t_max_n = kf * omega_max_rad_s**2
        r = np.asarray(rotor_positions_frd_m, dtype=np.float64)
        # Effectiveness (PX4 control allocation): [thrust up, roll, pitch, yaw] per rotor thrust.
        # Thrust along -z at r gives moment r x (0,0,-T) = (-y T, x T, 0); drag yaw spin*ktau/kf*T.
        self.B = np.vstack([np.ones(4), -r[:, 1], r[:, 0], np.asarray(spin_sign) * ktau / kf])
        self.B_pinv = np.linalg.pinv(self.B)  # (4, 4)
        self.vel_int = np.zeros((n, 3))
        self.rate_int = np.zeros((n, 3))
        self.prev_rates = None
        self.prev_vel_err = None
        self.dverr = np.zeros((n, 3))
        self.q_sp = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        self.thrust_sp_n = np.full(n, mass_kg * GRAVITY_M_S2)
        g = gains
        self.kp_v = np.array([g.vel_xy_p, g.vel_xy_p, g.vel_z_p])
        self.ki_v = np.array([g.vel_xy_i, g.vel_xy_i, g.vel_z_i])
        self.kd_v = np.array([g.vel_xy_d, g.vel_xy_d, 0.0])
        self.kp_r = np.array([g.rate_rp_p, g.rate_rp_p, g.rate_yaw_p])
        self.ki_r = np.array([g.rate_rp_i, g.rate_rp_i, g.rate_yaw_i])
        self.kd_r = np.array([g.rate_rp_d, g.rate_rp_d, 0.0])

    # --- position and velocity (PX4 MulticopterPositionControl) ---
    def position_step(self, pos_sp, pos, vel, yaw_sp, dt_s: float) -> None:
        g = self.g
        err = pos_sp - pos
        vel_sp = err * np.array([g.pos_xy_p, g.pos_xy_p, g.pos_z_p])
        h = np.hypot(vel_sp[:, 0], vel_sp[:, 1])
        vel_sp[:, :2] *= (np.minimum(1.0, g.vel_xy_max_m_s / np.maximum(h, 1e-9)))[:, None]
        vel_sp[:, 2] = np.clip(vel_sp[:, 2], -g.vel_z_max_m_s, g.vel_z_max_m_s)
        verr = vel_sp - vel
        if self.prev_vel_err is None:
            self.prev_vel_err = verr
        # Derivative of the velocity error through PX4's MPC_VELD_LP first-order low-pass.
        a = dt_s / (dt_s + 1.0 / (2 * np.pi * g.vel_d_lp_hz))
        self.dverr = (1 - a) * self.dverr + a * (verr - self.prev_vel_err) / dt_s
        self.prev_vel_err = verr
        acc = self.kp_v * verr + self.vel_int + self.kd_v * self.dverr
        self.vel_int = np.clip(self.vel_int + self.ki_v * verr * dt_s, -4.0, 4.0)
        # Thrust vector (NED, N) from the acceleration setpoint; tilt limited.
        f = self.mass_kg * (acc - np.array([0.0, 0.0, GRAVITY_M_S2]))
        f[:, 2] = np.minimum(f[:, 2], -0.2 * self.mass_kg * GRAVITY_M_S2)
        h = np.hypot(f[:, 0], f[:, 1])
        h_max = -f[:, 2] * np.tan(g.tilt_max_rad)
        f[:, :2] *= (np.minimum(1.0, h_max / np.maximum(h, 1e-9)))[:, None]
        self.thrust_sp_n = np.linalg.norm(f, axis=1)
        self.q_sp = attitude_from_thrust(f / self.thrust_sp_n[:, None], yaw_sp)

    # --- attitude, rates, allocation (PX4 mc_att_control, mc_rate_control, control_allocator) ---
    def rate_step(self, q: np.ndarray, rates_frd: np.ndarray, dt_s: float) -> np.ndarray:
        """Rotor thrust commands (B, 4) N, PX4 order, for the estimated attitude and measured rates."""
        rate_sp = self._attitude_p(q)
        err = rate_sp - rates_frd
        d = np.zeros_like(err) if self.prev_rates is None else (rates_frd - self.prev_rates) / dt_s
        self.prev_rates = rates_frd.copy()
        alpha = self.kp_r * err + self.rate_int - self.kd_r * d
        lim = 10.0 * self.g.integrator_limit
        self.rate_int = np.clip(self.rate_int + self.ki_r * err * dt_s, -lim, lim)
        torque = self.inertia * alpha
        # Collective thrust: the setpoint projected on the current body z (PX4 does the same).
        cos_tilt = np.einsum("bi,bi->b", body_z(q), body_z(self.q_sp))
        thrust = self.thrust_sp_n * np.maximum(cos_tilt, 0.5)
        return self.allocate(thrust, torque)

    def allocate(self, thrust_n: np.ndarray, torque_nm: np.ndarray) -> np.ndarray:
        """Per-rotor thrust (B, 4); on saturation yaw is given up first, then roll/pitch scaled."""
        # Elementwise, not a matmul: BLAS may round differently with the batch size, and a flight
        # must be the same whichever flights it is batched with.
        P = self.B_pinv
        base = thrust_n[:, None] * P[:, 0] + torque_nm[:, 0:1] * P[:, 1] + torque_nm[:, 1:2] * P[:, 2]
        yaw = torque_nm[:, 2:3] * P[:, 3]
        lo, hi = self.t_min_n, self.t_max_n
        dev = base - base.mean(axis=1, keepdims=True)
        if self.g.collective_yields:
            width = dev.max(axis=1, keepdims=True) - dev.min(axis=1, keepdims=True)
            dev = dev * np.minimum(1.0, (hi - lo) / np.maximum(width, 1e-12))
            lo_mean, hi_mean = lo - dev.min(axis=1, keepdims=True), hi - dev.max(axis=1, keepdims=True)
            base = np.minimum(np.maximum(base.mean(axis=1, keepdims=True), lo_mean), hi_mean) + dev
        else:
            mean = np.clip(base.mean(axis=1, keepdims=True), lo, hi)
            with np.errstate(divide="ignore", invalid="ignore"):
                room = np.where(dev > 0, (hi - mean) / dev, np.where(dev < 0, (mean - lo) / -dev, np.inf))
            base = mean + dev * np.minimum(1.0, room.min(axis=1, keepdims=True))
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(yaw > 0, (hi - base) / yaw, np.where(yaw < 0, (base - lo) / -yaw, np.inf))
        scale = np.clip(room.min(axis=1, keepdims=True), 0.0, 1.0)
        return np.clip(base + yaw * scale, lo, hi)

    def pwm_us(self, rotor_thrust_n: np.ndarray) -> np.ndarray:
        """ESC command for the rotor thrusts: nominal kF -> rotor speed -> paper ESC fit."""
        omega = np.sqrt(np.maximum(rotor_thrust_n, 0.0) / self.kf)
        return np.clip(self.esc.omega_rad_s_to_cmd(omega), self.esc.cmd_min, self.esc.cmd_max)

    def _attitude_p(self, q: np.ndarray) -> np.ndarray:
        g = self.g
        # Error quaternion q_e = q^-1 q_sp (body frame); yaw de-weighted as PX4's MC_YAW_WEIGHT.
        qe = qmul(qconj(q), self.q_sp)
        qe *= np.where(qe[:, :1] < 0, -1.0, 1.0)
        e = 2.0 * qe[:, 1:]
        rate_sp = e * np.array([g.att_rp_p, g.att_rp_p, g.att_yaw_p * g.yaw_weight])
        rate_sp[:, :2] = np.clip(rate_sp[:, :2], -g.rate_max_rad_s, g.rate_max_rad_s)
        rate_sp[:, 2] = np.clip(rate_sp[:, 2], -g.yaw_rate_max_rad_s, g.yaw_rate_max_rad_s)
        return rate_sp


def attitude_from_thrust(thrust_dir_ned: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(B, 4) quaternions whose body -z is the unit ``thrust_dir_ned`` (B, 3), heading ``yaw`` (PX4 bodyzToAttitude)."""
    z_b = -thrust_dir_ned  # body +z (down) in NED
    y_c = np.column_stack([-np.sin(yaw), np.cos(yaw), np.zeros_like(yaw)])
    x_b = np.cross(y_c, z_b)
    x_b /= np.linalg.norm(x_b, axis=1, keepdims=True)
    y_b = np.cross(z_b, x_b)
    return quat_from_rot(np.stack([x_b, y_b, z_b], axis=2))


def quat_from_rot(R: np.ndarray) -> np.ndarray:
    """(B, 3, 3) rotation matrices -> (B, 4) unit quaternions, w >= 0 (Shepperd's method, branch-free)."""
    tr = np.trace(R, axis1=1, axis2=2)
    cands = np.stack([tr, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=1)
    k = np.argmax(cands, axis=1)
    q = np.empty((len(R), 4))
    for i in range(4):
        m = k == i
        if not np.any(m):
            continue
        Rm = R[m]
        if i == 0:
            s = 2.0 * np.sqrt(1.0 + tr[m])
            q[m] = np.column_stack(
                [0.25 * s, (Rm[:, 2, 1] - Rm[:, 1, 2]) / s, (Rm[:, 0, 2] - Rm[:, 2, 0]) / s, (Rm[:, 1, 0] - Rm[:, 0, 1]) / s]
            )
        elif i == 1:
            s = 2.0 * np.sqrt(1.0 + Rm[:, 0, 0] - Rm[:, 1, 1] - Rm[:, 2, 2])
            q[m] = np.column_stack(
                [(Rm[:, 2, 1] - Rm[:, 1, 2]) / s, 0.25 * s, (Rm[:, 0, 1] + Rm[:, 1, 0]) / s, (Rm[:, 0, 2] + Rm[:, 2, 0]) / s]
            )
        elif i == 2:
            s = 2.0 * np.sqrt(1.0 + Rm[:, 1, 1] - Rm[:, 0, 0] - Rm[:, 2, 2])
            q[m] = np.column_stack(
                [(Rm[:, 0, 2] - Rm[:, 2, 0]) / s, (Rm[:, 0, 1] + Rm[:, 1, 0]) / s, 0.25 * s, (Rm[:, 1, 2] + Rm[:, 2, 1]) / s]
            )
        else:
            s = 2.0 * np.sqrt(1.0 + Rm[:, 2, 2] - Rm[:, 0, 0] - Rm[:, 1, 1])
            q[m] = np.column_stack(
                [(Rm[:, 1, 0] - Rm[:, 0, 1]) / s, (Rm[:, 0, 2] + Rm[:, 2, 0]) / s, (Rm[:, 1, 2] + Rm[:, 2, 1]) / s, 0.25 * s]
            )
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (B, 4) scalar-first quaternions."""
    w1, x1, y1, z1 = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    w2, x2, y2, z2 = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    return np.column_stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def qconj(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def body_z(q: np.ndarray) -> np.ndarray:
    """Third column of R_ned_frd (body +z in the world) for (B, 4) quaternions."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.column_stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
