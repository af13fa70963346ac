"""Measured flight -> the arrays the equation-error fit needs, computed once.

Why these filters: at 20 Hz the rates and velocities are too coarse to
differentiate sample by sample. Instead of differentiating the measurement and
comparing it with an instantaneous prediction (which the controller's fast
motor changes between grid instants would alias), both sides go through the
*same* linear operator: the prediction is integrated (trapezoid) and then the
measured signal and the integrated prediction are both differentiated with one
Savitzky-Golay filter. ``SGd(omega) = SGd(integral of the predicted angular
acceleration)`` holds exactly for a perfect model, whatever the filter, so what
remains is model error plus noise. When the IMU's specific force is logged it
is compared directly, with the same SG smoothing on both sides.

The prediction is built on a grid ``FINE`` times finer than the log: the
logged commands, rates, attitude and velocity are interpolated with cubic
splines, the motor lag and the integral run there, and the integral is read
back at the log instants. Linear interpolation at 20 Hz loses amplitude
between samples, which a fitted motor time constant then absorbs (it came out
25 % low); the cubic spline removes that bias.

Each airborne segment is trimmed at both ends: ground contact during take-off
and landing puts forces on the vehicle that the flight model does not have.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import savgol_coeffs

from monitor.errors import LogFormatError
from monitor.flight import FlightTable, true_runs
from monitor.resample import US_PER_S
from monitor.vehicle import VehicleConfig

SG_WINDOW = 7  # samples (0.35 s at 20 Hz): long enough to average noise, short against manoeuvres
SG_POLYORDER = 2
# Translational channels are compared at lower bandwidth (1 s): the logged
# collective command is a snapshot of the position loop's slower staircase
# (50 Hz in PX4), so its timing is uncertain by ~10 ms, which at 0.35 s would
# masquerade as a motor lag. Mass, drag and the ESC scale are slow effects.
SG_WINDOW_TRANSLATION = 21
EDGE_TRIM_S = 1.0
MIN_SEGMENT_S = 3.0
MAX_TILT_DEG = 60.0
FINE = 5  # prediction grid: 5 x the log rate (10 ms at 20 Hz)


@dataclass(frozen=True)
class Segment:
    """One airborne stretch of one flight, with everything the fit reuses."""

    flight: int
    source: str
    dt_s: float
    time_s: np.ndarray  # (T,)
    motor_cmd: np.ndarray  # (T, 4) raw ESC command (NaN when the log has only RPM)
    motor_rpm: np.ndarray  # (T, 4) target RPM as logged
    rates_rad_s: np.ndarray  # (T, 3) measured body rates FRD
    euler_rad: np.ndarray  # (T, 3) roll, pitch, yaw (yaw unwrapped)
    R_world_body: np.ndarray  # (T, 3, 3)
    vel_ned_m_s: np.ndarray | None  # (T, 3)
    accel_frd_m_s2: np.ndarray | None  # (T, 3) IMU specific force
    euler_deriv_rad_s: np.ndarray  # (T, 3) SG derivative of the logged attitude
    rates_deriv_rad_s2: np.ndarray  # (T, 3) SG derivative of the logged rates (a constant gyro bias drops out)
    vel_deriv_ned_m_s2: np.ndarray | None  # (T, 3) SG derivative of the velocity, translation window
    phase: np.ndarray  # (T,) str: hover / cruise / climb / manoeuvre
    valid: np.ndarray  # (T,) bool: inside the filter's support, away from the segment edges
    # The same signals on the fine prediction grid ((T - 1) * FINE + 1 instants).
    motor_cmd_fine: np.ndarray
    motor_rpm_fine: np.ndarray
    rates_fine_rad_s: np.ndarray
    R_world_body_fine: np.ndarray
    vel_ned_fine_m_s: np.ndarray | None

    @property
    def n(self) -> int:
        return len(self.time_s)

    @property
    def dt_fine_s(self) -> float:
        return self.dt_s / FINE


def upsample(x: np.ndarray, factor: int = FINE) -> np.ndarray:
    """Cubic spline through the samples onto a grid ``factor`` times finer (same first and last instant)."""
    t = np.arange(len(x), dtype=np.float64)
    tf = np.arange((len(x) - 1) * factor + 1, dtype=np.float64) / factor
    return CubicSpline(t, x, axis=0)(tf)


def sg_smooth(x: np.ndarray, window: int = SG_WINDOW) -> np.ndarray:
    return _sg(x, 0, 1.0, window)


def sg_deriv(x: np.ndarray, dt_s: float, window: int = SG_WINDOW) -> np.ndarray:
    return _sg(x, 1, dt_s, window)


@functools.lru_cache(maxsize=16)
def _sg_coeffs(window: int, deriv: int, dt_s: float) -> np.ndarray:
    return savgol_coeffs(window, SG_POLYORDER, deriv=deriv, delta=dt_s, use="dot")


def _sg(x: np.ndarray, deriv: int, dt_s: float, window: int) -> np.ndarray:
    """SG along axis 0, 'valid' style: the first/last half-window are NaN (never extrapolated)."""
    c = _sg_coeffs(window, deriv, float(dt_s))
    x = np.asarray(x, dtype=np.float64)
    h = window // 2
    out = np.full(x.shape, np.nan)
    if len(x) < window:
        return out
    win = np.lib.stride_tricks.sliding_window_view(x, window, axis=0)  # (T-w+1, ..., w)
    out[h : len(x) - h] = win @ c
    return out


def cumtrapz(x: np.ndarray, dt_s: float) -> np.ndarray:
    """Running trapezoid integral along axis 0, starting at 0."""
    out = np.zeros_like(x)
    out[1:] = np.cumsum(0.5 * (x[1:] + x[:-1]) * dt_s, axis=0)
    return out


def rotation_world_body(euler_rad: np.ndarray) -> np.ndarray:
    """R_world_body from ZYX Euler angles (roll, pitch, yaw), (T, 3, 3)."""
    phi, th, psi = euler_rad[:, 0], euler_rad[:, 1], euler_rad[:, 2]
    cf, sf, ct, st, cp, sp = np.cos(phi), np.sin(phi), np.cos(th), np.sin(th), np.cos(psi), np.sin(psi)
    R = np.empty((len(phi), 3, 3))
    R[:, 0, 0] = ct * cp
    R[:, 0, 1] = sf * st * cp - cf * sp
    R[:, 0, 2] = cf * st * cp + sf * sp
    R[:, 1, 0] = ct * sp
    R[:, 1, 1] = sf * st * sp + cf * cp
    R[:, 1, 2] = cf * st * sp - sf * cp
    R[:, 2, 0] = -st
    R[:, 2, 1] = sf * ct
    R[:, 2, 2] = cf * ct
    return R


def euler_rates(euler_rad: np.ndarray, rates_rad_s: np.ndarray) -> np.ndarray:
    """ZYX kinematics: Euler angle derivatives from body rates (p, q, r), (T, 3)."""
    phi, th = euler_rad[:, 0], euler_rad[:, 1]
    p, q, r = rates_rad_s[:, 0], rates_rad_s[:, 1], rates_rad_s[:, 2]
    sf, cf, ct = np.sin(phi), np.cos(phi), np.cos(th)
    return np.stack([p + (sf * q + cf * r) * np.tan(th), cf * q - sf * r, (sf * q + cf * r) / ct], axis=1)


def tilt_deg(roll_rad: np.ndarray, pitch_rad: np.ndarray) -> np.ndarray:
    """Angle between body z and the vertical, degrees (NaN in, NaN out)."""
    return np.degrees(np.arccos(np.clip(np.cos(roll_rad) * np.cos(pitch_rad), -1.0, 1.0)))


def flight_phases(vel_ned_m_s: np.ndarray | None, euler_rad: np.ndarray, rates_rad_s: np.ndarray) -> np.ndarray:
    """Label each sample hover / cruise / climb / manoeuvre (steady-state analysis uses hover and cruise)."""
    n = len(euler_rad)
    tilt = tilt_deg(euler_rad[:, 0], euler_rad[:, 1])
    rate = np.linalg.norm(rates_rad_s, axis=1)
    phase = np.full(n, "manoeuvre", dtype=object)
    if vel_ned_m_s is None:
        phase[(tilt < 3.0) & (rate < 0.15)] = "hover"
        return phase.astype(str)
    v_h = np.linalg.norm(vel_ned_m_s[:, :2], axis=1)
    v_z = np.abs(vel_ned_m_s[:, 2])
    acc = np.linalg.norm(np.nan_to_num(sg_deriv(vel_ned_m_s, 0.05)), axis=1)
    # Steady = unaccelerated and not rotating: the controller has settled each motor where the
    # vehicle needs it. Cruise is any steady translation, climbing or not (trim handles both).
    steady = (rate < 0.3) & (acc < 0.5)
    hover = steady & (v_h < 0.3) & (v_z < 0.2)
    phase[hover] = "hover"
    phase[steady & ~hover] = "cruise"
    phase[~steady & (v_z >= 0.3)] = "climb"
    return phase.astype(str)


def prepare(tables: list[FlightTable], vehicle: VehicleConfig) -> list[Segment]:
    """Cut each flight into airborne segments and precompute filters; raises when nothing is usable."""
    segs: list[Segment] = []
    for k, tab in enumerate(tables):
        dt = 1.0 / tab.rate_hz
        trim = int(round(EDGE_TRIM_S * tab.rate_hz))
        for a, b in _flying_segments(tab):
            a, b = a + trim, b - trim
            if b - a < MIN_SEGMENT_S * tab.rate_hz:
                continue
            seg = _segment(tab, k, a, b, dt, vehicle)
            if seg is not None:
                segs.append(seg)
    if not segs:
        names = ", ".join(t.source or f"flight {i}" for i, t in enumerate(tables))
        raise LogFormatError(
            f"{names}: no airborne stretch of at least {MIN_SEGMENT_S + 2 * EDGE_TRIM_S:.0f} s "
            "with motor commands, attitude and rates; nothing to calibrate against"
        )
    return segs


def _flying_segments(tab: FlightTable) -> list[tuple[int, int]]:
    """Airborne stretches inside the flight model's envelope: a flip or crash (tilt above
    MAX_TILT_DEG, often with ground contact) is no evidence about the vehicle's parameters."""
    tilt = tilt_deg(tab.roll_rad, tab.pitch_rad)
    return true_runs(tab.airborne.astype(bool) & (np.nan_to_num(tilt, nan=180.0) < MAX_TILT_DEG))


