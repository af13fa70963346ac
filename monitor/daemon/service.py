"""The daemon's loop: link in, pipeline, alerts out, heartbeats, rate checks, watchdog.

State that lives across loop turns is kept here (link health, stream rates,
pending stream requests); the per-step work is in ``pipeline``, the alert
rule in ``alerts``, the socket in ``link``.
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

import numpy as np

from monitor import mavlink_decode as md
from monitor.daemon.alerts import AlertRule, EventWriter, RateLimiter, StatusTextQueue
from monitor.daemon.config import MonitorConfig
from monitor.daemon.link import MAV_CMD_SET_MESSAGE_INTERVAL, Link
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.sdnotify import Notifier
from monitor.decision import Announcement, Decision, EscTelemetry, StepInputs, WindowEvidence, file_sha256

log = logging.getLogger("propwatch.monitor")

READ_TIMEOUT_S = 0.1  # select() returns at once when data comes; this only paces idle housekeeping
BAD_DATA_LOG_PERIOD_S = 5.0
MOTOR_STREAM = {"servo": "SERVO_OUTPUT_RAW", "actuator": "ACTUATOR_OUTPUT_STATUS", "esc": "ESC_STATUS"}
LANDED_RATE_HZ = 2.0  # EXTENDED_SYS_STATE: a state, not a signal
VIBRATION_RATE_HZ = 10.0  # imbalance evidence beside the classifier (PX4's default stream rate is lower)
EVIDENCE_FRESH_S = 2.0  # a VIBRATION / ESC_STATUS stream silent for longer is not live evidence


@dataclass
class Counters:
    messages: int = 0
    bad_data: int = 0
    alerts: int = 0
    statustexts: int = 0
    stream_requests: int = 0
    internal_errors: int = 0
    acks: Counter = field(default_factory=Counter)
    latencies_s: list = field(default_factory=list)


class Daemon:
    def __init__(
        self, config: MonitorConfig, link: Link, pipeline: Pipeline, events: EventWriter, notifier: Notifier | None = None
    ):
        self.cfg = config
        self.link = link
        self.pipeline = pipeline
        self.events = events
        self.notifier = notifier or Notifier({})
        self.rule = AlertRule(config.alerts)
        self.sequential = config.alerts.rule == "sequential"
        self.decision = Decision(
            config.alerts.decision(),
            config.resample.rate_hz,
            pipeline.window,
            model_sha256=file_sha256(pipeline.classifier.path),
        )
        self.esc_telemetry = EscTelemetry()
        self._evidence_t: dict[str, float] = {}  # evidence -> boot time (s) it was last usable
        self._paused = ""
        self._airborne = False
        self._status_text = ""
        self.statustexts = StatusTextQueue(config.alerts.statustext_min_interval_s, config.alerts.critical_threshold)
        self.stop = threading.Event()
        self.counters = Counters()
        self._rates: Counter = Counter()
        self._rate_window_start = time.monotonic()
        self._last_autopilot_hb: float | None = None
        self._link_up = False
        self._system_id: int | None = None
        self._next_hb = 0.0
        self._next_request = 0.0
        self._next_watchdog = 0.0
        self._next_bad_log = 0.0
        self._bad_since_log = 0
        self._classifying_state = False
        self._state_log_limit = RateLimiter(2.0)
        self._error_log_limit = RateLimiter(10.0)
        self._slow: set[str] = set(self.fast_streams())

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
        while not self.stop.is_set():
            try:
                batch = self.link.read(READ_TIMEOUT_S)
            except OSError as exc:  # serial unplugged, TCP peer gone: the link reopens itself
                log.error("link error on %s: %s; reopening", self.link.url, exc)
                self.link.close()
                continue
            for msg, received in batch:
                self.handle(msg, received)
            self.tick(time.monotonic())
            if self.link.is_log and self.link.eof:
                for step in self.pipeline.flush():
                    self._on_step(step)
                log.info("end of log %s", self.link.url)
                break
        self.notifier.stopping()
        self.events.close()
        self.summary()
        return 0

    def handle(self, msg, received_s: float) -> None:
        kind = msg.get_type()
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
        if self._system_id is not None and msg.get_srcSystem() == self._system_id and msg.get_srcComponent() == dec.component_id:
            self._rates[kind] += 1
            if kind == "HEARTBEAT":
                self._last_autopilot_hb = time.monotonic()
                if not self._link_up:
                    self._link_up = True
                    log.info("link up: autopilot heartbeat received")
                    self.notifier.status(f"link up: autopilot {self._system_id}")
            elif kind == "COMMAND_ACK" and msg.command == MAV_CMD_SET_MESSAGE_INTERVAL:
                self.counters.acks[int(msg.result)] += 1
                if msg.result != 0:
                    log.warning("stream-rate request refused by the autopilot (MAV_RESULT %d)", msg.result)
        for step in steps:
            self._on_step(step)
        if self.pipeline.vibration or self.pipeline.esc_samples:
            self._side_evidence()

    # -- evidence and the decision ---------------------------------------------------------
    def _side_evidence(self) -> None:
        """VIBRATION and ESC_STATUS since the last message: validated (bad ones counted), then used."""
        vib, esc = self.pipeline.vibration, self.pipeline.esc_samples
        self.pipeline.vibration, self.pipeline.esc_samples = [], []
        for v in vib:
            t = v.timestamp_us / 1e6
            before = sum(self.decision.vibration.rejected.values())
            for a in self.decision.vibration_sample(t, v.vibration, self._airborne):
                self._announce(a, int(v.timestamp_us // 1000))
            if sum(self.decision.vibration.rejected.values()) == before:
                self._evidence_t["vibration"] = t
        for e in esc:
            if self.esc_telemetry.observe(e.rpm) == "":
                self._evidence_t["esc_rpm"] = e.timestamp_us / 1e6

    def live_evidence(self, t_s: float) -> list[str]:
        """Which evidence is flowing now: classifier (motor stream + attitude), vibration, esc_rpm."""
        return [k for k, last in sorted(self._evidence_t.items()) if t_s - last <= EVIDENCE_FRESH_S]

    def _set_status(self, text: str) -> None:
        if text != self._status_text:
            self._status_text = text
            self.notifier.status(text)

    def _decide(self, step) -> None:
        """The shared decision rule on one grid step (pause when a stream stopped, never freeze it)."""
        t = step.timestamp_us / 1e6
        self._airborne = step.airborne
        self.decision.step(t, step.inputs or StepInputs(step.airborne))
        if step.valid:
            self._evidence_t["classifier"] = t
        live = self.live_evidence(t)
        if step.airborne and not step.valid:
            if self._paused != step.reason:
                self._paused = step.reason
                self.decision.pause(step.reason)
                motor = MOTOR_STREAM[self.cfg.input.motor_source]
                log.warning("t=%d ms: decision paused: %s", step.time_boot_ms, step.reason)
                self.events.write_event(
                    {
                        "kind": "paused",
                        "time_boot_ms": step.time_boot_ms,
                        "reason": step.reason,
                        "evidence_live": live,
                        "classifier_input": motor,
                    }
                )
            self._set_status(f"classifier paused: {step.reason}; evidence live: {', '.join(live) or 'none'}")
        elif step.valid and self._paused:
            self.events.write_event({"kind": "resumed", "time_boot_ms": step.time_boot_ms, "evidence_live": live})
            log.info("t=%d ms: decision resumed", step.time_boot_ms)
            self._paused = ""
            self.decision.resume()
        if step.valid:
            self._set_status(f"airborne: deciding; evidence live: {', '.join(live)}")
        elif not step.airborne and not self._paused:
            self._set_status(f"not deciding: {step.reason}")
        if not step.valid or step.fault_probability is None:
            return
        if step.latency_s is not None:
            self.counters.latencies_s.append(step.latency_s)
        ev = WindowEvidence(step.fault_probability, step.label_probability)
        for a in self.decision.window_evidence(t, ev):
            self._announce(a, step.time_boot_ms, step)

    def _announce(self, a: Announcement, time_boot_ms: int, step=None) -> None:
        self.counters.alerts += 1
        event = {**a.event(), "time_boot_ms": time_boot_ms}
        if step is not None and step.fault_probability is not None:
            event["probabilities"] = [round(float(p), 4) for p in step.fault_probability]
            event["battery_v"] = None if math.isnan(step.battery_v) else round(step.battery_v, 2)
        log.warning("%s t=%d ms: %s (%s evidence)", a.level.upper(), time_boot_ms, a.text, a.evidence)
        self.statustexts.add_text(a.text, a.severity)
        self._send_statustext()  # STATUSTEXT first: the pilot before the disk
        self.events.write_event(event)
        self._set_status(f"last alert: {a.text} at t={time_boot_ms} ms")

    def _on_step(self, step) -> None:
        if self.sequential:
            self._decide(step)
            return
        if step.valid != self._classifying_state:
            self._classifying_state = step.valid
            if step.valid:
                log.info("t=%d ms: buffering (classification after %d valid steps)", step.time_boot_ms, self.pipeline.window)
                self.notifier.status("airborne: classifying")
            elif self._state_log_limit.allow():  # NaN flapping must not flood the journal
                log.info("t=%d ms: not classifying: %s", step.time_boot_ms, step.reason)
                self.notifier.status(f"not classifying: {step.reason}")
        if not step.valid:
            self.rule.reset()
            return
        if step.fault_probability is None:
            return
        if step.latency_s is not None:
            self.counters.latencies_s.append(step.latency_s)
        p = step.fault_probability
        if self.cfg.alerts.named_value_float:
            for i, v in enumerate(p):
                self.link.send_named_value_float(step.time_boot_ms, f"PWF{i + 1}", float(v))
        alert = self.rule.update(step.time_boot_ms, p, step.label_probability, step.battery_v)
        if alert is None:
            return
        self.counters.alerts += 1
        text = alert.statustext()
        log.warning(
            "ALERT t=%d ms: %s (label %d, p=%s)",
            alert.time_boot_ms,
            text,
            alert.label,
            np.array2string(np.asarray(alert.fault_probability), precision=3),
        )
        self.notifier.status(f"last alert: {text} at t={alert.time_boot_ms} ms")
        self.events.write(alert)
        self.statustexts.add(alert)
        self._send_statustext()

    def _send_statustext(self) -> None:
        due = self.statustexts.due()
        if due is not None:
            self.counters.statustexts += 1
            self.link.send_statustext(*due)

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
        if self._link_up and self._last_autopilot_hb is not None and now - self._last_autopilot_hb > link.link_timeout_s:
            self._link_up = False
            log.warning("link lost: no autopilot heartbeat for %.1f s", now - self._last_autopilot_hb)
            self.notifier.status("link lost")
        if now - self._rate_window_start >= link.rate_check_period_s:
            self._check_rates(now)
        if self.notifier.watchdog_s and now >= self._next_watchdog:
            self.notifier.watchdog()
            self._next_watchdog = now + self.notifier.watchdog_s / 2
        self._send_statustext()  # alerts held back by the rate limit
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
        if self.sequential and "ATTITUDE" in names:
            self.link.request_message_interval(sysid, comp, md.STREAM_IDS["VIBRATION"], VIBRATION_RATE_HZ)
            self.counters.stream_requests += 1
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
        lat = np.asarray(self.counters.latencies_s, dtype=np.float64) * 1e3
        pct = (lambda q: float(np.percentile(lat, q))) if len(lat) else (lambda q: math.nan)
        c = self.counters
        return {
            "messages": c.messages,
            "bad_data": c.bad_data,
            "alerts": c.alerts,
            "statustexts": c.statustexts,
            "stream_requests": c.stream_requests,
            "internal_errors": c.internal_errors,
            "acks": {str(k): v for k, v in c.acks.items()},
            "pipeline": dict(self.pipeline.stats),
            "late_samples": self.pipeline.hold.late,
            "ignored": {f"{s}/{k}": n for (s, k), n in self.pipeline.decoder.ignored.items()},
            "undecodable": dict(self.pipeline.decoder.undecodable),
            "latency_ms": {"n": int(len(lat)), "p50": pct(50), "p99": pct(99), "max": float(lat.max()) if len(lat) else math.nan},
            "decision": self.decision.verdict() if self.sequential else None,
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
