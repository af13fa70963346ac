"""Say when blind: which reason the monitor cannot see for, and the transitions to report.

Reasons (short text for the ground station, <= 50 chars with the prefix):
``no motor data``, ``no attitude data``, ``implausible motor data``,
``implausible attitude``, ``autopilot clock frozen``, ``clock stepped back``, ``clock jumped``,
``autopilot rebooted``, ``link lost``. The service calls ``enter`` for an
event seen at once (reboot, clock step, frozen clock, lost link) and
``data(ok, ...)`` at each airborne grid step (bad data must last ``after_s``
before it counts, so one late packet is not a blind spell). ``recover`` ends
the spell when good data flows again. Each transition is returned so the
service reports it once: systemd STATUS, an events line and a NOTICE queued
here, rate-limited, never more than ``NOTICE_BACKLOG`` waiting.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from monitor.daemon.alerts import RateLimiter
from monitor.daemon.config import BlindConfig

BLIND_PREFIX = "PROPWATCH BLIND: "
RECOVERED_TEXT = "PROPWATCH OK: monitoring again"
MAV_SEVERITY_NOTICE = 5
NOTICE_BACKLOG = 4
STATUSTEXT_MAX_CHARS = 50


@dataclass(frozen=True)
class Transition:
    blind: bool  # True: entered (or changed reason); False: recovered
    reason: str  # short reason ('' on recovery)
    detail: str  # for the journal, STATUS and the events file
    duration_s: float = 0.0  # on recovery: how long it was blind

    def notice(self) -> str:
        text = BLIND_PREFIX + self.reason if self.blind else RECOVERED_TEXT
        return text[:STATUSTEXT_MAX_CHARS]

    def record(self, time_boot_ms: int | None) -> dict:
        out = {"event": "blind" if self.blind else "recovered", "time_boot_ms": time_boot_ms, "detail": self.detail}
        if self.blind:
            out["reason"] = self.reason
        else:
            out["blind_s"] = round(self.duration_s, 3)
        return out


class BlindTracker:
    def __init__(self, config: BlindConfig, clock: Callable[[], float] = time.monotonic):
        self.cfg = config
        self.clock = clock
        self.reason: str | None = None
        self.detail = ""
        self.spells = 0
        self._since = 0.0
        self._bad_since: float | None = None
        self._limit = RateLimiter(config.notice_min_interval_s, clock)
        self._notices: deque[str] = deque(maxlen=NOTICE_BACKLOG)

    @property
    def blind(self) -> bool:
        return self.reason is not None

    def enter(self, reason: str, detail: str = "") -> Transition | None:
        if self.reason == reason:
            return None
        if self.reason is None:
            self._since = self.clock()
            self.spells += 1
        self.reason, self.detail = reason, detail or reason
        return self._queue(Transition(True, reason, self.detail))

    def recover(self) -> Transition | None:
        self._bad_since = None
        if self.reason is None:
            return None
        t = Transition(False, "", f"monitoring again after {self.reason}", self.clock() - self._since)
        self.reason, self.detail = None, ""
        return self._queue(t)

    def data(self, ok: bool, reason: str = "", detail: str = "") -> Transition | None:
        """One airborne grid step: data present and plausible (ok), or not (with why)."""
        if ok:
            return self.recover()
        now = self.clock()
        if self._bad_since is None:
            self._bad_since = now
        if now - self._bad_since >= self.cfg.after_s:
            return self.enter(reason, detail)
        return None

    def _queue(self, t: Transition) -> Transition:
        text = t.notice()
        if not self._notices or self._notices[-1] != text:
            self._notices.append(text)
        return t

    def due(self) -> tuple[str, int] | None:
        """The next NOTICE to send now, or None (none waiting, or too soon)."""
        if not self._notices or not self._limit.allow():
            return None
        return self._notices.popleft(), MAV_SEVERITY_NOTICE
