"""The flight model the calibration checks, written as equation error.

Model (body FRD, world NED, PX4 quad-X rotor order; see ``monitor.vehicle``):

- rotor speed follows the ESC's target speed through a first-order lag
  (``motor_time_constant_s``, times ``motor_time_constant_ratio[i]`` for rotor i); the target comes from the logged command through
  the vehicle's ESC curve (``monitor.esc``), or from the logged RPM when the
  log has no command;
- ``motor_efficiency[i]`` scales the speed rotor i settles at for its
  command (as ``offline.sim.dynamics`` does: a worn motor or sagging ESC), so a
  weak motor loses thrust and drag torque alike, by ``e_i**2``; the paper's
  unbalance ratio (eqs. 14-17, ``F = w**2 / U_r**2``) is the speed scale
  ``1 / U_r(w)``;
- rotor i pushes ``f_i = kf * w_i**2`` along body -z at ``r_i`` and twists
  the body by ``spin_i * (ktau * w_i**2 + J_r * dw_i/dt)`` about +z: the drag
  torque plus the reaction of spinning the rotor up (``rotor_inertia_kg_m2``;
  ``dw_i/dt = (target_i - w_i) / tau_i`` exactly, from the first-order lag). The
  reaction leads the drag torque, so in yaw it offsets part of the motor lag
  that roll and pitch see in full;
- moments are taken about the centre of gravity, ``r_i - cg_offset_frd_m``;
- drag is linear in the air-relative body velocity
  (``linear_drag_n_per_m_s``, ``wind_ned_m_s``);
- the gyro reads the body rate plus ``gyro_bias_frd_rad_s``.

``residuals`` returns, per segment, the named signals "measured minus
predicted" after the shared filters of ``prepare``; ``trim_commands`` gives the
per-motor command the model needs to hold a steady state.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.signal import lfilter, lfilter_zi

from monitor.esc import RAD_S_PER_RPM
from monitor.vehicle import GRAVITY_M_S2, VehicleConfig
from offline.calibrate.prepare import FINE, SG_WINDOW, SG_WINDOW_TRANSLATION, Segment, cumtrapz, euler_rates, sg_deriv, sg_smooth

G_M_S2 = GRAVITY_M_S2
G_NED = np.array([0.0, 0.0, G_M_S2])

ROT_SIGNALS = ("roll_accel_rad_s2", "pitch_accel_rad_s2", "yaw_accel_rad_s2")
IMU_SIGNALS = ("accel_x_m_s2", "accel_y_m_s2", "accel_z_m_s2")
VEL_SIGNALS = ("accel_n_m_s2", "accel_e_m_s2", "accel_d_m_s2")
KIN_SIGNALS = ("roll_kin_rad_s", "pitch_kin_rad_s", "yaw_kin_rad_s")

# Optional per-motor speed scale as a function of the commanded rotor speed
# (the paper's unbalance ratio, eqs. 14-17); None means ``motor_efficiency``.
SpeedScale = Callable[[np.ndarray], np.ndarray] | None


def target_omega_rad_s(seg: Segment, vehicle: VehicleConfig, fine: bool = False) -> np.ndarray:
    """ESC target speed from the logged command (or the logged RPM when there is no command)."""
    if np.all(np.isnan(seg.motor_cmd)):
        return (seg.motor_rpm_fine if fine else seg.motor_rpm) * RAD_S_PER_RPM
    return vehicle.esc.cmd_to_omega_rad_s(seg.motor_cmd_fine if fine else seg.motor_cmd)


def first_order_lag(u: np.ndarray, tau_s, dt_s: float) -> np.ndarray:
    """Exact response of ``tau*y' = u - y`` to ``u`` linear between samples, starting at rest on u[0].

    Linear (not held) input between grid instants because the logged command is
    a snapshot of a signal that moves continuously at the controller's rate.
    ``tau_s`` is one time constant, or one per column of ``u``.
    """
    tau = np.asarray(tau_s, dtype=np.float64)
    if tau.ndim and not np.all(tau == tau.flat[0]):
        return np.column_stack([first_order_lag(u[:, [i]], float(t), dt_s)[:, 0] for i, t in enumerate(tau)])
    tau_s = float(tau.flat[0])
    a = np.exp(-dt_s / tau_s)
    beta = tau_s * (1.0 - a) / dt_s
    b = np.array([1.0 - beta, beta - a])
    den = np.array([1.0, -a])
    zi = lfilter_zi(b, den)[:, None] * u[0][None, :]
    y, _ = lfilter(b, den, u, axis=0, zi=zi)
    return y


def rotor_forces(seg: Segment, vehicle: VehicleConfig, speed_scale: SpeedScale = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-rotor thrust (N) and yaw torque magnitude (N m: drag plus spin-up reaction) on the fine grid, each (T_fine, 4)."""
    w_cmd = target_omega_rad_s(seg, vehicle, fine=True)
    e = np.asarray(vehicle.motor_efficiency) if speed_scale is None else speed_scale(w_cmd)
    target = e * w_cmd
    taus = vehicle.rotor_time_constants_s
    w = first_order_lag(target, taus, seg.dt_fine_s)
    w2 = np.maximum(w, 0.0) ** 2
    torque = vehicle.ktau_nm_per_rad_s2 * w2
    if vehicle.rotor_inertia_kg_m2 > 0:
        torque = torque + vehicle.rotor_inertia_kg_m2 * (target - w) / taus
    return vehicle.kf_n_per_rad_s2 * w2, torque