def _segment(tab: FlightTable, k: int, a: int, b: int, dt: float, vehicle: VehicleConfig) -> Segment | None:
    sl = slice(a, b)
    cmd = tab.motor_cmd[sl].astype(np.float64)
    rpm = tab.motor_rpm[sl].astype(np.float64)
    if np.all(np.isnan(cmd)):
        cmd = np.full_like(rpm, np.nan)
        if np.any(np.isnan(rpm)):
            return None
    elif np.any(np.isnan(cmd)):
        return None
    euler = np.stack([tab.roll_rad[sl], tab.pitch_rad[sl], np.unwrap(tab.yaw_rad[sl])], axis=1)
    rates = np.stack([tab.roll_rate_rad_s[sl], tab.pitch_rate_rad_s[sl], tab.yaw_rate_rad_s[sl]], axis=1)
    if np.any(np.isnan(euler)) or np.any(np.isnan(rates)):
        return None
    vel = None if tab.vel_ned_m_s is None else tab.vel_ned_m_s[sl].astype(np.float64)
    if vel is not None and np.any(np.isnan(vel)):
        vel = None
    acc = None if tab.accel_frd_m_s2 is None else tab.accel_frd_m_s2[sl].astype(np.float64)
    if acc is not None and np.any(np.isnan(acc)):
        acc = None
    t = (tab.timestamp_us[sl] - tab.timestamp_us[sl][0]) / US_PER_S
    valid = np.ones(b - a, dtype=bool)
    h = SG_WINDOW // 2
    h = max(h, SG_WINDOW_TRANSLATION // 2)
    valid[:h] = False
    valid[len(valid) - h :] = False
    return Segment(
        flight=k,
        source=tab.source or f"flight {k}",
        dt_s=dt,
        time_s=t,
        motor_cmd=cmd,
        motor_rpm=rpm,
        rates_rad_s=rates,
        euler_rad=euler,
        R_world_body=rotation_world_body(euler),
        vel_ned_m_s=vel,
        accel_frd_m_s2=acc,
        euler_deriv_rad_s=sg_deriv(euler, dt),
        rates_deriv_rad_s2=sg_deriv(rates, dt),
        vel_deriv_ned_m_s2=None if vel is None else sg_deriv(vel, dt, SG_WINDOW_TRANSLATION),
        phase=flight_phases(vel, euler, rates),
        valid=valid,
        motor_cmd_fine=upsample(cmd),
        motor_rpm_fine=upsample(rpm),
        rates_fine_rad_s=upsample(rates),
        R_world_body_fine=rotation_world_body(upsample(euler)),
        vel_ned_fine_m_s=None if vel is None else upsample(vel),
    )
