"""The autopilot as the daemon sees it: identity, stream rates, arming, heartbeats, version and acks.

``Autopilot.watch`` sees every message once the pipeline has decoded it (the decoder knows then which system and
component is the autopilot, and where its boot clock is): the first autopilot names the link's system id and the
vehicle's memory; HEARTBEAT keeps the link up and says armed or disarmed (a disarm may make the flight the vehicle's
history); AUTOPILOT_VERSION names the board; COMMAND_ACK answers a stream-rate request. ``Autopilot.tick`` is the
periodic side: our heartbeat, stream-rate and version requests, the link timeout and the rate check.
``loop_blindness`` says what the loop cannot see from these (a lost link, a frozen clock, a fast stream gone).
"""

from __future__ import annotations

import logging
import math
import time
from collections import Counter

from monitor.daemon.announce import Announcer, Counters
from monitor.daemon.config import MonitorConfig
from monitor.daemon.link import MAV_CMD_SET_MESSAGE_INTERVAL, Link
from monitor.daemon.memory_adapter import VehicleMemory
from monitor.mavlink import decode as md

log = logging.getLogger("propwatch.monitor")

MOTOR_STREAM = {"servo": "SERVO_OUTPUT_RAW", "actuator": "ACTUATOR_OUTPUT_STATUS", "esc": "ESC_STATUS"}
LANDED_RATE_HZ = 2.0  # EXTENDED_SYS_STATE: a state, not a signal
VIBRATION_RATE_HZ = 10.0  # imbalance evidence beside the classifier (PX4's default stream rate is lower)
# LOCAL_POSITION_NED: the velocity the shares' baseline follows, held on the 20 Hz grid. PX4's own rate on an onboard
# (companion) link, so the request never slows it for another consumer there; a radio link's 1 Hz gets raised.
VELOCITY_RATE_HZ = 30.0
# HIGHRES_IMU: the body's specific force (the air's drag), averaged over each 20 Hz step. PX4's rate for it on an
# onboard link; SCALED_IMU, what some links carry instead, is used as it comes (not requested).
IMU_RATE_HZ = 50.0
AUTOPILOT_VERSION_ID = 148
VERSION_REQUESTS = 3  # AUTOPILOT_VERSION asked for at most this often (an autopilot that never answers: sysid it is)


