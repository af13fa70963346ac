"""The STATUSTEXT queue (the events file is monitor/daemon/events.py) and the older consecutive-window rule.

The daemon decides with ``monitor.decision.rule.Decision`` (shared with
``propwatch diagnose``; ``alerts.rule: sequential``, the default). The rule
below is kept as ``alerts.rule: consecutive`` and as the comparison row of
``make evaluate-alerts``.

Consecutive rule, per propeller: P(faulty) >= threshold in ``consecutive`` classified
windows in a row raises an alert, then that propeller stays quiet for
``refractory_s`` seconds of ``time.monotonic()`` (a wall-clock step never
re-arms or silences it). STATUSTEXT is rate-limited on the same clock.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from monitor.daemon.config import AlertConfig
from monitor.daemon.events import EventWriter  # noqa: F401  (moved; kept importable from here)
from monitor.labels import N_PROPS

STATUSTEXT_MAX_CHARS = 50
MAV_SEVERITY_CRITICAL = 2
MAV_SEVERITY_WARNING = 4


@dataclass(frozen=True)
class Alert:
    time_boot_ms: int
    faulty_propellers: tuple[int, ...]  # 1..4, PX4 order
    fault_probability: tuple[float, ...]  # all four
    label: int  # 1..16, the most likely label of the window
    label_probability: tuple[float, ...]
    critical: bool
    battery_v: float = float("nan")  # context for the ground crew: a sagging pack also raises RPM

    def statustext(self) -> str:
        return statustext({p: self.fault_probability[p - 1] for p in self.faulty_propellers})

    @property
    def severity(self) -> int:
        return MAV_SEVERITY_CRITICAL if self.critical else MAV_SEVERITY_WARNING

    def event(self) -> dict:
        return {
            "time_boot_ms": self.time_boot_ms,
            "label": self.label,
            "faulty_propellers": list(self.faulty_propellers),
            "probabilities": [round(p, 4) for p in self.fault_probability],
            "label_probabilities": [round(p, 4) for p in self.label_probability],
            "severity": "CRITICAL" if self.critical else "WARNING",
            "battery_v": None if math.isnan(self.battery_v) else round(self.battery_v, 2),
        }


def statustext(probability_by_prop: dict[int, float]) -> str:
    """E.g. ``PROP 3 FAULT p=0.97``; several: ``PROP 1,3 FAULT p=0.91,0.97``; <= 50 chars."""
    props = sorted(probability_by_prop)
    text = f"PROP {','.join(map(str, props))} FAULT p={','.join(f'{probability_by_prop[p]:.2f}' for p in props)}"
    return text[:STATUSTEXT_MAX_CHARS]


class StatusTextQueue:
    """Rate-limited STATUSTEXT that never drops an alert: what arrives too soon is merged and sent later."""

    def __init__(self, min_interval_s: float, critical_threshold: float, clock: Callable[[], float] = time.monotonic):
        self.limit = RateLimiter(min_interval_s, clock)
        self.critical_threshold = critical_threshold
        self._pending: dict[int, float] = {}
        self._texts: dict[str, int] = {}  # decision announcements: text -> severity
        self._sent_severity = 99  # MAV_SEVERITY of the last text sent (none yet: any is more severe)

    def add(self, alert: Alert) -> None:
        for p in alert.faulty_propellers:
            self._pending[p] = max(self._pending.get(p, 0.0), alert.fault_probability[p - 1])

    def add_text(self, text: str, severity: int) -> None:
        """A worded announcement; what waits for the rate limit is sent later, most severe first."""
        self._texts[text] = min(severity, self._texts.get(text, severity))

    def due(self) -> tuple[str, int] | None:
        """(text, severity) to send now, or None (nothing pending, or too soon).

        An announcement more severe than the last text sent (suspect NOTICE, then fault WARNING, then
        CRITICAL) does not wait for the rate limit: a fault must not sit behind its own suspect notice.
        That is at most two extra texts per interval (severity only rises until a text goes out normally).
        """
        if not (self._pending or self._texts):
            return None
        if not self.limit.allow():
            if not (self._texts and min(self._texts.values()) < self._sent_severity):
                return None
            self.limit.restart()
        if self._texts:
            text = min(self._texts, key=lambda t: self._texts[t])  # MAV_SEVERITY: lower is more severe
            self._sent_severity = self._texts.pop(text)
            return text, self._sent_severity
        worst = max(self._pending.values())
        text = statustext(self._pending)
        self._pending = {}
        self._sent_severity = MAV_SEVERITY_CRITICAL if worst >= self.critical_threshold else MAV_SEVERITY_WARNING
        return text, self._sent_severity


class AlertRule:
    def __init__(self, config: AlertConfig, clock: Callable[[], float] = time.monotonic):
        self.config = config
        self.clock = clock
        self._streak = np.zeros(N_PROPS, dtype=np.int64)
        self._quiet_until = np.full(N_PROPS, -np.inf)

    def reset(self) -> None:
        """Streaks count consecutive windows: a gap in classification breaks them."""
        self._streak[:] = 0

    def update(
        self, time_boot_ms: int, fault_probability: np.ndarray, label_probability: np.ndarray, battery_v: float = float("nan")
    ) -> Alert | None:
        p = np.asarray(fault_probability, dtype=np.float64)
        hot = np.isfinite(p) & (p >= self.config.threshold)
        self._streak = np.where(hot, self._streak + 1, 0)
        now = self.clock()
        firing = (self._streak >= self.config.consecutive) & (now >= self._quiet_until)
        if not firing.any():
            return None
        self._quiet_until[firing] = now + self.config.refractory_s
        props = tuple(int(i) + 1 for i in np.flatnonzero(firing))
        lp = np.asarray(label_probability, dtype=np.float64)
        critical = bool(max(p[i - 1] for i in props) >= self.config.critical_threshold)
        return Alert(
            int(time_boot_ms),
            props,
            tuple(map(float, p)),
            int(np.argmax(lp)) + 1,
            tuple(map(float, lp)),
            critical,
            float(battery_v),
        )


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
