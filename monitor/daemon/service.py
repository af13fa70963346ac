"""The daemon's loop: link in, each message through watch -> pipeline -> decide -> announce, housekeeping.

One message's path (``Daemon.handle``): the ``pipeline`` decodes it (``monitor.daemon.pipeline``: the 20 Hz grid,
features, the network) and shows it to the autopilot's bookkeeping once decoded (``autopilot``: identity, stream
rates, arming, version, acks); each grid step it completes goes to ``decide`` (what is live, the pause, every judge
of the flight, blindness from the step), which hands it to ``announce`` (STATUSTEXT, the events file, STATUS,
latency). The loop itself reads the ``link``, runs the housekeeping at most every ``TICK_PERIOD_S``, paces its reads
and reports. Another autopilot system id on the link is another vehicle, with a monitor of its own (``vehicles``):
its messages go there.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path

from monitor.daemon.alerts import RateLimiter
from monitor.daemon.announce import Announcer, Counters
from monitor.daemon.autopilot import Autopilot
from monitor.daemon.blind import BlindTracker
from monitor.daemon.config import MonitorConfig
from monitor.daemon.decide import Decider, DecisionStage, stage_watches
from monitor.daemon.events import EventWriter
from monitor.daemon.link import Link
from monitor.daemon.memory_adapter import VehicleMemory
from monitor.daemon.pacing import MAX_PAUSE_S
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.rotor_evidence import RecentEffectiveness
from monitor.daemon.sdnotify import Notifier
from monitor.daemon.vehicles import Vehicles
from monitor.decision.hypotheses import FlightSets, load_rule
from monitor.decision.rule import Decision
from monitor.decision.thresholds import file_sha256

log = logging.getLogger("propwatch.monitor")

READ_TIMEOUT_S = 0.1  # select() returns at once when data comes; this only paces idle housekeeping
# Housekeeping (heartbeat, stream requests, blindness, held-back STATUSTEXT) at most this often, not after
# each of the ~100 datagrams a second: its deadlines are 0.5 s and longer (blind.frozen_clock_s 1 s by default),
# and alerts are sent as they are made. Each run costs ~0.1 ms of a cold CPU: 10 a second, not 20.
TICK_PERIOD_S = 0.1
BAD_DATA_LOG_PERIOD_S = 5.0
REPORT_TOP_N = 20  # the report lists at most this many ignored sources / undecodable kinds


class Daemon:
    def __init__(
        self,
        config: MonitorConfig,
        link: Link,
        pipeline: Pipeline,
        events: EventWriter,
        notifier: Notifier | None = None,
        vehicle=None,
        memory: VehicleMemory | None = None,
        one: bool = False,
    ):
        """``one``: this monitors one vehicle of several on the link (``monitor.daemon.vehicles``): it routes nothing."""
        self.cfg = config
        self.link = link
        self.memory = memory  # the vehicle's healthy history (monitor.daemon.memory_adapter), None without a state dir
        self.pipeline = pipeline
        self.events = events
        self.notifier = notifier or Notifier({})
        self.geometry = vehicle
        many = not one and config.link.system_id == 0 and config.link.max_vehicles > 1
        self.vehicles = Vehicles(self, config.link.max_vehicles) if many else None  # the other vehicles' monitors
        decision = Decision(
            config.alerts.decision(),
            config.resample.rate_hz,
            pipeline.window,
            model_sha256=file_sha256(pipeline.classifier.path),
        )
        rule = load_rule(pipeline.classifier.path)  # the model's conformal rule words alerts as hypothesis sets
        # The set over the windows of the last second (each already spans 5 s; every_k_steps apart) words an alert.
        horizon = max(1, round(config.resample.rate_hz / config.inference.every_k_steps))
        # Rotor effectiveness from the moment balance of the 5 s before an alert (in its event); needs the geometry.
        rotors = RecentEffectiveness(vehicle, pipeline.window, config.resample.rate_hz) if vehicle is not None else None
        sets = FlightSets(rule, horizon) if rule is not None else None
        self.stage = DecisionStage(decision, sets, rotors, memory, *stage_watches(config, pipeline))
        # The stage's judges, for reports and tests (the message path goes through ``decide`` only).
        self.decision, self.rotors, self.esc_telemetry = decision, rotors, self.stage.esc_telemetry
        self.stop = threading.Event()
        self.counters = Counters()
        self.blind = BlindTracker(config.blind)
        self.announce = Announcer(config, link, events, self.notifier, self.blind, self.counters)
        self.autopilot = Autopilot(config, link, pipeline.decoder, self.announce, self.counters, memory)
        self.decide = Decider(config, self.stage, self.announce, self.blind, self.autopilot)
        pipeline.watch = self.autopilot.watch
        self._next_watchdog = 0.0
        self._next_bad_log = 0.0
        self._bad_since_log = 0
        self._error_log_limit = RateLimiter(10.0)

    # -- main loop ---------------------------------------------------------------------
    def run(self) -> int:
        self.notifier.ready(f"monitoring {self.link.url}")
        log.info(
            "ready: model %s, %d features, window %d at %.0f Hz, link %s",
            self.pipeline.classifier.path,
            len(self.pipeline.features),
            self.pipeline.window,
            self.cfg.resample.rate_hz,
            self.link.url,
        )
        next_tick = 0.0
        # Sleep through datagrams that cannot complete the next step (monitor.daemon.pacing): udpin only, where
        # the kernel keeps every datagram with its arrival stamp while we sleep.
        pace = self.cfg.link.pace_reads and getattr(self.link, "is_udpin", False)
        while not self.stop.is_set():
            try:
                batch = self.link.read(READ_TIMEOUT_S)
            except OSError as exc:  # serial unplugged, TCP peer gone: the link reopens itself
                log.error("link error on %s: %s; reopening", self.link.url, exc)
                self.link.close()
                continue
            self.counters.reads += 1
            for msg, received, read in batch:
                self.handle(msg, received, read)
            now = time.monotonic()
            if now >= next_tick:
                next_tick = now + TICK_PERIOD_S
                self._tick_guarded(now)
            if pace and self.link.drained:
                self._pause()
            if self.link.is_log and self.link.eof:
                for d in (self, *(self.vehicles.others.values() if self.vehicles is not None else ())):
                    for step in d.pipeline.flush():
                        d._on_step(step)
                log.info("end of log %s", self.link.url)
                break
        self.notifier.stopping()
        self.events.close()
        self.summary()
        return 0

    def _pause(self) -> None:
        """Sleep until the next grid step can first complete (at most ``MAX_PAUSE_S``)."""
        now = time.perf_counter()
        wake = self.pipeline.wake_at(now)
        if self.vehicles is not None and self.vehicles.others:
            wake = self.vehicles.wake_at(now, wake)
        if wake is not None and wake > now:
            self.counters.paces += 1
            time.sleep(min(wake - now, MAX_PAUSE_S))

    def _tick_guarded(self, now: float) -> None:
        try:
            self.tick(now)
        except Exception:  # noqa: BLE001 - housekeeping must not stop the monitor in flight either
            self.counters.internal_errors += 1
            if self._error_log_limit.allow():
                log.exception("error in the loop's periodic work (%d so far); continuing", self.counters.internal_errors)

    def handle(self, msg, received_s: float, read_s: float | None = None) -> None:
        """One message that arrived at ``received_s`` and was read at ``read_s`` (perf_counter; read = arrival
        when not given): watched and through the pipeline, then each step it completes decided and announced."""
        kind = msg.get_type()
        self.announce.queued_s = 0.0 if read_s is None else read_s - received_s
        self.counters.messages += 1
        if kind == "BAD_DATA":
            self.counters.bad_data += 1
            self._bad_since_log += 1
            return
        if self.vehicles is not None and (other := self.vehicles.route(msg)) is not None:
            other.handle(msg, received_s, read_s)  # another vehicle's message, counted here and there
            return
        try:
            steps = self.pipeline.feed(msg, received_s)  # the autopilot watches it once decoded (Autopilot.watch)
        except Exception:  # noqa: BLE001 - one bad message must not stop the monitor in flight
            self.counters.internal_errors += 1
            if self._error_log_limit.allow():
                log.exception("error while processing %s (%d so far); continuing", kind, self.counters.internal_errors)
            self.pipeline.reset()
            return
        while self.pipeline.clock_events:  # reboot or clock step: blind until good data flows again
            what = self.pipeline.clock_events.popleft()
            if self.memory is not None:
                self.memory.discard(what)
            if "reboot" in what:
                self.autopilot.rebooted()
            reason = "autopilot rebooted" if "reboot" in what else "clock jumped" if "jumped" in what else "clock stepped back"
            self.decide.transition(self.blind.enter(reason, what))
        for step in steps:
            self._on_step(step)
        if self.pipeline.vibration or self.pipeline.esc_samples:
            self.decide.side_evidence(self.pipeline)

    def _on_step(self, step) -> None:
        """One grid step: decided, then announced (``Decider.step``, one call)."""
        self.decide.step(step)

    # -- periodic work -------------------------------------------------------------------
    def tick(self, now: float) -> None:
        self.autopilot.tick(now)  # heartbeat, stream and version requests, link timeout, rate check
        if self.notifier.watchdog_s and now >= self._next_watchdog:
            self.notifier.watchdog()
            self._next_watchdog = now + self.notifier.watchdog_s / 2
        self.announce.send_statustext()  # alerts held back by the rate limit
        if not self.link.is_log:  # a log replayed fast has no wall-clock meaning for blindness
            self.decide.loop_blind(self.autopilot.loop_blindness(now))
        self.announce.send_notice()
        self.announce.check_sink(now)
        if self._bad_since_log and now >= self._next_bad_log:
            log.warning("%d unparseable packets/bytes dropped (%d in total)", self._bad_since_log, self.counters.bad_data)
            self._bad_since_log = 0
            self._next_bad_log = now + BAD_DATA_LOG_PERIOD_S
        for other in self.vehicles.others.values() if self.vehicles is not None else ():
            other.tick(now)

    # -- reporting -----------------------------------------------------------------------
    def report(self) -> dict:
        c = self.counters
        ev = self.events
        return {
            "messages": c.messages,
            "bad_data": c.bad_data,
            "alerts": c.alerts,
            "statustexts": c.statustexts,
            "stream_requests": c.stream_requests,
            "internal_errors": c.internal_errors,
            "notices": c.notices,
            "blind_spells": self.blind.spells,
            "blind_now": self.blind.reason,
            "events_file": {
                "written": ev.written,
                "failures": ev.failures,
                "pending": ev.pending,
                "dropped": ev.dropped,
                "reported_to_gcs": c.sink_reports,
            },
            "implausible": dict(self.pipeline.plausible.dropped),
            "link": self.link.stats(),
            "acks": {str(k): v for k, v in c.acks.items()},
            "pipeline": dict(self.pipeline.stats),
            "late_samples": self.pipeline.hold.late,
            "hold_overflow": self.pipeline.hold.overflow,
            "ignored": {f"{s}/{k}": n for (s, k), n in self.pipeline.decoder.ignored.most_common(REPORT_TOP_N)},
            "undecodable": dict(self.pipeline.decoder.undecodable.most_common(REPORT_TOP_N)),
            "latency_ms": c.latency.percentiles_ms(),
            "latency_from_read_ms": c.latency_from_read.percentiles_ms(),
            "loop": {"reads": c.reads, "paces": c.paces, "pace_misses": self.pipeline.pacer.misses},
            "decision": self.decision.verdict(),
            "esc_rejected": dict(self.esc_telemetry.rejected),
            "system_id": self.autopilot.system_id,
            "other_vehicles": self.vehicles.report() if self.vehicles is not None else {},
        }

    def summary(self) -> None:
        r = self.report()
        if self.autopilot.system_id is None:
            log.warning("no autopilot HEARTBEAT was ever received: nothing was classified")
        log.info(
            "stopped: %d messages, %d steps (%d valid, %d classified), %d alerts, %d bad packets",
            r["messages"],
            r["pipeline"]["steps"],
            r["pipeline"]["valid_steps"],
            r["pipeline"]["classified"],
            r["alerts"],
            r["bad_data"],
        )
        for sys_id, o in r["other_vehicles"].items():
            p = o["pipeline"]
            log.info("vehicle system %s: %d steps (%d classified), %d alerts", sys_id, p["steps"], p["classified"], o["alerts"])

    def write_report(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.report(), indent=2, default=float) + "\n", encoding="utf-8")
