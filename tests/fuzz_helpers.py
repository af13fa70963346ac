"""Helpers for the fuzz/hardening tests: a PX4-like message generator, a link and notifier that record."""

from __future__ import annotations

import math
from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink

from monitor.daemon.config import monitor_config_from_mapping
from monitor.daemon.events import EventWriter
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.sdnotify import Notifier
from monitor.daemon.service import Daemon
from monitor.esc import PAPER_ESC

HOVER_PWM_US = 1450


def decoded(m, sys_id: int = 1, comp: int = 1):
    """A message as the daemon receives it: packed by a sender, parsed back by pymavlink."""
    return mavlink.MAVLink(None).decode(bytearray(m.pack(mavlink.MAVLink(None, srcSystem=sys_id, srcComponent=comp))))


def px4_stream(
    t0_s: float,
    t1_s: float,
    seed: int = 0,
    att_hz: float = 50.0,
    servo_hz: float = 25.0,
    faulty: tuple[int, ...] = (),
    attitude: Callable[[float], tuple[float, ...]] | None = None,
    pwm: Callable[[float], list[int]] | None = None,
    sys_id: int = 1,
) -> list:
    """Armed, IN_AIR PX4 messages with boot times in [t0_s, t1_s), in time order.

    ``attitude(t)`` / ``pwm(t)`` override the values at boot time t (for injected faults).
    """
    import numpy as np

    rng = np.random.default_rng(seed)
    events: list[tuple[float, int, object]] = []
    t = math.ceil(t0_s)
    while t < t1_s:
        events.append((t, 0, mavlink.MAVLink_heartbeat_message(2, 12, 128 | 1, 0, 4, 3)))
        events.append((t + 0.001, 1, mavlink.MAVLink_extended_sys_state_message(0, 2)))
        t += 0.5
    k0, k1 = math.ceil(t0_s * att_hz), math.ceil(t1_s * att_hz)
    for k in range(k0, k1):
        t = k / att_hz
        if attitude is not None:
            vals = attitude(t)
        else:
            vals = (0.02 * math.sin(0.5 * t), 0.015 * math.cos(0.4 * t), 0.3, *rng.normal(0.0, 0.01, 3))
        events.append((t, 2, mavlink.MAVLink_attitude_message(int(round(t * 1000)), *vals)))
    k0, k1 = math.ceil(t0_s * servo_hz), math.ceil(t1_s * servo_hz)
    for k in range(k0, k1):
        t = k / servo_hz + 0.001
        if pwm is not None:
            u = pwm(t)
        else:
            u = [int(round(HOVER_PWM_US + 8.0 * math.sin(0.7 * t) + rng.normal(0.0, 3.0))) for _ in range(4)]
            for p in faulty:
                u[p - 1] += 60
        ch = list(u) + [0] * 4
        events.append((t, 3, mavlink.MAVLink_servo_output_raw_message(int(round(t * 1e6)) & 0xFFFFFFFF, 0, *ch)))
    events.sort(key=lambda e: (e[0], e[1]))
    return [decoded(m, sys_id) for _, _, m in events]


class FakeLink:
    """Records what the daemon sends instead of sending it."""

    url = "fake:"
    is_log = False
    is_udpout = False
    eof = False

    def __init__(self) -> None:
        self.sent: list[tuple] = []

    def statustexts(self) -> list[tuple[str, int]]:
        return [(s[1], s[2]) for s in self.sent if s[0] == "STATUSTEXT"]

    def set_system_id(self, system_id: int) -> None:
        pass

    def autopilot_seen(self, msg=None) -> None:
        pass

    def stats(self) -> dict:
        return {}

    def close(self) -> None:
        pass

    def send_heartbeat(self) -> None:
        self.sent.append(("HEARTBEAT",))

    def send_statustext(self, text: str, severity: int) -> None:
        self.sent.append(("STATUSTEXT", text, severity))

    def send_named_value_float(self, *args) -> None:
        self.sent.append(("NAMED_VALUE_FLOAT", *args))

    def request_message_interval(self, *args) -> None:
        self.sent.append(("COMMAND_LONG", *args))


class RecordingNotifier(Notifier):
    def __init__(self) -> None:
        super().__init__({})
        self.states: list[str] = []

    def notify(self, state: str) -> bool:
        self.states.append(state)
        return True

    def statuses(self) -> list[str]:
        return [s[len("STATUS=") :] for s in self.states if s.startswith("STATUS=")]


def make_daemon(classifier, events_path=None, config: dict | None = None, events_clock=None):
    # the classifier given is declared the synthetic vehicle's (undeclared, a network is silent)
    cfg = monitor_config_from_mapping({"airframe_declared": True, **(config or {})})
    link = FakeLink()
    kw = {"clock": events_clock} if events_clock else {}
    events = EventWriter(events_path, cfg.blind.events_retry_s, cfg.blind.events_backlog, **kw)
    d = Daemon(cfg, link, Pipeline(classifier, cfg, PAPER_ESC), events, RecordingNotifier())
    return d, link


def feed(daemon: Daemon, msgs, tick_every: int = 50) -> list:
    """Handle every message (ticking as the loop would); returns the steps' StepResults seen."""
    import time

    steps = []
    real_on_step = daemon._on_step

    def spy(step):
        steps.append(step)
        real_on_step(step)

    daemon._on_step = spy
    try:
        for i, m in enumerate(msgs):
            daemon.handle(m, time.perf_counter())
            if i % tick_every == 0:
                daemon.tick(time.monotonic())
        daemon.tick(time.monotonic())
    finally:
        daemon._on_step = real_on_step
    return steps
