"""The daemon's loop: link in, pipeline, alerts out, heartbeats, rate checks, watchdog.

One message's path: ``Daemon.handle`` -> ``pipeline`` (decode, the 20 Hz grid,
features, the network) -> ``decide`` (every judge of the flight, one call per
grid step) -> ``_announce`` (STATUSTEXT queue in ``alerts``, the events file in
``events``). State that lives across loop turns is kept here (link health,
stream rates, pending stream requests, blind spells, why the decision is
paused); the socket is in ``link``.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from monitor.daemon.alerts import RateLimiter, StatusTextQueue
from monitor.daemon.blind import BlindTracker, Transition
from monitor.daemon.config import MonitorConfig
from monitor.daemon.decide import Alert, DecisionStage
from monitor.daemon.events import EventWriter
from monitor.daemon.latency import LatencyHistogram
from monitor.daemon.link import MAV_CMD_SET_MESSAGE_INTERVAL, Link
from monitor.daemon.memory_adapter import VehicleMemory
from monitor.daemon.pacing import MAX_PAUSE_S
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.rotor_evidence import RecentEffectiveness
from monitor.daemon.sdnotify import Notifier
from monitor.decision.hypotheses import FlightSets, load_rule
from monitor.decision.rule import Decision
from monitor.decision.thresholds import file_sha256
from monitor.mavlink import decode as md
from monitor.resample import US_PER_S

log = logging.getLogger("propwatch.monitor")

READ_TIMEOUT_S = 0.1  # select() returns at once when data comes; this only paces idle housekeeping
# Housekeeping (heartbeat, stream requests, blindness, held-back STATUSTEXT) at most this often, not after
# each of the ~100 datagrams a second: its deadlines are 0.5 s and longer (blind.frozen_clock_s 1 s by default),
# and alerts are sent as they are made. Each run costs ~0.1 ms of a cold CPU: 10 a second, not 20.
TICK_PERIOD_S = 0.1
BAD_DATA_LOG_PERIOD_S = 5.0
MOTOR_STREAM = {"servo": "SERVO_OUTPUT_RAW", "actuator": "ACTUATOR_OUTPUT_STATUS", "esc": "ESC_STATUS"}
LANDED_RATE_HZ = 2.0  # EXTENDED_SYS_STATE: a state, not a signal
VIBRATION_RATE_HZ = 10.0  # imbalance evidence beside the classifier (PX4's default stream rate is lower)
# LOCAL_POSITION_NED: the velocity the shares' baseline follows, held on the 20 Hz grid. PX4's own rate on an onboard
# (companion) link, so the request never slows it for another consumer there; a radio link's 1 Hz gets raised.
VELOCITY_RATE_HZ = 30.0
# HIGHRES_IMU: the body's specific force (the air's drag), averaged over each 20 Hz step. PX4's rate for it on an
# onboard link; SCALED_IMU, what some links carry instead, is used as it comes (not requested).
IMU_RATE_HZ = 50.0
EVIDENCE_FRESH_S = 2.0  # a VIBRATION / ESC_STATUS stream (or the grid's velocity, IMU) silent for longer is not live
# Context for the decision (the shares' baseline follows it), not evidence of a fault: listed apart in STATUS and events.
CONTEXT = ("velocity", "imu")
SINK_REPORT_PERIOD_S = 60.0  # a failing events file is told to the ground station once a minute
MAV_SEVERITY_WARNING = 4
REPORT_TOP_N = 20  # the report lists at most this many ignored sources / undecodable kinds
AUTOPILOT_VERSION_ID = 148
VERSION_REQUESTS = 3  # AUTOPILOT_VERSION asked for at most this often (an autopilot that never answers: sysid it is)
PAUSE_LOG_PERIOD_S = 2.0  # decision pauses in the journal and events file: at most one per period (flapping data)


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
    ):
        self.cfg = config
        self.link = link
        self.memory = memory  # the vehicle's healthy history (monitor.daemon.memory_adapter), None without a state dir
        self.pipeline = pipeline
        self.events = events
        self.notifier = notifier or Notifier({})
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
        self.stage = DecisionStage(decision, FlightSets(rule, horizon) if rule is not None else None, rotors, memory)
        # The stage's judges, for reports and tests (the message path goes through ``stage`` only).
        self.decision, self.rotors, self.esc_telemetry = decision, rotors, self.stage.esc_telemetry
        self._evidence_t: dict[str, float] = {}  # evidence -> boot time (s) it was last usable
        self._context_t: dict[str, float] = {}  # context (CONTEXT) -> boot time (s) a step last had it
        self._paused = ""  # why the classifier's evidence stopped while airborne ('' = flowing)
        self._pause_recorded = ""  # the pause last written to the journal and events file
        self._pause_log_limit = RateLimiter(PAUSE_LOG_PERIOD_S)
        self._live: list[str] = []  # evidence live at the last step
        self._context: list[str] = []  # context live at the last step
        self._airborne = False
        self.statustexts = StatusTextQueue(config.alerts.statustext_min_interval_s)
        self.stop = threading.Event()
        self.counters = Counters()
        self._rates: Counter = Counter()
        self._rate_window_start = time.monotonic()
        self._last_autopilot_hb: float | None = None
        self._link_up = False
        self._system_id: int | None = None
        self._next_hb = 0.0
        self._next_request = 0.0
        self._next_version_request = 0.0
        self._version_requests = 0
        self._next_watchdog = 0.0
        self._next_bad_log = 0.0
        self._bad_since_log = 0
        self._error_log_limit = RateLimiter(10.0)
        self._fast = self.fast_streams()
        self._slow: set[str] = set(self._fast)
        self.blind = BlindTracker(config.blind)
        self._bad_steps = False  # an airborne step without usable data was told to the tracker since it last recovered
        self._armed = False
        self._last_fast_rx: dict[str, float] = {}
        self._clock_seen: int | None = None
        self._clock_moved_at = time.monotonic()
        self._next_sink_report = 0.0
        self._link_up_at = 0.0
        self._tick_reason: str | None = None  # the loop's own blindness (link, clock, streams), else None
        self._status_base = ""
        self._status_sent = ""
        self._queued_s = 0.0  # how long the message being handled waited in the socket before its read

    def fast_streams(self) -> tuple[str, ...]:
        return ("ATTITUDE", MOTOR_STREAM[self.cfg.input.motor_source])

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
                for step in self.pipeline.flush():
                    self._on_step(step)
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
        when not given)."""
        kind = msg.get_type()
        self._queued_s = 0.0 if read_s is None else read_s - received_s
        self.counters.messages += 1
        if kind == "BAD_DATA":
            self.counters.bad_data += 1
            self._bad_since_log += 1
            return
        try:
            steps = self.pipeline.feed(msg, received_s)
        except Exception:  # noqa: BLE001 - one bad message must not stop the monitor in flight
            self.counters.internal_errors += 1
            if self._error_log_limit.allow():
                log.exception("error while processing %s (%d so far); continuing", kind, self.counters.internal_errors)
            self.pipeline.reset()
            return
        dec = self.pipeline.decoder
        if dec.system_id is not None and self._system_id is None:
            self._system_id = dec.system_id
            self.link.set_system_id(dec.system_id)
            log.info("autopilot: system %d component %d", dec.system_id, dec.component_id)
            if self.memory is not None:
                self.memory.identify(dec.system_id)
        if self._system_id is not None and msg.get_srcSystem() == self._system_id and msg.get_srcComponent() == dec.component_id:
            self._rates[kind] += 1
            now = time.monotonic()
            if kind in self._fast:
                self._last_fast_rx[kind] = now
            if dec.clock_us != self._clock_seen:
                self._clock_seen, self._clock_moved_at = dec.clock_us, now
            if kind == "HEARTBEAT":
                armed = bool(getattr(msg, "base_mode", 0) & md.MAV_MODE_FLAG_SAFETY_ARMED)
                if self._armed and not armed and self.memory is not None:
                    self._disarmed()
                self._armed = armed
                self._last_autopilot_hb = now
                self.link.autopilot_seen(msg)
                if not self._link_up:
                    self._link_up = True
                    self._link_up_at = now
                    log.info("link up: autopilot heartbeat received")
                    self._set_status(f"link up: autopilot {self._system_id}")
            elif kind == "AUTOPILOT_VERSION" and self.memory is not None:
                self.memory.identify(self._system_id, int(getattr(msg, "uid", 0) or 0) or None)
            elif kind == "COMMAND_ACK" and msg.command == MAV_CMD_SET_MESSAGE_INTERVAL:
                self.counters.acks[int(msg.result)] += 1
                if msg.result != 0:
                    log.warning("stream-rate request refused by the autopilot (MAV_RESULT %d)", msg.result)
        while self.pipeline.clock_events:  # reboot or clock step: blind until good data flows again
            what = self.pipeline.clock_events.popleft()
            if self.memory is not None:
                self.memory.discard(what)
            reason = "autopilot rebooted" if "reboot" in what else "clock jumped" if "jumped" in what else "clock stepped back"
            self._transition(self.blind.enter(reason, what))
        for step in steps:
            self._on_step(step)
        if self.pipeline.vibration or self.pipeline.esc_samples:
            self._side_evidence()

    # -- evidence and the decision ---------------------------------------------------------
    def _side_evidence(self) -> None:
        """VIBRATION and ESC_STATUS since the last message: validated (bad ones counted), then used."""
        vib, esc = self.pipeline.vibration, self.pipeline.esc_samples
        self.pipeline.vibration, self.pipeline.esc_samples = [], []
        alerts, fresh = self.stage.side_evidence(vib, esc, self._airborne)
        self._evidence_t.update(fresh)
        for a in alerts:
            self._announce(a)

    def live_evidence(self, t_s: float) -> list[str]:
        """Which evidence is flowing now: classifier (motor stream + attitude), vibration, esc_rpm."""
        return [k for k, last in sorted(self._evidence_t.items()) if t_s - last <= EVIDENCE_FRESH_S]

    def live_context(self, t_s: float) -> list[str]:
        """Which context the grid steps carry now: velocity (LOCAL_POSITION_NED), imu (the specific force). Not
        evidence itself: what the omega^2 shares' baseline follows."""
        return [k for k in CONTEXT if t_s - self._context_t.get(k, -math.inf) <= EVIDENCE_FRESH_S]

    def _context_status(self) -> str:
        return f"; context live: {', '.join(self._context)}" if self._context else ""

    def _on_step(self, step) -> None:
        """One grid step: what is live and why the decision pauses (from the step itself), the decision stage (one
        call: every judge of the flight), STATUS, blindness seen from the step, then the step's alerts."""
        t = step.timestamp_us / US_PER_S
        self._airborne = step.airborne
        if step.valid:
            self._evidence_t["classifier"] = t
        if step.inputs is not None:
            if step.inputs.vel_heading_m_s is not None:
                self._context_t["velocity"] = t
            if step.inputs.accel_xy_frd_m_s2 is not None:
                self._context_t["imu"] = t
        live = self._live = self.live_evidence(t)
        self._context = self.live_context(t)
        if step.airborne and not step.valid:
            self._paused = step.reason
            self._record_pause(step.time_boot_ms, step.reason, live)  # at every such step: one held back is written later
        elif step.valid and self._paused:
            self._paused = ""
            self._record_resume(step.time_boot_ms, live)
        out = self.stage.step(step, self._pause_reason())
        if step.airborne and not step.valid:
            self._set_status(
                f"classifier paused: {step.reason}; evidence live: {', '.join(live) or 'none'}{self._context_status()}"
            )
        elif step.valid:
            self._set_status(
                f"airborne: deciding; evidence live: {', '.join(live)}{self._context_status()}"
                f"{out.shares_learning}{out.memory_status}"
            )
        elif not self._paused:
            self._set_status(f"not deciding: {step.reason}{out.memory_status}")
        self._blind_step(step)  # after the step's own pause state, so a recovered line says whether it runs
        if step.valid and step.fault_probability is not None:
            self._add_latency(step)
            self._send_named_values(step)
        for a in out.alerts:
            self._announce(a)

    def _pause_reason(self) -> str:
        """The decision pauses while a stream is stopped (``_paused``) or the monitor is blind; else it runs ('')."""
        return self._paused if self.blind.reason is None else f"blind: {self.blind.reason}"

    def _apply_pause(self) -> None:
        self.stage.pause(self._pause_reason())

    def _record_pause(self, time_boot_ms: int, reason: str, live: list[str]) -> None:
        """Journal and events line for a pause (or a new reason); flapping data is rate-limited.

        A pause held back by the limit is written at a later step of the same pause (within
        ``PAUSE_LOG_PERIOD_S``); one that ends first is not written, and neither is its resume.
        """
        if reason == self._pause_recorded:
            return
        if not self._pause_log_limit.allow():
            return
        self._pause_recorded = reason
        log.warning("t=%d ms: decision paused: %s", time_boot_ms, reason)
        self.events.write_record(
            {
                "event": "paused",
                "time_boot_ms": time_boot_ms,
                "reason": reason,
                "evidence_live": live,
                "context_live": self._context,
                "classifier_input": MOTOR_STREAM[self.cfg.input.motor_source],
            }
        )

    def _record_resume(self, time_boot_ms: int, live: list[str]) -> None:
        if not self._pause_recorded:
            return
        self._pause_recorded = ""
        log.info("t=%d ms: decision resumed", time_boot_ms)
        self.events.write_record(
            {"event": "resumed", "time_boot_ms": time_boot_ms, "evidence_live": live, "context_live": self._context}
        )

    def _announce(self, alert: Alert) -> None:
        self.counters.alerts += 1
        a, time_boot_ms = alert.announcement, alert.time_boot_ms
        event = {"event": "alert", **a.event(), "time_boot_ms": time_boot_ms, **alert.fields}
        log.warning("%s t=%d ms: %s (%s evidence)", a.level.upper(), time_boot_ms, a.text, a.evidence)
        # The ground station first: a failing disk must never delay or lose the alert itself.
        self.statustexts.add_text(a.text, a.severity)
        self._send_statustext()
        self._set_status(f"last alert: {a.text} at t={time_boot_ms} ms")
        self.events.write_record(event)

    def _add_latency(self, step) -> None:
        """From the completing message's arrival (its kernel stamp on udpin), and from its read."""
        if step.latency_s is not None:
            self.counters.latency.add(step.latency_s)
            self.counters.latency_from_read.add(step.latency_s - self._queued_s)

    def _send_named_values(self, step) -> None:
        if self.cfg.alerts.named_value_float:
            for i, v in enumerate(step.fault_probability):
                self.link.send_named_value_float(step.time_boot_ms, f"PWF{i + 1}", float(v))

    def _blind_step(self, step) -> None:
        """Blindness seen from one grid step: bad data while airborne for ``blind.after_s``, or good data again."""
        if step.data_ok:
            # A lost link or frozen clock ends at the next tick that clears it. Nothing to recover from (not blind,
            # no bad step counting towards blind.after_s) is the common step: the tracker is not called then.
            if self._tick_reason is None and (self._bad_steps or self.blind.reason is not None):
                self._bad_steps = False
                self._transition(self.blind.recover())
        elif step.airborne:
            self._bad_steps = True
            self._transition(self.blind.data(False, *_blind_reason(step.reason)))

    def _disarmed(self) -> None:
        """Landing and disarm: the flight may become the vehicle's history (monitor.daemon.memory_adapter)."""
        auth = self.link.flight_authenticated if getattr(self.link, "gate", None) is not None else None
        what = self.memory.disarmed(auth)
        if what != "no flight":
            self.events.write_record({"event": "vehicle_memory", "flight": what, "status": self.memory.status().lstrip("; ")})

    def _send_statustext(self) -> None:
        due = self.statustexts.due()
        if due is not None:
            self.counters.statustexts += 1
            self.link.send_statustext(*due)

    # -- blind spells, sink failures, systemd STATUS ---------------------------------------
    def _transition(self, t: Transition | None) -> None:
        if t is None:
            return
        if t.blind:
            log.warning("BLIND: %s", t.detail)
        else:
            log.info("recovered: %s (blind %.1f s)", t.detail, t.duration_s)
        record = t.record(self._clock_seen // 1000 if self._clock_seen is not None else None)
        self._apply_pause()  # blind: the decision adds nothing; recovered: it runs again unless a stream is stopped
        record["decision"] = "paused" if self.decision.paused_reason else "running"
        self._publish_status()
        self.events.write_record(record)
        self._send_notice()

    def _send_notice(self) -> None:
        due = self.blind.due()
        if due is not None:
            self.counters.notices += 1
            self.link.send_statustext(*due)

    def _set_status(self, text: str) -> None:
        """A new base text (the same one again, every step, changes nothing: blind spells and the events file
        publish their own changes, and the tick publishes the rest)."""
        if text != self._status_base:
            self._status_base = text
            self._publish_status()

    def _publish_status(self) -> None:
        blind = self.blind.reason is not None
        text = f"BLIND: {self.blind.detail}" if blind else self._status_base
        if blind:
            text += f"; decision paused, evidence live: {', '.join(self._live) or 'none'}"
        if self.events.failing:
            text += f"; events file failing ({self.events.last_error}, {self.events.pending} waiting)"
        if text and text != self._status_sent:
            self._status_sent = text
            self.notifier.status(text)

    def _check_blind(self, now: float) -> None:
        """Blindness seen from the loop: a lost link, a frozen autopilot clock, a fast stream gone."""
        found = self._loop_blindness(now)
        self._tick_reason = None if found is None else found[0]
        if found is not None:
            self._transition(self.blind.enter(*found))

    def _loop_blindness(self, now: float) -> tuple[str, str] | None:
        b = self.cfg.blind
        if self._system_id is None:
            return None
        if not self._link_up and self._last_autopilot_hb is not None:
            return "link lost", "link lost: no autopilot heartbeat"
        fresh = [k for k, t in self._last_fast_rx.items() if now - t < b.frozen_clock_s]
        if fresh and now - self._clock_moved_at >= b.frozen_clock_s:
            return "autopilot clock frozen", f"autopilot clock frozen for {now - self._clock_moved_at:.1f} s"
        if self._armed and self._link_up:
            for name, what in zip(self._fast, ("attitude", "motor")):
                t = self._last_fast_rx.get(name, self._link_up_at)
                if now - t >= max(b.after_s, self.cfg.resample.max_gap_s):
                    return f"no {what} data", f"no {name} from the autopilot"
        return None

    def _check_sink(self, now: float) -> None:
        self.events.retry()
        if self.events.failing and now >= self._next_sink_report:
            self._next_sink_report = now + SINK_REPORT_PERIOD_S
            self.counters.sink_reports += 1
            self.link.send_statustext("PROPWATCH: events file write failing", MAV_SEVERITY_WARNING)
        self._publish_status()

    # -- periodic work -------------------------------------------------------------------
    def tick(self, now: float) -> None:
        link = self.cfg.link
        talking = self._system_id is not None and not self.link.is_log  # a log cannot hear us
        # Over udpout the autopilot learns our address from what we send: heartbeat before we know
        # its system id (as the configured one, else PX4's default 1), or neither side ever speaks.
        announce = talking or self.link.is_udpout
        if announce and now >= self._next_hb:
            self.link.send_heartbeat()
            self._next_hb = now + 1.0 / link.heartbeat_rate_hz
        if link.request_streams and talking and self._slow and now >= self._next_request:
            self._request_streams(sorted(self._slow))
            self._next_request = now + link.request_retry_s
        if self.memory is not None and talking and self.memory.uid is None and now >= self._next_version_request:
            # the vehicle's identity for its memory: the board's uid (AUTOPILOT_VERSION), asked for a few times
            self.link.request_message(self._system_id, self.pipeline.decoder.component_id, AUTOPILOT_VERSION_ID)
            self._version_requests += 1
            self._next_version_request = now + (link.request_retry_s if self._version_requests < VERSION_REQUESTS else math.inf)
        if self._link_up and self._last_autopilot_hb is not None and now - self._last_autopilot_hb > link.link_timeout_s:
            self._link_up = False
            log.warning("link lost: no autopilot heartbeat for %.1f s", now - self._last_autopilot_hb)
            self._set_status("link lost")
        if now - self._rate_window_start >= link.rate_check_period_s:
            self._check_rates(now)
        if self.notifier.watchdog_s and now >= self._next_watchdog:
            self.notifier.watchdog()
            self._next_watchdog = now + self.notifier.watchdog_s / 2
        self._send_statustext()  # alerts held back by the rate limit
        if not self.link.is_log:  # a log replayed fast has no wall-clock meaning for blindness
            self._check_blind(now)
        self._send_notice()
        self._check_sink(now)
        if self._bad_since_log and now >= self._next_bad_log:
            log.warning("%d unparseable packets/bytes dropped (%d in total)", self._bad_since_log, self.counters.bad_data)
            self._bad_since_log = 0
            self._next_bad_log = now + BAD_DATA_LOG_PERIOD_S

    def _request_streams(self, names: list[str]) -> None:
        sysid, comp = self._system_id, self.pipeline.decoder.component_id
        for name in names:
            self.link.request_message_interval(sysid, comp, md.STREAM_IDS[name], self.cfg.link.stream_rate_hz)
            self.counters.stream_requests += 1
        if self.cfg.input.landed_state != "ignore" and "ATTITUDE" in names:
            self.link.request_message_interval(sysid, comp, md.STREAM_IDS["EXTENDED_SYS_STATE"], LANDED_RATE_HZ)
            self.counters.stream_requests += 1
        if "ATTITUDE" in names:
            self.link.request_message_interval(sysid, comp, md.STREAM_IDS["VIBRATION"], VIBRATION_RATE_HZ)
            self.link.request_message_interval(sysid, comp, md.STREAM_IDS["LOCAL_POSITION_NED"], VELOCITY_RATE_HZ)
            self.link.request_message_interval(sysid, comp, md.HIGHRES_IMU_ID, IMU_RATE_HZ)
            self.counters.stream_requests += 3
        log.info("requested %s at %.0f Hz (MAV_CMD_SET_MESSAGE_INTERVAL)", ", ".join(names), self.cfg.link.stream_rate_hz)

    def _check_rates(self, now: float) -> None:
        span = now - self._rate_window_start
        need = self.cfg.link.min_rate_fraction * self.cfg.resample.rate_hz
        slow = set()
        if self._system_id is None:
            others = sum(self.pipeline.decoder.ignored.values())
            log.warning(
                "no autopilot HEARTBEAT yet (%d messages received, %d from other systems/components)",
                self.counters.messages,
                others,
            )
        elif self._link_up:  # a link that is down is reported as such, not as slow streams
            for name in self.fast_streams():
                hz = self._rates[name] / span
                if hz < need:
                    slow.add(name)
                    what = "missing" if hz == 0 else f"at {hz:.1f} Hz"
                    log.warning("stream %s %s (need >= %.0f Hz)", name, what, need)
        self._slow = slow
        self._rates.clear()
        self._rate_window_start = now

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
            "latency_ms": _percentiles_ms(c.latency),
            "latency_from_read_ms": _percentiles_ms(c.latency_from_read),
            "loop": {
                "reads": c.reads,
                "paces": c.paces,
                "pace_misses": self.pipeline.pacer.misses,
            },
            "decision": self.decision.verdict(),
            "esc_rejected": dict(self.esc_telemetry.rejected),
        }

    def summary(self) -> None:
        r = self.report()
        if self._system_id is None:
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

    def write_report(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.report(), indent=2, default=float) + "\n", encoding="utf-8")


def _percentiles_ms(lat: LatencyHistogram) -> dict:
    return {"n": lat.n, "p50": lat.percentile_s(50) * 1e3, "p99": lat.percentile_s(99) * 1e3, "max": lat.max_s * 1e3}


def _blind_reason(step_reason: str) -> tuple[str, str]:
    """(short reason, detail) of an airborne step without usable data."""
    if "implausible" in step_reason:
        return ("implausible attitude" if step_reason.startswith("attitude") else "implausible motor data"), step_reason
    if step_reason.startswith("attitude") and "motor" not in step_reason:
        return "no attitude data", step_reason
    return "no motor data", step_reason
