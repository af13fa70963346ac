"""Window indices over flights, never materialising all windows.

A data set's features are (B, T, F); ``monitor.features.sliding_windows``
gives a strided (B, N, window, F) view and a batch is gathered from it by
(flight, start) index pairs, so memory stays at one batch.
"""

from __future__ import annotations

import numpy as np

from monitor.features import sliding_windows


def valid_starts(features: np.ndarray, window: int) -> np.ndarray:
    """(B, N) bool: window starting at step n of flight b has no NaN/inf (never learn from invented data)."""
    bad = ~np.isfinite(features).all(axis=-1)  # (B, T)
    c = np.concatenate([np.zeros((bad.shape[0], 1), np.int64), np.cumsum(bad, axis=1)], axis=1)
    n = bad.shape[1] - window + 1
    if n <= 0:
        return np.zeros((bad.shape[0], 0), bool)
    return (c[:, window : window + n] - c[:, :n]) == 0


def window_index(
    features: np.ndarray, window: int, stride: int = 1, flights: np.ndarray | None = None, offset: int = 0
) -> np.ndarray:
    """(M, 2) int64 [flight, start] pairs of valid windows, every ``stride`` steps from ``offset``."""
    ok = valid_starts(features, window)
    if flights is None:
        flights = np.arange(features.shape[0])
    cols = np.arange(offset % max(stride, 1), ok.shape[1], stride)
    f, s = np.meshgrid(flights, cols, indexing="ij")
    keep = ok[f, s]
    return np.stack([f[keep], s[keep]], axis=1).astype(np.int64)


def gather(features: np.ndarray, index: np.ndarray, window: int) -> np.ndarray:
    """(len(index), window, F) float32 copy of just the requested windows."""
    view = sliding_windows(features, window)  # (B, N, window, F), no copy
    return np.ascontiguousarray(view[index[:, 0], index[:, 1]], dtype=np.float32)
