"""Onto the 20 Hz grid: zero-order hold on the autopilot's boot clock.

Grid instants are whole multiples of the period on the boot clock
(0, 50 000, 100 000 µs, ...), so a log read in one go and a live stream read
message by message land on the same instants. At each instant a stream
contributes its latest sample at or before it; if that sample is older than
``max_age_us`` (or there is none) the value is NaN: data is never invented.
"""

from __future__ import annotations

import numpy as np

US_PER_S = 1_000_000


def period_us(rate_hz: float) -> int:
    p = US_PER_S / rate_hz
    if abs(p - round(p)) > 1e-9:
        raise ValueError(f"rate_hz={rate_hz} does not give a whole number of microseconds")
    return int(round(p))


def grid_us(t_first_us: int, t_last_us: int, rate_hz: float) -> np.ndarray:
    """Grid instants covering [t_first_us, t_last_us], aligned to multiples of the period."""
    p = period_us(rate_hz)
    start = -(-int(t_first_us) // p) * p  # ceil to the grid
    if t_last_us < start:
        return np.empty(0, dtype=np.int64)
    return np.arange(start, int(t_last_us) + 1, p, dtype=np.int64)


def hold(sample_t_us: np.ndarray, values: np.ndarray, grid_t_us: np.ndarray, max_age_us: int) -> np.ndarray:
    """Zero-order hold of (N, ...) samples onto the grid; NaN where stale or absent.

    Samples must be sorted by time; duplicates keep the last one written.
    """
    t = np.asarray(sample_t_us, dtype=np.int64)
    v = np.asarray(values, dtype=np.float64)
    out_shape = (len(grid_t_us),) + v.shape[1:]
    if len(t) == 0:
        return np.full(out_shape, np.nan)
    if np.any(np.diff(t) < 0):
        raise ValueError("hold(): sample times must be sorted")
    idx = np.searchsorted(t, grid_t_us, side="right") - 1
    ok = idx >= 0
    out = np.full(out_shape, np.nan)
    age = np.where(ok, grid_t_us - t[np.clip(idx, 0, None)], np.iinfo(np.int64).max)
    ok &= age <= max_age_us
    out[ok] = v[idx[ok]]
    return out


def span_mean(sample_t_us: np.ndarray, values: np.ndarray, grid_t_us: np.ndarray, span_us: int, max_age_us: int) -> np.ndarray:
    """(G, W) at each grid instant g the mean of the finite samples in ``(g - span_us, g]``; NaN where every sample
    there is NaN; where the span holds no sample, ``hold`` (a stream slower than the grid), stale after
    ``max_age_us``. What the daemon's resampler gives a ``mean_us`` stream (monitor/daemon/resampler.py), so diagnose
    and the daemon feed the decision the same specific force: a 50-250 Hz accelerometer that vibrates, one sample
    of which held would be noise."""
    t = np.asarray(sample_t_us, dtype=np.int64)
    v = np.asarray(values, dtype=np.float64).reshape(len(t), -1)
    held = hold(t, v, grid_t_us, max_age_us)
    if len(t) == 0:
        return held
    finite = np.isfinite(v).all(axis=1)
    csum = np.vstack([np.zeros((1, v.shape[1])), np.cumsum(np.where(finite[:, None], v, 0.0), axis=0)])
    ccount = np.concatenate([[0], np.cumsum(finite)])
    hi = np.searchsorted(t, grid_t_us, side="right")
    lo = np.searchsorted(t, np.asarray(grid_t_us, dtype=np.int64) - int(span_us), side="right")
    in_span, n = hi - lo, ccount[hi] - ccount[lo]
    out = held.copy()
    some = in_span > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (csum[hi] - csum[lo]) / n[:, None]
    out[some] = np.where((n[some] > 0)[:, None], mean[some], np.nan)
    return out
