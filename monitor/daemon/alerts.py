"""The STATUSTEXT queue and the rate limiter (the events file is monitor/daemon/events.py).

The daemon decides with ``monitor.decision.rule.Decision`` (shared with
``propwatch diagnose``); what it announces is worded there and queued here,
rate-limited on ``time.monotonic()`` (a wall-clock step never re-arms or
silences it). The consecutive-window rule it is compared against lives offline
(``offline.classifier.consecutive``).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np


class StatusTextQueue:
    """Rate-limited STATUSTEXT that never drops an announcement: what arrives too soon is sent later."""

    def __init__(self, min_interval_s: float, clock: Callable[[], float] = time.monotonic):
        self.limit = RateLimiter(min_interval_s, clock)
        self._texts: dict[str, int] = {}  # text -> severity
        self._sent_severity = 99  # MAV_SEVERITY of the last text sent (none yet: any is more severe)

    def add_text(self, text: str, severity: int) -> None:
        """A worded announcement; what waits for the rate limit is sent later, most severe first."""
        self._texts[text] = min(severity, self._texts.get(text, severity))

    def due(self) -> tuple[str, int] | None:
        """(text, severity) to send now, or None (nothing pending, or too soon).

        An announcement more severe than the last text sent (suspect NOTICE, then fault WARNING, then
        CRITICAL) does not wait for the rate limit: a fault must not sit behind its own suspect notice.
        That is at most two extra texts per interval (severity only rises until a text goes out normally).
        """
        if not self._texts:
            return None
        if not self.limit.allow():
            if min(self._texts.values()) >= self._sent_severity:
                return None
            self.limit.restart()
        text = min(self._texts, key=lambda t: self._texts[t])  # MAV_SEVERITY: lower is more severe
        self._sent_severity = self._texts.pop(text)
        return text, self._sent_severity


class RateLimiter:
    """At most one event per ``min_interval_s`` on a monotonic clock."""

    def __init__(self, min_interval_s: float, clock: Callable[[], float] = time.monotonic):
        self.min_interval_s = min_interval_s
        self.clock = clock
        self._last = -np.inf

    def allow(self) -> bool:
        now = self.clock()
        if now - self._last < self.min_interval_s:
            return False
        self._last = now
        return True

    def restart(self) -> None:
        """Count an event sent now (outside ``allow``): the next interval starts here."""
        self._last = self.clock()