def body_moments(f: np.ndarray, tau: np.ndarray, vehicle: VehicleConfig) -> np.ndarray:
    """(T, 3) moments about the CG from rotor thrusts and torques."""
    r = vehicle.rotor_positions_array_m - np.asarray(vehicle.cg_offset_frd_m)
    roll = -(f * r[:, 1]).sum(axis=1)
    pitch = (f * r[:, 0]).sum(axis=1)
    yaw = (tau * vehicle.spin_sign).sum(axis=1)
    return np.stack([roll, pitch, yaw], axis=1)


def specific_force_body(seg: Segment, f: np.ndarray, vehicle: VehicleConfig) -> np.ndarray:
    """(T_fine, 3) what an IMU at the CG reads: (thrust + drag) / mass."""
    force = np.zeros((len(f), 3))
    force[:, 2] = -f.sum(axis=1)
    drag = np.asarray(vehicle.linear_drag_n_per_m_s)
    if seg.vel_ned_fine_m_s is not None and np.any(drag > 0):
        v_air_ned = seg.vel_ned_fine_m_s - np.asarray(vehicle.wind_ned_m_s)
        v_air_body = np.einsum("tji,tj->ti", seg.R_world_body_fine, v_air_ned)
        force -= drag * v_air_body
    return force / vehicle.mass_kg


def integrated(seg: Segment, x_fine: np.ndarray, window: int = SG_WINDOW) -> np.ndarray:
    """Trapezoid integral on the fine grid, read back at the log instants and SG-differentiated like the measurement."""
    return sg_deriv(cumtrapz(x_fine, seg.dt_fine_s)[::FINE], seg.dt_s, window)


