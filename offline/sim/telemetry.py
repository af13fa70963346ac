"""What the link and the estimator do to logged signals: attitude delay, sample-time jitter, dropped samples.

Applied after simulation to the canonical 20 Hz signals of each flight
(``FlightLog.signals()``), with the flight's drawn values and its own RNG:
- delay: attitude and rates are read ``attitude_log_delay_s`` earlier than the
  motor commands (linear interpolation on the log grid; yaw unwrapped first);
- jitter: each sample of each message group is taken at its slot time plus a
  normal offset of std ``telemetry_jitter_std_s`` (clipped to one period);
- drops: each sample of each group is lost with ``telemetry_drop_prob`` and the
  previous value is held (zero-order hold, as ``monitor/resample.py`` does
  within its staleness limit).
Groups: motor RPM (ESC / actuator outputs), attitude (roll, pitch, yaw), rates.
"""

from __future__ import annotations

import numpy as np

GROUPS = (("motor_rpm",), ("roll_rad", "pitch_rad", "yaw_rad"), ("roll_rate_rad_s", "pitch_rate_rad_s", "yaw_rate_rad_s"))


def _resample(x: np.ndarray, t_read: np.ndarray) -> np.ndarray:
    """x (T,) or (T, k) on grid 0..T-1, read at fractional sample times t_read (T,)."""
    t = np.clip(t_read, 0.0, len(x) - 1.0)
    i0 = np.minimum(np.floor(t).astype(np.int64), len(x) - 2)
    w = t - i0
    if x.ndim == 2:
        w = w[:, None]
    return x[i0] * (1.0 - w) + x[i0 + 1] * w


def _hold_drops(x: np.ndarray, dropped: np.ndarray) -> np.ndarray:
    """Each dropped sample takes the last kept one (the first sample is always kept)."""
    dropped = dropped.copy()
    dropped[0] = False
    last = np.where(~dropped, np.arange(len(x)), 0)
    np.maximum.accumulate(last, out=last)
    return x[last]


def degrade_flight(
    signals: dict[str, np.ndarray],
    rate_hz: float,
    delay_s: float,
    jitter_std_s: float,
    drop_prob: float,
    rng: np.random.Generator,
    groups: tuple[tuple[str, ...], ...] = GROUPS,
) -> dict[str, np.ndarray]:
    """One flight's signals (each (T,) or (T, k)) -> the degraded copy. ``groups``: message groups, the first
    (the motor outputs) undelayed, the others read ``delay_s`` earlier."""
    out = dict(signals)
    n = len(signals[groups[0][0]])
    grid = np.arange(n, dtype=np.float64)
    for g, names in enumerate(groups):
        shift = np.clip(rng.normal(0.0, jitter_std_s * rate_hz, n), -1.0, 1.0) if jitter_std_s > 0 else np.zeros(n)
        if g > 0:
            shift -= delay_s * rate_hz
        dropped = rng.random(n) < drop_prob
        for name in names:
            x = np.asarray(signals[name], dtype=np.float64)
            if name == "yaw_rad":
                x = np.unwrap(x)
            if np.any(shift):
                x = _resample(x, grid + shift)
            if dropped.any():
                x = _hold_drops(x, dropped)
            if name == "yaw_rad":
                x = (x + np.pi) % (2 * np.pi) - np.pi
            out[name] = x.astype(np.asarray(signals[name]).dtype)
    return out
