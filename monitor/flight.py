"""The canonical flight table: what every log reader produces and every consumer reads.

A ``FlightTable`` is one flight on a uniform grid (20 Hz by default) of the
autopilot's boot clock. Rotor columns are in PX4 quad-X order (see
``monitor.vehicle``); readers map their own motor numbering at the boundary
and record it in ``motor_names`` (e.g. CrazyPAD's ``M1..M4``).
NaN marks a value that was not measured at that instant.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from monitor.errors import LogFormatError


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges where a 1-D boolean mask is true."""
    d = np.diff(np.concatenate([[0], np.asarray(mask, dtype=bool).astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


@dataclass(frozen=True)
class FlightTable:
    timestamp_us: np.ndarray  # (T,) int64, autopilot boot clock, uniform grid
    motor_cmd: np.ndarray  # (T, 4) raw ESC command (PWM µs, or the vehicle's unit), NaN if unknown
    motor_rpm: np.ndarray  # (T, 4) target RPM (ESC fit, or ESC telemetry when configured)
    roll_rad: np.ndarray
    pitch_rad: np.ndarray
    yaw_rad: np.ndarray
    roll_rate_rad_s: np.ndarray
    pitch_rate_rad_s: np.ndarray
    yaw_rate_rad_s: np.ndarray
    battery_v: np.ndarray  # (T,) NaN where unknown
    airborne: np.ndarray  # (T,) bool: armed and flying
    rate_hz: float = 20.0
    source: str = ""
    motor_names: tuple[str, str, str, str] = ("1", "2", "3", "4")
    warnings: tuple[str, ...] = field(default_factory=tuple)
    # Optional measured extras (None when the log lacks them); calibration uses them.
    accel_frd_m_s2: np.ndarray | None = None  # (T, 3) specific force from the IMU, FRD
    vel_ned_m_s: np.ndarray | None = None  # (T, 3)
    pos_ned_m: np.ndarray | None = None  # (T, 3)
    extras: dict = field(default_factory=dict)  # reader-specific columns, e.g. {"motor_pwm_applied": (T,4)}

    def __post_init__(self) -> None:
        n = len(self.timestamp_us)
        for name in ("motor_cmd", "motor_rpm"):
            if getattr(self, name).shape != (n, 4):
                raise LogFormatError(f"{self.source}: {name} must have shape ({n}, 4), got {getattr(self, name).shape}")
        for name in (
            "roll_rad",
            "pitch_rad",
            "yaw_rad",
            "roll_rate_rad_s",
            "pitch_rate_rad_s",
            "yaw_rate_rad_s",
            "battery_v",
            "airborne",
        ):
            if getattr(self, name).shape != (n,):
                raise LogFormatError(f"{self.source}: {name} must have shape ({n},), got {getattr(self, name).shape}")
        for name in ("accel_frd_m_s2", "vel_ned_m_s", "pos_ned_m"):
            v = getattr(self, name)
            if v is not None and v.shape != (n, 3):
                raise LogFormatError(f"{self.source}: {name} must have shape ({n}, 3), got {v.shape}")

    def __len__(self) -> int:
        return len(self.timestamp_us)

    def signals(self) -> dict[str, np.ndarray]:
        """The canonical signals that ``monitor.features`` consumes."""
        return {
            "motor_rpm": self.motor_rpm,
            "roll_rad": self.roll_rad,
            "pitch_rad": self.pitch_rad,
            "yaw_rad": self.yaw_rad,
            "roll_rate_rad_s": self.roll_rate_rad_s,
            "pitch_rate_rad_s": self.pitch_rate_rad_s,
            "yaw_rate_rad_s": self.yaw_rate_rad_s,
        }

    def airborne_segments(self) -> list[tuple[int, int]]:
        """[start, stop) index ranges where ``airborne`` is true."""
        return true_runs(self.airborne)
