"""evalsim's wind, sensors, battery and telemetry: each a frozen config plus a small seeded process.

All in NED/FRD. Values are set away from the training simulator's on purpose;
README.md tabulates each with its reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Wind:
    """Mean wind plus Dryden-like gusts: a first-order (Gauss-Markov) process per axis.

    The Dryden spectrum's low-altitude form is first order in each component with
    time constant L/V; with the length scales of a few metres of altitude and
    the few-m/s airspeeds here, L/V is 1-4 s. ``flight.simulate_flights`` steps it.
    """

    mean_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    gust_std_m_s: Vec3 = (0.0, 0.0, 0.0)
    gust_time_constant_s: Vec3 = (3.0, 3.0, 1.0)


@dataclass(frozen=True)
class Sensors:
    """What the autopilot's estimator hands the controller and the log (PX4 vehicle_angular_velocity etc.)."""

    gyro_noise_std_rad_s: float = 0.004  # after PX4's gyro low-pass, per sample
    gyro_bias_std_rad_s: float = 0.003  # per-flight constant bias, per axis
    # The airframe's own gyro offset, added to the per-flight draw (the calibration matrix's gyro-bias effect).
    gyro_bias_frd_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_noise_std_m_s2: float = 0.08
    attitude_noise_std_rad: float = np.deg2rad(0.15)
    attitude_bias_std_rad: float = np.deg2rad(0.4)  # per-flight estimator tilt error (roll, pitch)
    velocity_noise_std_m_s: float = 0.05
    position_noise_std_m: float = 0.05
    gyro_vibration_rad_s_per_m_s2: float = 0.01  # 1P rocking seen by the gyro per m/s² of 1P acceleration
    vibration_filter_gain: float = 0.35  # PX4's gyro/accel low-pass (~30 Hz) at the ~90 Hz 1P frequency
    healthy_vibration_m_s2: float = 0.05  # residual imbalance of a healthy propeller


@dataclass(frozen=True)
class Telemetry:
    """MAVLink telemetry as QGroundControl records it: nominal rate, jitter and rare drops."""

    rate_hz: float = 20.0
    jitter_std_s: float = 0.004
    drop_probability: float = 0.003


def sample_times_s(cfg: Telemetry, duration_s: float, rng: np.random.Generator) -> np.ndarray:
    """Increasing send times of the telemetry samples in [0, duration_s)."""
    n = int(round(duration_s * cfg.rate_hz))
    t = np.arange(n) / cfg.rate_hz + rng.normal(0.0, cfg.jitter_std_s, n)
    t[0] = 0.0
    keep = rng.random(n) >= cfg.drop_probability
    keep[0] = keep[-1] = True
    dropped = np.flatnonzero(~keep)  # never two drops in a row: held values stay fresh
    keep[dropped[np.flatnonzero(np.diff(dropped) == 1) + 1]] = True
    t = np.clip(t[keep], 0.0, duration_s - 1e-6)
    return np.maximum.accumulate(t)


class Battery:
    """4S packs (one per flight, arrays): linear open-circuit voltage over charge, internal resistance."""

    def __init__(self, full_v, empty_v, capacity_mah, r_ohm, start_soc):
        self.full_v, self.empty_v = np.asarray(full_v, float), np.asarray(empty_v, float)
        self.r = np.asarray(r_ohm, float)
        self.capacity_c = np.asarray(capacity_mah, float) * 3.6
        self.soc = np.asarray(start_soc, float).copy()
        self.voltage_v = self.ocv()
        self.current_a = np.zeros_like(self.voltage_v)

    def ocv(self) -> np.ndarray:
        return self.empty_v + (self.full_v - self.empty_v) * self.soc

    def step(self, power_w: np.ndarray, dt_s: float) -> None:
        v = self.ocv()
        # I from P = I (V_oc - I R), the smaller root (R > 0 is required by the vehicle config).
        disc = np.maximum(v * v - 4.0 * self.r * power_w, 0.0)
        self.current_a = (v - np.sqrt(disc)) / (2.0 * np.maximum(self.r, 1e-9))
        self.voltage_v = v - self.current_a * self.r
        self.soc = np.maximum(self.soc - self.current_a * dt_s / self.capacity_c, 0.0)