class Autopilot:
    def __init__(
        self,
        config: MonitorConfig,
        link: Link,
        decoder: md.MavlinkDecoder,
        announce: Announcer,
        counters: Counters,
        memory: VehicleMemory | None = None,
    ):
        self.cfg = config
        self.link = link
        self.decoder = decoder
        self.announce = announce
        self.counters = counters
        self.memory = memory  # the vehicle's healthy history, None without a state dir
        self.system_id: int | None = None
        self.fast = ("ATTITUDE", MOTOR_STREAM[config.input.motor_source])  # the streams the classifier needs
        self.slow: set[str] = set(self.fast)  # fast streams below their rate at the last check (asked for again)
        self.armed = False
        self.link_up = False
        self.link_up_at = 0.0
        self.last_heartbeat: float | None = None  # monotonic time of the autopilot's last HEARTBEAT
        self.last_fast_rx: dict[str, float] = {}
        self.clock_us: int | None = None  # the autopilot's boot clock as last seen
        self.clock_moved_at = time.monotonic()
        self.rates: Counter = Counter()
        self.rate_window_start = time.monotonic()
        self.next_heartbeat = 0.0
        self.next_request = 0.0
        self.next_version_request = 0.0
        self.version_requests = 0

    # -- each message ----------------------------------------------------------------------
    def watch(self, msg) -> None:
        """One message, already decoded by the pipeline (the decoder knows the autopilot's ids and clock)."""
        dec = self.decoder
        if dec.system_id is not None and self.system_id is None:
            self.system_id = dec.system_id
            self.link.set_system_id(dec.system_id)
            self.announce.system_id = dec.system_id
            log.info("autopilot: system %d component %d", dec.system_id, dec.component_id)
            if self.memory is not None:
                self.memory.identify(dec.system_id)
        if self.system_id is None or msg.get_srcSystem() != self.system_id or msg.get_srcComponent() != dec.component_id:
            return
        kind = msg.get_type()
        self.rates[kind] += 1
        now = time.monotonic()
        if kind in self.fast:
            last = max(self.last_fast_rx.values(), default=None)
            if last is None or now - last >= self.cfg.blind.frozen_clock_s:
                # The first fast message, or the first after a silence: a frozen clock is one that stands still while
                # messages keep coming, so its time counts from here (the decoder confirms a clock over a few samples)
                self.clock_moved_at = now
            self.last_fast_rx[kind] = now
        if dec.clock_us != self.clock_us:
            self.clock_us, self.clock_moved_at = dec.clock_us, now
        if kind == "HEARTBEAT":
            armed = bool(getattr(msg, "base_mode", 0) & md.MAV_MODE_FLAG_SAFETY_ARMED)
            if self.armed and not armed and self.memory is not None:
                self._disarmed()
            self.armed = armed
            self.last_heartbeat = now
            self.link.autopilot_seen(msg)
            if not self.link_up:
                self.link_up = True
                self.link_up_at = now
                log.info("link up: autopilot heartbeat received")
                self.announce.set_status(f"link up: autopilot {self.system_id}")
        elif kind == "AUTOPILOT_VERSION" and self.memory is not None:
            notice = self.memory.identify(self.system_id, int(getattr(msg, "uid", 0) or 0) or None, self.armed)
            if notice:
                self.announce.record({"event": "vehicle_identity", "notice": notice, "vehicle": self.memory.key})
        elif kind == "COMMAND_ACK" and msg.command == MAV_CMD_SET_MESSAGE_INTERVAL:
            self.counters.acks[int(msg.result)] += 1
            if msg.result != 0:
                log.warning("stream-rate request refused by the autopilot (MAV_RESULT %d)", msg.result)

    def rebooted(self) -> None:
        """The autopilot's boot time went back: a new boot, whose uid is asked for and taken again."""
        if self.memory is not None:
            self.memory.new_boot()
            self.version_requests, self.next_version_request = 0, 0.0

    def _disarmed(self) -> None:
        """Landing and disarm: the flight may become the vehicle's history (monitor.daemon.memory_adapter)."""
        auth = self.link.flight_authenticated if getattr(self.link, "gate", None) is not None else None
        what = self.memory.disarmed(auth)
        if self.memory.needs_uid:  # a uid that came in flight was ignored: ask again on the ground
            self.version_requests, self.next_version_request = 0, 0.0
        if what != "no flight":
            self.announce.record({"event": "vehicle_memory", "flight": what, "status": self.memory.status().lstrip("; ")})

    # -- periodic work -------------------------------------------------------------------
    def tick(self, now: float) -> None:
        link = self.cfg.link
        talking = self.system_id is not None and not self.link.is_log  # a log cannot hear us
        # Over udpout the autopilot learns our address from what we send: heartbeat before we know
        # its system id (as the configured one, else PX4's default 1), or neither side ever speaks.
        if (talking or self.link.is_udpout) and now >= self.next_heartbeat:
            self.link.send_heartbeat()
            self.next_heartbeat = now + 1.0 / link.heartbeat_rate_hz
        if link.request_streams and talking and self.slow and now >= self.next_request:
            self._request_streams(sorted(self.slow))
            self.next_request = now + link.request_retry_s
        if self.memory is not None and talking and self.memory.needs_uid and now >= self.next_version_request:
            # the vehicle's identity for its memory: the board's uid (AUTOPILOT_VERSION), asked for a few times
            self.link.request_message(self.system_id, self.decoder.component_id, AUTOPILOT_VERSION_ID)
            self.version_requests += 1
            retry = link.request_retry_s if self.version_requests < VERSION_REQUESTS else math.inf
            self.next_version_request = now + retry
        if self.link_up and self.last_heartbeat is not None and now - self.last_heartbeat > link.link_timeout_s:
            self.link_up = False
            log.warning("link lost: no autopilot heartbeat for %.1f s", now - self.last_heartbeat)
            self.announce.set_status("link lost")
        if now - self.rate_window_start >= link.rate_check_period_s:
            self._check_rates(now)

    def _request_streams(self, names: list[str]) -> None:
        sysid, comp = self.system_id, self.decoder.component_id
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
        span = now - self.rate_window_start
        need = self.cfg.link.min_rate_fraction * self.cfg.resample.rate_hz
        slow = set()
        if self.system_id is None:
            others = sum(self.decoder.ignored.values())
            log.warning(
                "no autopilot HEARTBEAT yet (%d messages received, %d from other systems/components)",
                self.counters.messages,
                others,
            )
        elif self.link_up:  # a link that is down is reported as such, not as slow streams
            for name in self.fast:
                hz = self.rates[name] / span
                if hz < need:
                    slow.add(name)
                    what = "missing" if hz == 0 else f"at {hz:.1f} Hz"
                    log.warning("stream %s %s (need >= %.0f Hz)", name, what, need)
        self.slow = slow
        self.rates.clear()
        self.rate_window_start = now

    def loop_blindness(self, now: float) -> tuple[str, str] | None:
        """(reason, detail) of what the loop cannot see: a lost link, a frozen autopilot clock, a fast stream gone."""
        b = self.cfg.blind
        if self.system_id is None:
            return None
        if not self.link_up and self.last_heartbeat is not None:
            return "link lost", "link lost: no autopilot heartbeat"
        fresh = [k for k, t in self.last_fast_rx.items() if now - t < b.frozen_clock_s]
        if fresh and now - self.clock_moved_at >= b.frozen_clock_s:
            return "autopilot clock frozen", f"autopilot clock frozen for {now - self.clock_moved_at:.1f} s"
        if self.armed and self.link_up:
            for name, what in zip(self.fast, ("attitude", "motor")):
                t = self.last_fast_rx.get(name, self.link_up_at)
                if now - t >= max(b.after_s, self.cfg.resample.max_gap_s):
                    return f"no {what} data", f"no {name} from the autopilot"
        return None
