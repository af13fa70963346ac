"""When to read next: sleep through the datagrams that cannot complete the next grid step.

The loop used to wake for every datagram (~106 a second from PX4), and a wake-up of a Python process
costs far more than its work (a cold cache: ~80 µs to select and read one datagram, measured by
``bench/bench_daemon_phases.py --floor``). Only the datagram that completes a grid step is urgent
(its latency is the monitor's); the others can wait in the socket and be read with it.

A step at boot time ``g`` is final once every pacing stream (attitude, motor) has a sample later
than ``g`` (``StreamingHold``). A stream's next sample can come no earlier than any of its latest
``ANCHORS`` samples plus the shortest span of as many sample intervals as it had recently, nor
earlier than ``g``; and a sample stamped ``t`` on the autopilot's boot clock cannot arrive before
``t`` plus the smallest arrival-minus-stamp offset that stream recently had. The latest of those,
over the streams still missing, is the earliest the step can complete: the loop sleeps until then
(at most ``MAX_PAUSE_S``) and reads everything waiting.

Every bound is a lower bound learnt from the stream, so a loose one costs wake-ups, not latency;
it is wrong only where the schedule itself changes (a faster stream, a replay sped up, a link whose
delay falls, a jitter larger than any seen in the last seconds). That is checked on
every completed step: if its completing sample arrived more than ``LATE_TOLERANCE_S`` before the
bound planned for it, pacing stops for ``SUSPEND_S`` and the loop wakes for every datagram.
"""

from __future__ import annotations

import math
from collections import deque

from monitor.resample import US_PER_S

MAX_PAUSE_S = 0.1  # at most the idle select timeout (service.READ_TIMEOUT_S): housekeeping keeps its pace
LATE_TOLERANCE_S = 0.0015  # a completing sample this much earlier than its bound: the bound was wrong
SUSPEND_S = 10.0  # after such a miss, wake for every datagram this long
RECENT_S = 5.0  # offsets and spans are the minima over the last 5 to 10 s
ANCHORS = 4  # the latest samples each next sample is bounded from
MIN_SAMPLES = 50  # a stream's schedule is trusted from this many samples on (start, reset): 1-2 s of PX4's streams


class _RecentMin:
    """Minimum over the last one to two windows of ``span_s`` (two buckets, constant memory)."""

    __slots__ = ("span_s", "_start", "_cur", "_prev")

    def __init__(self, span_s: float):
        self.span_s = span_s
        self._start, self._cur, self._prev = -math.inf, math.inf, math.inf

    def add(self, value: float, now_s: float) -> None:
        if now_s - self._start >= self.span_s:
            self._start, self._prev, self._cur = now_s, self._cur, math.inf
        if value < self._cur:
            self._cur = value

    @property
    def value(self) -> float:
        return min(self._cur, self._prev)


class _StreamTiming:
    """One pacing stream: its latest sample times, the shortest span of 1, 2, ... intervals between its
    samples, and its smallest arrival-minus-stamp offset (minima over the last few seconds)."""

    __slots__ = ("samples", "offset_s", "recent_us", "span_us")

    def __init__(self) -> None:
        self.samples = 0
        self.offset_s = _RecentMin(RECENT_S)  # arrival (s, the loop's clock) - boot stamp (s)
        self.recent_us: deque[int] = deque(maxlen=ANCHORS)  # latest sample times, oldest first
        self.span_us = [_RecentMin(RECENT_S) for _ in range(ANCHORS)]  # [m - 1]: shortest span of m intervals

    def add(self, t_us: int, arrival_s: float) -> None:
        self.offset_s.add(arrival_s - t_us / US_PER_S, arrival_s)
        if self.recent_us and t_us <= self.recent_us[-1]:
            return  # out of order or repeated: its offset counts, its spacing does not
        for m, before in enumerate(reversed(self.recent_us)):
            self.span_us[m].add(t_us - before, arrival_s)
        self.recent_us.append(t_us)
        self.samples += 1

    def next_us(self) -> float:
        """A lower bound on the boot time of the next sample: each of the latest samples plus the shortest span
        of as many intervals as separate it from the next; the tightest of them (a jittered stream's best
        anchor, not merely its latest sample). A dropped sample only moves the next one later."""
        return max(before + self.span_us[m].value for m, before in enumerate(reversed(self.recent_us)))


class ReadPacer:
    """Learns each pacing stream's schedule from what arrives; plans the next wake-up; checks the plan."""

    def __init__(self, streams: tuple[str, ...]):
        self.streams = tuple(streams)
        self.misses = 0  # completed steps whose sample waited past the tolerance for a planned wake-up
        self.reset()

    def reset(self) -> None:
        """Forget the schedule (a reboot, a clock step, a reset of the hold)."""
        self._timing = {s: _StreamTiming() for s in self.streams}
        self._plan_s: float | None = None
        self._suspended_until = -math.inf

    def observe(self, stream: str, t_us: int, arrival_s: float, completed: bool) -> None:
        """One sample of a pacing stream, at boot time ``t_us``, arrived at ``arrival_s``; ``completed``: it made
        at least one grid step final."""
        self._timing[stream].add(t_us, arrival_s)
        if completed and self._plan_s is not None:
            if arrival_s < self._plan_s - LATE_TOLERANCE_S:
                self.misses += 1
                self._suspended_until = arrival_s + SUSPEND_S
            self._plan_s = None

    def wake_at(self, after_us: int | None, now_s: float) -> float | None:
        """The earliest time (the arrival clock) the next grid step can complete, None when unknown or while
        pacing is suspended. The step completes when every pacing stream has a sample later than ``after_us``
        (the step's boot time plus the hold's reorder allowance)."""
        if after_us is None or now_s < self._suspended_until:
            return None
        wake = -math.inf
        for tm in self._timing.values():
            if tm.recent_us and tm.recent_us[-1] > after_us:
                continue  # this stream already has its sample
            if tm.samples < MIN_SAMPLES:
                return None  # schedule not learnt yet
            wake = max(wake, max(after_us + 1, tm.next_us()) / US_PER_S + tm.offset_s.value)
        if not math.isfinite(wake):
            return None
        self._plan_s = wake
        return wake
