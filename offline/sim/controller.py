"""PX4-like multicopter cascade, batched over flights.

    position P -> velocity PID (limits, anti-windup) -> thrust vector + attitude setpoint
    (``MulticopterPositionControl``, run at ``position_rate_hz``)
    -> quaternion attitude P -> body-rate PID -> quad-X allocation with desaturation
    (``MulticopterAttitudeControl`` / ``MulticopterRateControl`` / control allocation,
    run at ``control_rate_hz``) -> rotor speed command -> PWM through the inverse ESC fit.

Gains are PX4 defaults (v1.14 parameter reference) and keep PX4's names and
units. The rate loop works in PX4's normalised torque (-1..1); this module
turns it into N m with the vehicle's own authority: normalised torque 1 is
every rotor's thrust swinging by half its maximum, which is how PX4's
control allocation scales a symmetric quad's effectiveness matrix.

Deliberate simplifications, each PX4-flavoured: no jerk-limited trajectory
generator (the velocity setpoint is slew-limited by MPC_ACC_HOR /
MPC_ACC_UP_MAX / MPC_ACC_DOWN_MAX instead); the hover thrust estimator is
taken as converged (the controller knows mass + payload, not the faults);
the attitude setpoint is tilt-then-yaw rather than PX4's body-z/yaw
construction (equal for small tilts); no yaw-weight decoupling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from monitor.errors import ConfigError
from monitor.vehicle import VehicleConfig
from offline.sim.dynamics import GRAVITY_M_S2
from offline.sim.quat import QUAT_CONJ_MUL

try:  # the clip ufunc itself: one call, where np.clip's Python wrapper costs more than the work
    from numpy._core.umath import clip as _clip_ufunc
except ImportError:  # numpy < 2
    from numpy.core.umath import clip as _clip_ufunc


def clip_in_place(x: np.ndarray, lo, hi) -> np.ndarray:
    """``np.clip(x, lo, hi, out=x)`` without its wrapper: max then min, NaN propagates."""
    return _clip_ufunc(x, lo, hi, x)


@dataclass(frozen=True)
class ControllerConfig:
    """PX4 parameters (names lower-cased, units in the name where PX4 has one)."""

    mpc_xy_p: float = 0.95  # MPC_XY_P, 1/s
    mpc_z_p: float = 1.0  # MPC_Z_P, 1/s
    mpc_xy_vel_p_acc: float = 1.8  # MPC_XY_VEL_P_ACC, 1/s
    mpc_xy_vel_i_acc: float = 0.4  # MPC_XY_VEL_I_ACC, 1/s^2
    mpc_xy_vel_d_acc: float = 0.2  # MPC_XY_VEL_D_ACC
    mpc_z_vel_p_acc: float = 4.0  # MPC_Z_VEL_P_ACC
    mpc_z_vel_i_acc: float = 2.0  # MPC_Z_VEL_I_ACC
    mpc_z_vel_d_acc: float = 0.0  # MPC_Z_VEL_D_ACC
    mpc_xy_cruise_m_s: float = 5.0  # MPC_XY_CRUISE (mission speed)
    mpc_z_vel_max_up_m_s: float = 3.0  # MPC_Z_VEL_MAX_UP
    mpc_z_vel_max_dn_m_s: float = 1.5  # MPC_Z_VEL_MAX_DN
    mpc_acc_hor_m_s2: float = 3.0  # MPC_ACC_HOR
    mpc_acc_up_max_m_s2: float = 4.0  # MPC_ACC_UP_MAX
    mpc_acc_down_max_m_s2: float = 3.0  # MPC_ACC_DOWN_MAX
    mpc_tiltmax_air_deg: float = 45.0  # MPC_TILTMAX_AIR
    mpc_thr_min: float = 0.12  # MPC_THR_MIN, fraction of full collective thrust
    mpc_thr_max: float = 1.0  # MPC_THR_MAX
    mpc_yawrauto_max_deg_s: float = 45.0  # MPC_YAWRAUTO_MAX
    mpc_yaw_mode_heading_min_m: float = 2.0  # MPC_YAW_MODE 0 (face the waypoint) only beyond this horizontal distance
    nav_acc_rad_m: float = 0.4  # NAV_ACC_RAD; PX4's 2 m default is tightened so every waypoint is visited within 0.5 m
    mc_roll_p: float = 6.5  # MC_ROLL_P, 1/s
    mc_pitch_p: float = 6.5  # MC_PITCH_P
    mc_yaw_p: float = 2.8  # MC_YAW_P
    mc_rollrate_max_deg_s: float = 220.0  # MC_ROLLRATE_MAX
    mc_pitchrate_max_deg_s: float = 220.0  # MC_PITCHRATE_MAX
    mc_yawrate_max_deg_s: float = 200.0  # MC_YAWRATE_MAX
    mc_rollrate_p: float = 0.15  # MC_ROLLRATE_P, normalised torque per rad/s
    mc_rollrate_i: float = 0.2  # MC_ROLLRATE_I
    mc_rollrate_d: float = 0.003  # MC_ROLLRATE_D
    mc_pitchrate_p: float = 0.15  # MC_PITCHRATE_P
    mc_pitchrate_i: float = 0.2  # MC_PITCHRATE_I
    mc_pitchrate_d: float = 0.003  # MC_PITCHRATE_D
    mc_yawrate_p: float = 0.2  # MC_YAWRATE_P
    mc_yawrate_i: float = 0.1  # MC_YAWRATE_I
    mc_yawrate_d: float = 0.0  # MC_YAWRATE_D
    mc_rr_int_lim: float = 0.3  # MC_RR_INT_LIM (and MC_PR_INT_LIM)
    mc_yr_int_lim: float = 0.3  # MC_YR_INT_LIM

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not math.isfinite(value) or value < 0:
                raise ConfigError(f"controller.{name}: must be a finite number >= 0, got {value}")
        if not 0 < self.mpc_tiltmax_air_deg < 90:
            raise ConfigError("controller.mpc_tiltmax_air_deg: must be in (0, 90)")
        if not self.mpc_thr_min < self.mpc_thr_max <= 1:
            raise ConfigError("controller.mpc_thr_max: must be above mpc_thr_min and at most 1")


@dataclass
class ControllerState:
    """Integrators, filters and setpoints of B flights (updated in place)."""

    waypoint_index: np.ndarray  # (B,) int, index of the waypoint being flown to
    waypoints_reached: np.ndarray  # (B,) int, waypoints reached so far (counts repeats)
    vel_sp_ned_m_s: np.ndarray  # (B, 3) slew-limited velocity setpoint
    vel_int_ned_m_s2: np.ndarray  # (B, 3) velocity integrator (acceleration)
    vel_prev_ned_m_s: np.ndarray  # (B, 3) for the derivative on measurement
    yaw_sp_rad: np.ndarray  # (B,)
    q_sp: np.ndarray  # (B, 4) attitude setpoint
    thrust_sp_n: np.ndarray  # (B,) collective thrust setpoint
    rate_int: np.ndarray  # (B, 3) rate integrator (normalised torque)
    rate_prev_rad_s: np.ndarray  # (B, 3)


class Controller:
    def __init__(
        self,
        cfg: ControllerConfig,
        vehicle: VehicleConfig,
        mass_kg: np.ndarray,
        position_dt_s: float,
        control_dt_s: float,
        gains: dict[str, np.ndarray] | None = None,
    ):
        """``gains``: per-flight values (B,) of ControllerConfig gain fields, overriding ``cfg`` for those
        flights (the loops' gains become (B, 3) arrays); None keeps ``cfg`` for every flight."""
        self.cfg = cfg
        self.vehicle = vehicle
        self.mass_kg = np.asarray(mass_kg, dtype=np.float64).reshape(-1)
        self.pos_dt = float(position_dt_s)
        self.ctrl_dt = float(control_dt_s)
        kf, ktau = vehicle.kf_n_per_rad_s2, vehicle.ktau_nm_per_rad_s2
        self.kf = kf
        self.rotor_thrust_max_n = kf * vehicle.omega_max_rad_s**2
        self.rotor_thrust_min_n = kf * vehicle.omega_min_rad_s**2
        # Nominal geometry: the controller does not know the calibration terms (CG offset...).
        pos = np.array(vehicle.rotor_positions_frd_m)
        alloc = np.vstack([np.ones(4), -pos[:, 1], pos[:, 0], vehicle.spin_sign * (ktau / kf)])
        self.mix = np.linalg.inv(alloc)  # [T, Mx, My, Mz] -> per-rotor thrust
        half = 0.5 * self.rotor_thrust_max_n
        self.torque_authority_nm = np.abs(alloc[1:]).sum(axis=1) * half
        self.rate_p = np.array([cfg.mc_rollrate_p, cfg.mc_pitchrate_p, cfg.mc_yawrate_p])
        self.rate_i = np.array([cfg.mc_rollrate_i, cfg.mc_pitchrate_i, cfg.mc_yawrate_i])
        self.rate_d = np.array([cfg.mc_rollrate_d, cfg.mc_pitchrate_d, cfg.mc_yawrate_d])
        self.rate_int_lim = np.array([cfg.mc_rr_int_lim, cfg.mc_rr_int_lim, cfg.mc_yr_int_lim])
        self.att_p = np.array([cfg.mc_roll_p, cfg.mc_pitch_p, cfg.mc_yaw_p])
        self.pos_p = np.array([cfg.mpc_xy_p, cfg.mpc_xy_p, cfg.mpc_z_p])
        self.rate_max = np.radians([cfg.mc_rollrate_max_deg_s, cfg.mc_pitchrate_max_deg_s, cfg.mc_yawrate_max_deg_s])
        self.vel_p = np.array([cfg.mpc_xy_vel_p_acc, cfg.mpc_xy_vel_p_acc, cfg.mpc_z_vel_p_acc])
        self.vel_i = np.array([cfg.mpc_xy_vel_i_acc, cfg.mpc_xy_vel_i_acc, cfg.mpc_z_vel_i_acc])
        self.vel_d = np.array([cfg.mpc_xy_vel_d_acc, cfg.mpc_xy_vel_d_acc, cfg.mpc_z_vel_d_acc])
        if gains:
            self._per_flight_gains(cfg, gains)
        self.tan_tilt_max = math.tan(math.radians(cfg.mpc_tiltmax_air_deg))
        self.thrust_max_n = 4 * self.rotor_thrust_max_n * cfg.mpc_thr_max
        self.thrust_min_n = 4 * self.rotor_thrust_max_n * cfg.mpc_thr_min
        # Anti-windup: the velocity integrator never asks for more than these accelerations.
        self.vel_int_lim = np.array([cfg.mpc_acc_hor_m_s2, cfg.mpc_acc_hor_m_s2, GRAVITY_M_S2])
        self.flight_rows = np.arange(len(self.mass_kg))  # for gathering each flight's current waypoint
        # Folded constants and work buffers for the fast inner loop.
        self.inv_kf = 1.0 / kf
        self.rotor_thrust_span_n = self.rotor_thrust_max_n - self.rotor_thrust_min_n
        self.mix_rp = (self.mix[:, 1:3] * self.torque_authority_nm[:2]).T  # (2, 4) normalised roll/pitch -> N
        self.mix_yaw = self.mix[:, 3] * self.torque_authority_nm[2]  # (4,) normalised yaw -> N
        self.neg_rate_max, self.neg_rate_int_lim = -self.rate_max, -self.rate_int_lim
        self.yaw_spread = float(self.mix_yaw.max() - self.mix_yaw.min())
        self.mix_torque = np.vstack([self.mix_rp, self.mix_yaw])  # (3, 4) normalised torque -> N per rotor
        self.att_2p = 2.0 * self.att_p
        self.rate_i_dt = self.rate_i * self.ctrl_dt
        self.rate_d_per_dt = self.rate_d / self.ctrl_dt
        n = len(self.mass_kg)
        self._qq = np.empty((n, 4, 4))
        self._qq16 = self._qq.reshape(n, 16)
        self._q4 = np.empty((n, 4))
        self._qe_w, self._qe_vec = self._q4[:, :1], self._q4[:, 1:]
        self._r4 = np.empty((n, 4))
        self._quarter = np.empty(n)
        self._quarter_col = self._quarter[:, None]
        self._ok4 = np.empty((n, 4), dtype=bool)
        self._ones3 = np.ones(3)
        # Position loop: per-call constants (same products as written out in the loop) and
        # buffers with their column views made once. Scalars are 0-d arrays, which numpy takes
        # faster than Python floats (same float64 values), and outputs are passed positionally.
        dt = self.pos_dt
        k = lambda x: np.array(float(x))  # noqa: E731
        self.dmax_h = k(cfg.mpc_acc_hor_m_s2 * dt)
        self.dv_z_lo, self.dv_z_hi = k(-cfg.mpc_acc_up_max_m_s2 * dt), k(cfg.mpc_acc_down_max_m_s2 * dt)
        self.yaw_step, self.neg_yaw_step = (
            k(math.radians(cfg.mpc_yawrauto_max_deg_s) * dt),
            k(-(math.radians(cfg.mpc_yawrauto_max_deg_s) * dt)),
        )
        self._k = {
            name: k(value)
            for name, value in (
                ("cruise", cfg.mpc_xy_cruise_m_s),
                ("vz_lo", -cfg.mpc_z_vel_max_up_m_s),
                ("vz_hi", cfg.mpc_z_vel_max_dn_m_s),
                ("dt", dt),
                ("fz_lo", -self.thrust_max_n),
                ("fz_hi", -self.thrust_min_n),
                ("tmax2", self.thrust_max_n**2),
                ("tan", self.tan_tilt_max),
                ("zero", 0.0),
                ("eps", 1e-12),
                ("one", 1.0),
                ("neg_one", -1.0),
                ("half", 0.5),
                ("quarter", 0.25),
                ("pi", math.pi),
                ("two_pi", 2 * math.pi),
                ("heading_min", cfg.mpc_yaw_mode_heading_min_m),
                ("acc_rad2", cfg.nav_acc_rad_m**2),
                ("inv_kf", self.inv_kf),
                ("lo", self.rotor_thrust_min_n),
                ("hi", self.rotor_thrust_max_n),
            )
        }
        self._quarter_k, self._lo_k, self._hi_k, self._inv_kf_k, self._neg_one_k, self._one_k = (
            self._k[name] for name in ("quarter", "lo", "hi", "inv_kf", "neg_one", "one")
        )
        self.neg_vel_int_lim = -self.vel_int_lim
        self.weight_n = self.mass_kg * GRAVITY_M_S2
        self.mass_col = self.mass_kg[:, None]
        self._vsp, self._dv, self._acc_ff, self._verr, self._acc, self._f, self._pt3 = np.empty((7, n, 3))
        self._h, self._h2, self._h3, self._h4, self._h5, self._h6 = np.empty((6, n))
        self._h_col = self._h[:, None]
        # (x, y, horizontal pair, z) column views of the position loop's buffers
        self._vsp_cols = (self._vsp[:, 0], self._vsp[:, 1], self._vsp[:, :2], self._vsp[:, 2])
        self._dv_cols = (self._dv[:, 0], self._dv[:, 1], self._dv[:, :2], self._dv[:, 2])
        self._f_cols = (self._f[:, 0], self._f[:, 1], self._f[:, :2], self._f[:, 2])
        self._h2_col = self._h2[:, None]
        self._att_views = (None, None, None, None)  # (q, q_sp, q as a column, q_sp as a row)
        self._qsp_cols = (None, ())  # (q_sp, its columns)
        self._r3 = np.empty((n, 3))
        self._u3 = np.empty((n, 3))
        self._t3 = np.empty((n, 3))

    def _per_flight_gains(self, cfg: ControllerConfig, gains: dict[str, np.ndarray]) -> None:
        n = len(self.mass_kg)
        unknown = sorted(set(gains) - set(cfg.__dict__))
        if unknown:
            raise ConfigError(f"controller gains: unknown fields {unknown}")

        def g(name: str) -> np.ndarray:
            v = np.broadcast_to(np.asarray(gains.get(name, getattr(cfg, name)), dtype=np.float64), (n,))
            if not np.all(np.isfinite(v)) or np.any(v < 0):
                raise ConfigError(f"controller.{name}: per-flight gains must be finite and >= 0")
            return v

        def axes(x: str, y: str, z: str) -> np.ndarray:
            return np.stack([g(x), g(y), g(z)], axis=1)

        self.rate_p = axes("mc_rollrate_p", "mc_pitchrate_p", "mc_yawrate_p")
        self.rate_i = axes("mc_rollrate_i", "mc_pitchrate_i", "mc_yawrate_i")
        self.rate_d = axes("mc_rollrate_d", "mc_pitchrate_d", "mc_yawrate_d")
        self.att_p = axes("mc_roll_p", "mc_pitch_p", "mc_yaw_p")
        self.pos_p = axes("mpc_xy_p", "mpc_xy_p", "mpc_z_p")
        self.vel_p = axes("mpc_xy_vel_p_acc", "mpc_xy_vel_p_acc", "mpc_z_vel_p_acc")
        self.vel_i = axes("mpc_xy_vel_i_acc", "mpc_xy_vel_i_acc", "mpc_z_vel_i_acc")
        self.vel_d = axes("mpc_xy_vel_d_acc", "mpc_xy_vel_d_acc", "mpc_z_vel_d_acc")

    def initial_state(self, n: int, yaw_rad: float = 0.0) -> ControllerState:
        q = np.zeros((n, 4))
        q[:, 0], q[:, 3] = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
        return ControllerState(
            waypoint_index=np.zeros(n, dtype=np.int64),
            waypoints_reached=np.zeros(n, dtype=np.int64),
            vel_sp_ned_m_s=np.zeros((n, 3)),
            vel_int_ned_m_s2=np.zeros((n, 3)),
            vel_prev_ned_m_s=np.zeros((n, 3)),
            yaw_sp_rad=np.full(n, yaw_rad),
            q_sp=q,
            thrust_sp_n=self.mass_kg * GRAVITY_M_S2,
            rate_int=np.zeros((n, 3)),
            rate_prev_rad_s=np.zeros((n, 3)),
        )

    # -- position and velocity (MulticopterPositionControl) ------------------------------------
    def update_position(
        self, c: ControllerState, pos_ned_m: np.ndarray, vel_ned_m_s: np.ndarray, waypoints_ned_m: np.ndarray
    ) -> np.ndarray:
        """Advance the mission, run the position/velocity loops; sets q_sp and thrust_sp_n.

        Returns the waypoint error (target - position), (B, 3).
        """
        # Written with preallocated buffers and the operations of the plain formulas in the same
        # order, so the results are the same to the last bit.
        K, rows = self._k, self.flight_rows
        target = waypoints_ned_m[rows, c.waypoint_index]
        err = target - pos_ned_m
        reached = np.less((err * err) @ self._ones3, K["acc_rad2"])
        if np.count_nonzero(reached):  # cheaper than a logical_or reduction on a few flights
            c.waypoints_reached += reached
            c.waypoint_index = (c.waypoint_index + reached) % waypoints_ned_m.shape[1]
            target = waypoints_ned_m[rows, c.waypoint_index]
            err = target - pos_ned_m
        hn, hn_col, dt = self._h, self._h_col, K["dt"]

        # Position P with PX4's speed limits (horizontal norm, separate up/down).
        vel_sp = np.multiply(err, self.pos_p, self._vsp)
        v_x, v_y, v_xy, v_z = self._vsp_cols
        np.hypot(v_x, v_y, hn)
        np.maximum(hn, K["cruise"], out=hn)
        v_xy *= np.divide(K["cruise"], hn_col, hn_col)
        clip_in_place(v_z, K["vz_lo"], K["vz_hi"])
        # Slew-limit the setpoint (stands in for PX4's jerk-limited trajectory).
        dv = np.subtract(vel_sp, c.vel_sp_ned_m_s, self._dv)
        d_x, d_y, d_xy, d_z = self._dv_cols
        np.hypot(d_x, d_y, hn)
        np.maximum(hn, self.dmax_h, out=hn)
        d_xy *= np.divide(self.dmax_h, hn_col, hn_col)
        clip_in_place(d_z, self.dv_z_lo, self.dv_z_hi)
        c.vel_sp_ned_m_s += dv
        acc_ff = np.divide(dv, dt, self._acc_ff)

        # Velocity PID (derivative on the measurement, as PX4), integrator clamped.
        verr = np.subtract(c.vel_sp_ned_m_s, vel_ned_m_s, self._verr)
        t3 = np.multiply(self.vel_i, verr, self._pt3)
        t3 *= dt
        c.vel_int_ned_m_s2 += t3
        clip_in_place(c.vel_int_ned_m_s2, self.neg_vel_int_lim, self.vel_int_lim)
        acc_sp = np.multiply(self.vel_p, verr, self._acc)
        np.add(acc_ff, acc_sp, acc_sp)
        acc_sp += c.vel_int_ned_m_s2
        np.subtract(vel_ned_m_s, c.vel_prev_ned_m_s, t3)
        np.multiply(self.vel_d, t3, t3)
        t3 /= dt
        acc_sp -= t3
        c.vel_prev_ned_m_s[...] = vel_ned_m_s

        # Thrust vector (NED) with vertical priority: clamp collective, then limit the tilt.
        f = np.multiply(acc_sp, self.mass_col, self._f)
        f_x, f_y, f_xy, f_z = self._f_cols
        f_z -= self.weight_n
        clip_in_place(f_z, K["fz_lo"], K["fz_hi"])
        fh = np.hypot(f_x, f_y, hn)
        # fh_max = min(-f_z tan(tilt_max), sqrt(max(thrust_max^2 - f_z^2, 0)))
        room = np.square(f_z, self._h2)
        np.subtract(K["tmax2"], room, room)
        np.maximum(room, K["zero"], out=room)
        np.sqrt(room, room)
        fh_max = np.negative(f_z, self._h3)
        fh_max *= K["tan"]
        np.minimum(fh_max, room, out=fh_max)
        np.maximum(fh, fh_max, out=fh)
        fh += K["eps"]
        f_xy *= np.divide(fh_max[:, None], hn_col, hn_col)
        thrust = np.sqrt((f * f) @ self._ones3)
        c.thrust_sp_n = thrust

        # Yaw setpoint: face the waypoint (MPC_YAW_MODE 0), rate-limited by MPC_YAWRAUTO_MAX.
        err_x, err_y = err[:, 0], err[:, 1]
        far = np.greater(np.hypot(err_x, err_y, hn), K["heading_min"])
        yaw_target = np.where(far, np.arctan2(err_y, err_x, self._h3), c.yaw_sp_rad)
        pi, two_pi = K["pi"], K["two_pi"]
        dyaw = np.subtract(yaw_target, c.yaw_sp_rad, self._h4)
        dyaw += pi
        np.remainder(dyaw, two_pi, dyaw)
        dyaw -= pi
        yaw = c.yaw_sp_rad + clip_in_place(dyaw, self.neg_yaw_step, self.yaw_step)
        yaw += pi
        np.remainder(yaw, two_pi, yaw)
        yaw -= pi
        c.yaw_sp_rad = yaw

        # Attitude setpoint: tilt body z onto -f, then yaw. q_tilt takes e_z to z_b = -f/|f|.
        zb = f
        zb /= np.negative(thrust[:, None], self._h2_col)
        zb_x, zb_y, zb_z = f_x, f_y, f_z
        # q_tilt = normalise(1 + zb_z, -zb_y, zb_x, 0), then q_sp = q_tilt ⊗ (cos(yaw/2), 0, 0, sin(yaw/2)).
        tw = np.add(K["one"], zb_z, self._h2)
        inv = np.multiply(tw, tw, self._h3)
        inv += np.multiply(zb_x, zb_x, hn)
        inv += np.multiply(zb_y, zb_y, hn)
        np.sqrt(inv, inv)
        np.divide(K["one"], inv, inv)
        half_yaw = np.multiply(K["half"], yaw, self._h4)
        cy = np.cos(half_yaw, self._h5)
        cy *= inv
        sy = np.sin(half_yaw, self._h6)
        sy *= inv
        tx, ty = np.negative(zb_y, self._h4), zb_x
        qs, cols = self._qsp_cols
        if qs is not c.q_sp:
            qs = c.q_sp
            qs, cols = self._qsp_cols = (qs, (qs[:, 0], qs[:, 1], qs[:, 2], qs[:, 3]))
        np.multiply(tw, cy, cols[0])
        np.add(np.multiply(tx, cy, cols[1]), np.multiply(ty, sy, hn), cols[1])
        np.subtract(np.multiply(ty, cy, cols[2]), np.multiply(tx, sy, hn), cols[2])
        np.multiply(tw, sy, cols[3])
        return err

    # -- attitude, rates and allocation (MulticopterAttitudeControl/RateControl) ---------------
    def update_attitude(self, c: ControllerState, q: np.ndarray, gyro_frd_rad_s: np.ndarray) -> np.ndarray:
        """Returns the commanded rotor speed (B, 4) in rad/s."""
        # q_err = conj(q) ⊗ q_sp; rate setpoint = P * 2 sign(w) vec(q_err) (PX4 AttitudeControl).
        views = self._att_views
        if views[0] is not q or views[1] is not c.q_sp:  # broadcasting views, made once per array
            views = self._att_views = (q, c.q_sp, q[:, :, None], c.q_sp[:, None, :])
        np.multiply(views[2], views[3], self._qq)
        np.matmul(self._qq16, QUAT_CONJ_MUL, self._q4)
        rate_sp = np.copysign(self.att_2p, self._qe_w, self._r3)
        rate_sp *= self._qe_vec
        _clip_ufunc(rate_sp, self.neg_rate_max, self.rate_max, rate_sp)

        # Rate PID in normalised torque, derivative on the measurement (PX4 RateControl).
        rerr = rate_sp
        rerr -= gyro_frd_rad_s
        integ = c.rate_int
        t = np.multiply(self.rate_i_dt, rerr, self._t3)
        integ += t
        _clip_ufunc(integ, self.neg_rate_int_lim, self.rate_int_lim, integ)
        u = np.multiply(self.rate_p, rerr, self._u3)
        u += integ
        np.subtract(gyro_frd_rad_s, c.rate_prev_rad_s, t)
        np.multiply(self.rate_d_per_dt, t, t)
        u -= t
        c.rate_prev_rad_s[...] = gyro_frd_rad_s
        _clip_ufunc(u, self._neg_one_k, self._one_k, u)
        return self.allocate(c.thrust_sp_n, u)

    def allocate(self, thrust_n: np.ndarray, torque_norm: np.ndarray) -> np.ndarray:
        """Quad-X allocation -> commanded rotor speed (B, 4), desaturating only where needed.

        ``torque_norm`` is PX4's normalised torque. A flight whose rotors all
        fit their range gets the plain mix; the others are desaturated (PX4
        style, see ``_desaturate``). Deciding per flight keeps a batch equal to
        its flights run one at a time, and skips the work when nothing saturates.
        """
        lo, hi = self.rotor_thrust_min_n, self.rotor_thrust_max_n
        cmd = np.matmul(torque_norm, self.mix_torque, self._r4)
        np.multiply(thrust_n, self._quarter_k, self._quarter)
        cmd += self._quarter_col
        # Whole-batch check first: when every rotor of every flight fits (NaN does not), nothing else
        # is needed. Comparisons and counts: cheaper than min/max reductions on a few flights.
        ok = self._ok4
        if (
            np.count_nonzero(np.greater_equal(cmd, self._lo_k, ok)) + np.count_nonzero(np.less_equal(cmd, self._hi_k, ok))
            != 2 * cmd.size
        ):
            fits = (np.minimum.reduce(cmd, axis=1) >= lo) & (np.maximum.reduce(cmd, axis=1) <= hi)
            cmd = np.where(fits[:, None], cmd, self._desaturate(thrust_n, torque_norm))
        cmd *= self._inv_kf_k
        return np.sqrt(cmd, cmd)

    def _desaturate(self, thrust_n: np.ndarray, torque_norm: np.ndarray) -> np.ndarray:
        """Per-rotor thrust (B, 4) that fits the rotors' range, keeping roll/pitch authority.

        As PX4's control allocation: the roll/pitch differential is scaled down
        only if it alone exceeds the range; yaw gets the room that is left; then
        the collective moves (down, or up as in airmode) so every rotor fits.
        """
        lo, span = self.rotor_thrust_min_n, self.rotor_thrust_span_n
        rp = torque_norm[:, :2] @ self.mix_rp
        yw = torque_norm[:, 2:3] * self.mix_yaw
        rp_spread = np.maximum.reduce(rp, axis=1) - np.minimum.reduce(rp, axis=1)
        rp *= (span / np.maximum(rp_spread, span))[:, None]
        room = span - np.minimum(rp_spread, span)
        y_spread = np.abs(torque_norm[:, 2]) * self.yaw_spread
        yw *= (room / np.maximum(np.maximum(y_spread, room), 1e-12))[:, None]
        rp += yw
        coll = 0.25 * thrust_n
        np.maximum(coll, lo - np.minimum.reduce(rp, axis=1), out=coll)
        np.minimum(coll, lo + span - np.maximum.reduce(rp, axis=1), out=coll)
        rp += coll[:, None]
        return np.maximum(rp, lo, out=rp)
