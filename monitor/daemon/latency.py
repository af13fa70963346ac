"""A fixed-size latency histogram: constant memory however long the monitor runs.

Bins are log-spaced from 10 µs to 10 s (``BINS_PER_DECADE`` per decade, so a
percentile is exact to within one bin, about 2 %), plus one underflow and one
overflow bin. The flight-hour cost is zero bytes, where a list of floats grew
~2.3 MB per flight-hour.
"""

from __future__ import annotations

import math

import numpy as np

LO_S = 1e-5
DECADES = 6
BINS_PER_DECADE = 100


class LatencyHistogram:
    def __init__(self) -> None:
        self.edges_s = LO_S * 10.0 ** (np.arange(DECADES * BINS_PER_DECADE + 1) / BINS_PER_DECADE)
        self.counts = np.zeros(len(self.edges_s) + 1, dtype=np.int64)  # [under, bins..., over]
        self.n = 0
        self.max_s = math.nan
        self._log_lo = math.log10(LO_S)

    def add(self, latency_s: float) -> None:
        if not math.isfinite(latency_s):
            return
        if latency_s < LO_S:
            i = 0
        else:
            i = min(int((math.log10(latency_s) - self._log_lo) * BINS_PER_DECADE) + 1, len(self.counts) - 1)
        self.counts[i] += 1
        self.n += 1
        self.max_s = latency_s if not self.max_s >= latency_s else self.max_s

    def percentile_s(self, q: float) -> float:
        """Upper edge of the bin holding the q-th percentile (a bound, never an under-estimate)."""
        if self.n == 0:
            return math.nan
        rank = math.ceil(q / 100.0 * self.n)
        i = int(np.searchsorted(np.cumsum(self.counts), max(rank, 1)))
        if i == 0:
            return LO_S
        if i >= len(self.counts) - 1:
            return self.max_s
        return min(float(self.edges_s[i]), self.max_s)

    def percentiles_ms(self) -> dict:
        """The report's figures: count, p50, p99 and max in milliseconds."""
        return {"n": self.n, "p50": self.percentile_s(50) * 1e3, "p99": self.percentile_s(99) * 1e3, "max": self.max_s * 1e3}
