"""Streaming zero-order hold onto the boot-clock grid, equal to ``monitor.resample.hold``.

Samples arrive one at a time, streams interleaved. A grid instant ``g`` is
*final* once every pacing stream has delivered a sample later than
``g + reorder_us`` (nothing that could still change ``g`` is pending), or once
the boot clock has passed ``g + max_age + reorder_us`` (a stream that stopped:
its value at ``g`` can only be stale or held from what we already have).
At a final instant each stream contributes exactly what the batch ``hold()``
gives on the same samples: its latest sample at or before ``g`` (the last one
written among equal times), or NaN when that is older than its ``max_age_us``.

A sample at or before an instant already emitted cannot change it any more:
it is dropped and counted in ``late`` (the batch path would still use it;
PX4 sends each stream in order, so this needs reordering beyond
``reorder_us`` within one stream).

A stream with ``moves_clock=False`` (optional context such as velocity) is held
the same way but never starts the grid or moves the boot clock: which
instants are emitted, and when, is exactly what it would be without it. It
keeps only the samples within its ``max_age_us`` of its newest one (and the one
before), so it stays small while no grid runs.

A stream with ``mean_us > 0`` (the accelerometer: 50-250 Hz and vibrating)
gives at ``g`` the mean of its finite samples in ``(g - mean_us, g]``, not one
sample held; NaN when all of them are NaN (an implausible sample dropped is
NaN). A span with no sample at all is held as above (a stream slower than the
grid), stale after ``max_age_us``.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

import numpy as np

# Beyond this many instants in one go (a link that returns after a long drop), the instants in between are
# skipped: a window spanning them is invalid anyway. Fewer still where every stream is stale sooner: past the
# longest max_age every instant is empty, so at most that many (plus one) are emitted per sample.
MAX_CATCH_UP_STEPS = 1200
# Hard size of each stream's pending samples. A sample at the same boot time as the newest one
# replaces it (the batch hold keeps the last written among equal times, so nothing changes); this
# cap only bites when the clock of one stream runs ahead of the others' without bound: the oldest
# pending samples are dropped and counted in ``overflow``.
MAX_PENDING_SAMPLES = 2048


@dataclass(frozen=True)
class StreamSpec:
    width: int
    max_age_us: int
    paces: bool  # a pacing stream gates when an instant is final (the fast ones)
    moves_clock: bool = True  # False: held, but its samples neither start the grid nor make instants final
    mean_us: int = 0  # > 0: the value at g is the mean of the samples in (g - mean_us, g] (see the module doc)


@dataclass(frozen=True)
class GridStep:
    timestamp_us: int
    values: dict[str, np.ndarray]  # stream -> (width,) float64, NaN where stale/absent
    skipped_before: int = 0  # instants skipped just before this one (long gap)


class _Stream:
    __slots__ = ("spec", "times", "values", "last_t")

    def __init__(self, spec: StreamSpec):
        self.spec = spec
        self.times: list[int] = []
        self.values: list[np.ndarray] = []
        self.last_t: int | None = None  # latest time ever received

    def value_at(self, g: int) -> np.ndarray:
        i = bisect.bisect_right(self.times, g) - 1
        if i < 0 or g - self.times[i] > self.spec.max_age_us:
            return np.full(self.spec.width, np.nan)
        if self.spec.mean_us:
            lo = bisect.bisect_right(self.times, g - self.spec.mean_us)
            if lo <= i:  # samples in the span: their mean (a handful, so a loop beats np.nanmean's overhead)
                good = [v for v in self.values[lo : i + 1] if not np.isnan(v).any()]
                return sum(good) / len(good) if good else np.full(self.spec.width, np.nan)
        return self.values[i]

    def prune(self, g: int) -> None:
        # Keep the latest sample at or before g (it may hold the next instants) and all later ones.
        i = bisect.bisect_right(self.times, g) - 1
        if i > 0:
            del self.times[:i], self.values[:i]


class StreamingHold:
    def __init__(self, period_us: int, streams: dict[str, StreamSpec], reorder_us: int = 0):
        if period_us <= 0:
            raise ValueError("period_us must be positive")
        self.period_us = period_us
        self.specs = dict(streams)
        self.reorder_us = reorder_us
        self.late = 0
        self.overflow = 0
        self.reset()

    def reset(self) -> None:
        self._streams = {k: _Stream(s) for k, s in self.specs.items()}
        # What _is_final reads at every sample, worked out once: the pacing streams, and the boot time past an
        # instant after which it is final whatever they hold.
        self._pacing = [s for s in self._streams.values() if s.spec.paces]
        self._horizon_us = max((s.spec.max_age_us for s in self._pacing), default=0) + self.reorder_us
        oldest_us = max((s.spec.max_age_us for s in self._streams.values()), default=0) + self.reorder_us
        self._catch_up = min(MAX_CATCH_UP_STEPS, -(-oldest_us // self.period_us) + 1)
        self.next_g: int | None = None
        self.last_emitted: int | None = None
        self.clock_us: int | None = None

    def push(self, stream: str, t_us: int, values) -> list[GridStep]:
        """Add one sample; return the instants it made final, in order."""
        s = self._streams[stream]
        t_us = int(t_us)
        if self.last_emitted is not None and t_us <= self.last_emitted:
            self.late += 1  # at or before an instant already emitted
            return []
        v = np.asarray(values, dtype=np.float64).reshape(s.spec.width)
        if s.times and s.times[-1] == t_us:  # a frozen clock: the newest sample at that time wins, as in hold()
            s.values[-1] = v
            return []
        i = bisect.bisect_right(s.times, t_us)
        s.times.insert(i, t_us)
        s.values.insert(i, v)
        if len(s.times) > MAX_PENDING_SAMPLES:
            del s.times[0], s.values[0]
            self.overflow += 1
        s.last_t = t_us if s.last_t is None else max(s.last_t, t_us)
        if not s.spec.moves_clock:
            # Bounded even while no grid runs: older samples only hold instants more than max_age behind its newest
            # (a mean stream keeps one span more, so an instant that is not stale still has its whole span).
            s.prune(s.last_t - s.spec.max_age_us - s.spec.mean_us)
            return []  # nothing it holds can make an instant final
        self.clock_us = t_us if self.clock_us is None else max(self.clock_us, t_us)
        if self.next_g is None:
            self.next_g = -(-t_us // self.period_us) * self.period_us  # ceil to the grid, as grid_us()
        return self._emit(final_only=True)

    def flush(self) -> list[GridStep]:
        """End of input: every instant up to the latest boot time is final."""
        return self._emit(final_only=False)

    def _is_final(self, g: int) -> bool:
        if self.clock_us is not None and self.clock_us >= g + self._horizon_us:
            return True
        after = g + self.reorder_us
        return all(s.last_t is not None and s.last_t > after for s in self._pacing)

    def _emit(self, final_only: bool) -> list[GridStep]:
        out: list[GridStep] = []
        if self.next_g is None or self.clock_us is None:
            return out
        skipped = 0
        backlog = (self.clock_us - self.next_g) // self.period_us
        if backlog > self._catch_up:
            jump = backlog - self._catch_up
            self.next_g += jump * self.period_us
            skipped = int(jump)
        while self.next_g <= self.clock_us and (not final_only or self._is_final(self.next_g)):
            g = self.next_g
            out.append(GridStep(g, {k: s.value_at(g) for k, s in self._streams.items()}, skipped))
            skipped = 0
            for s in self._streams.values():
                s.prune(g)
            self.next_g = g + self.period_us
            self.last_emitted = g
        return out
