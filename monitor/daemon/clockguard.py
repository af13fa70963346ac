"""A boot clock that only changes for a plausible sequence, never for one frame.

The daemon's grid, its reboot detection and every stream's staleness follow
the autopilot's boot clock (``MavlinkDecoder.clock_us``). One message is enough
to move that clock: a far-future ATTITUDE made the grid catch up thousands of
empty steps per message, and a valid-CRC random payload read as a reboot. Here a
sample whose boot time is more than ``JUMP_US`` ahead of the clock, or more
than ``BACK_US`` behind it, is a *candidate* clock: it is dropped (counted in
``refused``) until ``CONFIRM_SAMPLES`` samples agree with it (each within
``JUMP_US`` of the candidate's latest; up to ``MAX_CANDIDATES`` candidates are
followed at once, the weakest forgotten first, so junk in between does not hide a real one) with none on the
old clock in between. The first clock of a run is confirmed the same way. A genuine reboot or clock step (the old clock stops, the new one runs)
is confirmed within a tenth of a second of PX4's streams; a forger interleaved
with a live autopilot never is, and random boot times never agree with each
other. The first refusal of a run, and then at most one per ``TELL_PERIOD_S``
of boot time, is written to the journal with the count ("clock jumped +3600.0 s").

``GuardedDecoder`` is the decoder with this check in front of every boot-time
stamp (all the timed messages pass ``_stamp``); HEARTBEAT, battery and landed
state carry no time and are placed at the clock as before. A confirmed clock
that is ahead by more than the arrival time since the old clock's last sample
(plus ``JUMP_US``) is a clock event, not a gap (a recorded log's arrival times
are its own: a hole in a .tlog stays a gap at any replay speed): it is handed on as a forward
``ClockReset`` (the pipeline says "autopilot clock jumped +X s" and starts its
grid again) instead of a catch-up over the empty instants.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from monitor.mavlink import decode as md
from monitor.resample import US_PER_S

log = logging.getLogger("propwatch.monitor")

# A step of the boot clock beyond these is a clock change, not a sample: PX4's streams come 10-250 times a
# second, so 2 s ahead is no jitter; back is the decoder's own reboot threshold (pipeline.CLOCK_BACK_US).
JUMP_US = 2 * US_PER_S
BACK_US = US_PER_S
CONFIRM_SAMPLES = 10  # PX4 sends ~100 timed messages a second: a tenth of a second of agreement
MAX_CANDIDATES = 4
TELL_PERIOD_S = 60.0


class ClockJumped(Exception):
    """A sample's boot time is a candidate clock not (yet) confirmed: the message is dropped."""


class ClockGuard:
    def __init__(self) -> None:
        self.refused = 0  # samples dropped on a candidate clock
        self.confirmed = 0  # candidate clocks that became the clock
        self._candidates: list[list[int]] = []  # [latest boot time, samples agreeing]
        self._told_at_us: int | None = None

    def check(self, t_us: int, clock_us: int | None) -> bool:
        """True: ``t_us`` may move the clock (or sit behind it as usual); False: dropped."""
        if clock_us is not None and clock_us - BACK_US <= t_us <= clock_us + JUMP_US:
            self._candidates.clear()  # the old clock is alive
            return True
        cand = next((c for c in self._candidates if abs(t_us - c[0]) <= JUMP_US), None)
        if cand is None:
            if len(self._candidates) >= MAX_CANDIDATES:  # junk makes many one-sample candidates: drop the weakest
                self._candidates.remove(min(self._candidates, key=lambda c: c[1]))
            cand = [t_us, 0]
            self._candidates.append(cand)
        cand[0], cand[1] = t_us, cand[1] + 1
        if cand[1] >= CONFIRM_SAMPLES:
            self.confirmed += clock_us is not None
            self._candidates.clear()
            return True
        self.refused += 1
        if clock_us is None:
            return False
        if self._told_at_us is None or abs(clock_us - self._told_at_us) >= TELL_PERIOD_S * US_PER_S:
            self._told_at_us = clock_us
            log.warning(
                "clock jumped %+.1f s (boot time %.1f s on a clock at %.1f s): dropped until %d samples agree "
                "and the old clock stops (%d dropped so far; told at most once a minute)",
                (t_us - clock_us) / US_PER_S,
                t_us / US_PER_S,
                clock_us / US_PER_S,
                CONFIRM_SAMPLES,
                self.refused,
            )
        return False


class GuardedDecoder(md.MavlinkDecoder):
    """``MavlinkDecoder`` whose boot clock moves only as ``ClockGuard`` allows."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.clock_guard = ClockGuard()
        self._last_ok_s: float | None = None  # arrival (s) of the last sample on the clock
        self._arrival_s = 0.0

    def _stamp(self, t_us: int, out: list) -> int:
        before = self.clock_guard.confirmed
        if not self.clock_guard.check(t_us, self.clock_us):
            raise ClockJumped
        now = self._arrival_s
        if self.clock_guard.confirmed != before and t_us > self.clock_us:
            elapsed_us = (now - (self._last_ok_s or now)) * US_PER_S
            if t_us - self.clock_us > elapsed_us + JUMP_US:  # ahead of the time that passed: the clock jumped
                out.append(md.ClockReset(t_us, self.clock_us))
                self.clock_us = t_us
        self._last_ok_s = now
        return super()._stamp(t_us, out)

    def decode(self, msg: Any) -> list:
        # Arrival: a recorded log's own time (pymavlink's ``_timestamp``), else now; only differences are used.
        recorded = getattr(msg, "_timestamp", None)
        self._arrival_s = float(recorded) if recorded else time.monotonic()
        try:
            return super().decode(msg)
        except ClockJumped:
            return []
