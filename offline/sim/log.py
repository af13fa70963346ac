"""``FlightLog``: simulated flights as a frozen dataclass of arrays (leading axis = flight).

Samples are at ``log_rate_hz`` on the autopilot boot clock: ``time_s`` counts
from the start of the simulated flight, ``timestamp_us`` = boot time at the
start (``BOOT_OFFSET_US``, as a real log never starts at boot) + ``time_s``.
Units and frames are in the names; rotor columns in PX4 quad-X order.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from monitor.esc import RPM_PER_RAD_S
from monitor.features import SIGNALS
from monitor.flight import FlightTable

BOOT_OFFSET_US = 5_000_000  # the flight starts 5 s after the autopilot booted

# Per-flight arrays (leading axis B) and the shared time axes.
TIME_FIELDS = ("time_s", "timestamp_us")


@dataclass(frozen=True)
class FlightLog:
    time_s: np.ndarray  # (T,)
    timestamp_us: np.ndarray  # (T,) int64 boot clock
    pos_ned_m: np.ndarray  # (B, T, 3)
    vel_ned_m_s: np.ndarray  # (B, T, 3)
    q_world_body: np.ndarray  # (B, T, 4) ground truth
    roll_rad: np.ndarray  # (B, T) estimator output (truth + attitude noise)
    pitch_rad: np.ndarray
    yaw_rad: np.ndarray
    rates_frd_rad_s: np.ndarray  # (B, T, 3) gyro: truth + noise + bias
    accel_frd_m_s2: np.ndarray  # (B, T, 3) IMU specific force
    motor_omega_rad_s: np.ndarray  # (B, T, 4) actual rotor speed
    thrust_n: np.ndarray  # (B, T, 4)
    torque_nm: np.ndarray  # (B, T, 4) drag-torque magnitude
    pwm_us: np.ndarray  # (B, T, 4) ESC command sent by the controller
    motor_rpm: np.ndarray  # (B, T, 4) target RPM = ESC fit of pwm_us (monitor.esc)
    battery_v: np.ndarray  # (B, T) loaded pack voltage
    battery_current_a: np.ndarray  # (B, T)
    waypoint_error_ned_m: np.ndarray  # (B, T, 3) target waypoint - position
    waypoint_index: np.ndarray  # (B, T) int, waypoint being flown to
    log_rate_hz: float = 20.0

    def __len__(self) -> int:
        return self.pos_ned_m.shape[0]

    @property
    def n_samples(self) -> int:
        return len(self.time_s)

    def array_fields(self) -> list[str]:
        return [f.name for f in fields(self) if f.name != "log_rate_hz"]

    def select(self, idx) -> FlightLog:
        """The flights ``idx`` (int, slice, index array or mask), keeping the leading axis."""
        if isinstance(idx, (int, np.integer)):
            idx = [int(idx)]
        kw = {n: (getattr(self, n) if n in TIME_FIELDS else getattr(self, n)[idx]) for n in self.array_fields()}
        return FlightLog(log_rate_hz=self.log_rate_hz, **kw)

    def signals(self) -> dict[str, np.ndarray]:
        """Canonical signals for ``monitor.features`` (leading axis B, time next), named by ``SIGNALS``."""
        rates = self.rates_frd_rad_s
        values = (self.motor_rpm, self.roll_rad, self.pitch_rad, self.yaw_rad, rates[..., 0], rates[..., 1], rates[..., 2])
        return dict(zip(SIGNALS, values, strict=True))

    def to_flight_table(self, i: int, source: str = "sim") -> FlightTable:
        """Flight ``i`` as the canonical ``FlightTable`` (airborne throughout: flights start in hover)."""
        n = self.n_samples
        return FlightTable(
            timestamp_us=self.timestamp_us.copy(),
            motor_cmd=self.pwm_us[i].copy(),
            motor_rpm=self.motor_rpm[i].copy(),
            roll_rad=self.roll_rad[i].copy(),
            pitch_rad=self.pitch_rad[i].copy(),
            yaw_rad=self.yaw_rad[i].copy(),
            roll_rate_rad_s=self.rates_frd_rad_s[i, :, 0].copy(),
            pitch_rate_rad_s=self.rates_frd_rad_s[i, :, 1].copy(),
            yaw_rate_rad_s=self.rates_frd_rad_s[i, :, 2].copy(),
            battery_v=self.battery_v[i].copy(),
            airborne=np.ones(n, dtype=bool),
            rate_hz=float(self.log_rate_hz),
            source=source,
            accel_frd_m_s2=self.accel_frd_m_s2[i].copy(),
            vel_ned_m_s=self.vel_ned_m_s[i].copy(),
            pos_ned_m=self.pos_ned_m[i].copy(),
            # The same key the log readers use for ESC telemetry (the rotors' actual speed).
            extras={"esc_rpm": self.motor_omega_rad_s[i] * RPM_PER_RAD_S},
        )

    @staticmethod
    def concatenate(logs: list[FlightLog]) -> FlightLog:
        """Join logs of the same length and rate along the flight axis."""
        first = logs[0]
        for lg in logs[1:]:
            if lg.n_samples != first.n_samples or lg.log_rate_hz != first.log_rate_hz:
                raise ValueError("FlightLog.concatenate: logs differ in length or rate")
        kw = {
            n: (getattr(first, n) if n in TIME_FIELDS else np.concatenate([getattr(lg, n) for lg in logs]))
            for n in first.array_fields()
        }
        return FlightLog(log_rate_hz=first.log_rate_hz, **kw)
