"""What the daemon tells: STATUSTEXT to the ground station, the events file, systemd's STATUS, and its latency.

An alert goes to the ground station first (rate-limited by ``alerts.StatusTextQueue``, never dropped), then to
STATUS and the events file: a failing disk must never delay or lose the alert itself. The pause journal (the
decision paused and resumed, at most one line per ``PAUSE_LOG_PERIOD_S``), blind spells and the vehicle memory's
flights are events lines too. STATUS is one line: the latest base text (link, deciding, paused, last alert), with the
blind spell and a failing events file appended; it is sent to systemd only when it changes.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from monitor.daemon.alerts import RateLimiter, StatusTextQueue
from monitor.daemon.blind import BlindTracker
from monitor.daemon.config import MonitorConfig
from monitor.daemon.events import EventWriter
from monitor.daemon.latency import LatencyHistogram
from monitor.daemon.link import Link
from monitor.daemon.sdnotify import Notifier
from monitor.decision.rule import Announcement

log = logging.getLogger("propwatch.monitor")

SINK_REPORT_PERIOD_S = 60.0  # a failing events file is told to the ground station once a minute
MAV_SEVERITY_WARNING = 4
PAUSE_LOG_PERIOD_S = 2.0  # decision pauses in the journal and events file: at most one per period (flapping data)


@dataclass(frozen=True)
class Alert:
    announcement: Announcement
    time_boot_ms: int
    fields: dict  # the event's fields beside the announcement's own (probabilities, battery, rotor effectiveness)


@dataclass
class Counters:
    messages: int = 0
    bad_data: int = 0
    alerts: int = 0
    statustexts: int = 0
    stream_requests: int = 0
    internal_errors: int = 0
    notices: int = 0
    sink_reports: int = 0
    acks: Counter = field(default_factory=Counter)
    reads: int = 0  # loop turns (each one wake-up at least)
    paces: int = 0  # sleeps until the next step could complete (monitor.daemon.pacing)
    latency: LatencyHistogram = field(default_factory=LatencyHistogram)  # from the arrival of the completing message
    latency_from_read: LatencyHistogram = field(default_factory=LatencyHistogram)  # from its read (the older measure)


class Announcer:
    def __init__(
        self,
        config: MonitorConfig,
        link: Link,
        events: EventWriter,
        notifier: Notifier,
        blind: BlindTracker,
        counters: Counters,
    ):
        self.cfg = config
        self.link = link
        self.events = events
        self.notifier = notifier
        self.blind = blind
        self.counters = counters
        self.statustexts = StatusTextQueue(config.alerts.statustext_min_interval_s)
        self.pause_log_limit = RateLimiter(PAUSE_LOG_PERIOD_S)
        self.live: list[str] = []  # evidence live at the last step (STATUS while blind)
        self.context: list[str] = []  # context live at the last step
        self.queued_s = 0.0  # how long the message being handled waited in the socket before its read
        self._pause_recorded = ""  # the pause last written to the journal and events file
        self._status_base = ""
        self._status_sent = ""
        self._next_sink_report = 0.0
        self.system_id: int | None = None  # the vehicle's (its alerts name it)
        # Several vehicles on the link (``monitor.daemon.vehicles``): the first one's STATUS names every vehicle
        # (``compose``), and another one's own text (``status_text``) goes into it (``status_changed``).
        self.status_text = ""
        self.compose: Callable[[str], str] | None = None
        self.status_changed: Callable[[], None] | None = None

    def record(self, record: dict) -> None:
        self.events.write_record(record)

    # -- alerts ---------------------------------------------------------------------------
    def alert(self, alert: Alert) -> None:
        self.counters.alerts += 1
        a, time_boot_ms = alert.announcement, alert.time_boot_ms
        event = {"event": "alert", "system_id": self.system_id, **a.event(), "time_boot_ms": time_boot_ms, **alert.fields}
        log.warning("%s system %s t=%d ms: %s (%s evidence)", a.level.upper(), self.system_id, time_boot_ms, a.text, a.evidence)
        # The ground station first: a failing disk must never delay or lose the alert itself.
        self.statustexts.add_text(a.text, a.severity)
        self.send_statustext()
        self.set_status(f"last alert: {a.text} at t={time_boot_ms} ms")
        self.events.write_record(event)

    def send_statustext(self) -> None:
        due = self.statustexts.due()
        if due is not None:
            self.counters.statustexts += 1
            self.link.send_statustext(*due)

    def classified(self, step) -> None:
        """A classified step: its latency (from the completing message's arrival, its kernel stamp on udpin, and
        from its read), and the probabilities as NAMED_VALUE_FLOAT where configured."""
        if step.latency_s is not None:
            self.counters.latency.add(step.latency_s)
            self.counters.latency_from_read.add(step.latency_s - self.queued_s)
        if self.cfg.alerts.named_value_float:
            for i, v in enumerate(step.fault_probability):
                self.link.send_named_value_float(step.time_boot_ms, f"PWF{i + 1}", float(v))

    # -- the pause journal ------------------------------------------------------------------
    def paused(self, time_boot_ms: int, reason: str, classifier_input: str) -> None:
        """Journal and events line for a pause (or a new reason); flapping data is rate-limited.

        A pause held back by the limit is written at a later step of the same pause (within
        ``PAUSE_LOG_PERIOD_S``); one that ends first is not written, and neither is its resume.
        """
        if reason == self._pause_recorded:
            return
        if not self.pause_log_limit.allow():
            return
        self._pause_recorded = reason
        log.warning("t=%d ms: decision paused: %s", time_boot_ms, reason)
        self.events.write_record(
            {
                "event": "paused",
                "time_boot_ms": time_boot_ms,
                "reason": reason,
                "evidence_live": self.live,
                "context_live": self.context,
                "classifier_input": classifier_input,
            }
        )

    def resumed(self, time_boot_ms: int) -> None:
        if not self._pause_recorded:
            return
        self._pause_recorded = ""
        log.info("t=%d ms: decision resumed", time_boot_ms)
        self.events.write_record(
            {"event": "resumed", "time_boot_ms": time_boot_ms, "evidence_live": self.live, "context_live": self.context}
        )

    # -- blind spells, sink failures, systemd STATUS ---------------------------------------
    def transition(self, record: dict) -> None:
        """A blind spell began or ended (``record``: its events line, the decision's state already in it)."""
        self.publish_status()
        self.events.write_record(record)
        self.send_notice()

    def send_notice(self) -> None:
        due = self.blind.due()
        if due is not None:
            self.counters.notices += 1
            self.link.send_statustext(*due)

    def set_status(self, text: str) -> None:
        """A new base text (the same one again, every step, changes nothing: blind spells and the events file
        publish their own changes, and the tick publishes the rest)."""
        if text != self._status_base:
            self._status_base = text
            self.publish_status()

    def publish_status(self) -> None:
        blind = self.blind.reason is not None
        text = f"BLIND: {self.blind.detail}" if blind else self._status_base
        if blind:
            text += f"; decision paused, evidence live: {', '.join(self.live) or 'none'}"
        if self.events.failing:
            text += f"; events file failing ({self.events.last_error}, {self.events.pending} waiting)"
        self.status_text = text
        if self.status_changed is not None:
            self.status_changed()
            return
        if self.compose is not None:
            text = self.compose(text)
        if text and text != self._status_sent:
            self._status_sent = text
            self.notifier.status(text)

    def check_sink(self, now: float) -> None:
        self.events.retry()
        if self.events.failing and now >= self._next_sink_report:
            self._next_sink_report = now + SINK_REPORT_PERIOD_S
            self.counters.sink_reports += 1
            self.link.send_statustext("PROPWATCH: events file write failing", MAV_SEVERITY_WARNING)
        self.publish_status()