def angular_accel(seg: Segment, vehicle: VehicleConfig, f: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(measured, predicted) filtered angular acceleration, each (T, 3)."""
    bias = np.asarray(vehicle.gyro_bias_frd_rad_s)
    omega = seg.rates_fine_rad_s - bias
    J = np.asarray(vehicle.inertia_diag_kg_m2)
    alpha = (body_moments(f, tau, vehicle) - np.cross(omega, omega * J)) / J
    return seg.rates_deriv_rad_s2, integrated(seg, alpha)


def residuals(seg: Segment, vehicle: VehicleConfig, speed_scale: SpeedScale = None) -> dict[str, np.ndarray]:
    """Named (T,) residuals, measured minus predicted; NaN outside ``seg.valid``."""
    f, tau = rotor_forces(seg, vehicle, speed_scale)
    bias = np.asarray(vehicle.gyro_bias_frd_rad_s)
    omega = seg.rates_rad_s - bias
    meas, pred = angular_accel(seg, vehicle, f, tau)
    rot = meas - pred
    out = {name: rot[:, i] for i, name in enumerate(ROT_SIGNALS)}
    fs = specific_force_body(seg, f, vehicle)
    # Velocity first: like the rates, it integrates the force between grid
    # instants, so it compares fairly with the integrated prediction. An IMU
    # snapshot is instantaneous and favours the last logged command (it pulls a
    # fitted motor lag low); it is the fallback when there is no velocity.
    if seg.vel_ned_m_s is not None:
        a_ned = np.einsum("tij,tj->ti", seg.R_world_body_fine, fs) + G_NED
        w = SG_WINDOW_TRANSLATION
        acc = seg.vel_deriv_ned_m_s2 - integrated(seg, a_ned, w)
        out.update({name: acc[:, i] for i, name in enumerate(VEL_SIGNALS)})
    elif seg.accel_frd_m_s2 is not None:
        w = SG_WINDOW_TRANSLATION
        acc = sg_smooth(seg.accel_frd_m_s2, w) - sg_smooth(fs[::FINE], w)
        out.update({name: acc[:, i] for i, name in enumerate(IMU_SIGNALS)})
    # Attitude kinematics, same integrate-then-differentiate form: a gyro bias shows here.
    kin = seg.euler_deriv_rad_s - sg_deriv(cumtrapz(euler_rates(seg.euler_rad, omega), seg.dt_s), seg.dt_s)
    out.update({name: kin[:, i] for i, name in enumerate(KIN_SIGNALS)})
    for v in out.values():
        v[~seg.valid] = np.nan
    return out


def trim_thrusts(vehicle: VehicleConfig, thrust_total_n: np.ndarray) -> np.ndarray:
    """(N, 4) rotor thrusts that give ``thrust_total_n`` with zero moment about the CG.

    Independent of ``motor_efficiency``: each rotor's torque/thrust ratio is
    ktau/kf whatever its efficiency, so a weak motor shows up only in the
    command it needs (``trim_commands``), not in the thrust split. A CG offset
    does change the split: along a diagonal it moves thrust between the two
    rotors of the same spin, the only change that keeps the yaw balance.
    """
    r = vehicle.rotor_positions_array_m - np.asarray(vehicle.cg_offset_frd_m)
    A = np.stack([np.ones(4), -r[:, 1], r[:, 0], vehicle.spin_sign * vehicle.ktau_nm_per_rad_s2 / vehicle.kf_n_per_rad_s2])
    rhs = np.zeros((len(thrust_total_n), 4))
    rhs[:, 0] = thrust_total_n
    return np.linalg.solve(A, rhs.T).T


def trim_commands(vehicle: VehicleConfig, thrust_total_n: np.ndarray, speed_scale: SpeedScale = None) -> np.ndarray:
    """(N, 4) ESC commands holding the trim thrusts (target RPM when the ESC is not modelled)."""
    f = trim_thrusts(vehicle, np.atleast_1d(np.asarray(thrust_total_n, dtype=np.float64)))
    w = np.sqrt(np.maximum(f, 0.0) / vehicle.kf_n_per_rad_s2)
    w_cmd = w / np.asarray(vehicle.motor_efficiency)
    if speed_scale is not None:
        for _ in range(20):  # the paper's ratio depends on the speed it corrects: fixed point
            w_cmd = w / speed_scale(w_cmd)
    return vehicle.esc.omega_rad_s_to_cmd(w_cmd)


def steady_thrust_n(seg: Segment, vehicle: VehicleConfig) -> np.ndarray:
    """(T,) total thrust the model needs to hold the measured attitude and velocity unaccelerated."""
    g_body = np.einsum("tji,j->ti", seg.R_world_body, G_NED) * vehicle.mass_kg
    t = g_body[:, 2].copy()
    drag = np.asarray(vehicle.linear_drag_n_per_m_s)
    if seg.vel_ned_m_s is not None:
        v_air = np.einsum("tji,tj->ti", seg.R_world_body, seg.vel_ned_m_s - np.asarray(vehicle.wind_ned_m_s))
        t -= drag[2] * v_air[:, 2]
    return t
