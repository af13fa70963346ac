"""What keeps the daemon cheap at 20 Hz: housekeeping is paced by time, not by datagrams; no telemetry thread."""

from __future__ import annotations

import os
import subprocess
import sys

from test_daemon_helpers import synth_flight, toy_model, write_tlog

from monitor.daemon import service
from monitor.daemon.config import monitor_config_from_mapping
from monitor.daemon.events import EventWriter
from monitor.daemon.link import Link
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.sdnotify import Notifier
from monitor.daemon.service import Daemon
from monitor.model import Classifier, choose_esc


class CountingDaemon(Daemon):
    ticks = 0

    def tick(self, now: float) -> None:
        self.ticks += 1
        super().tick(now)


def test_housekeeping_runs_by_the_clock_not_after_every_datagram(tmp_path, monkeypatch):
    tlog = write_tlog(tmp_path / "flight.tlog", synth_flight(20.0))
    clf = Classifier(toy_model(tmp_path / "toy.onnx"))
    cfg = monitor_config_from_mapping({"link": {"tlog_speed": 0.0}})
    d = CountingDaemon(cfg, Link(str(tlog), 191, 0.0), Pipeline(clf, cfg, choose_esc(clf, "")), EventWriter(None), Notifier({}))
    clock = [0.0]

    def slow_clock() -> float:  # each reading 1 ms later: about a thousand messages a second of loop time
        clock[0] += 0.001
        return clock[0]

    monkeypatch.setattr(service.time, "monotonic", slow_clock)
    d.run()
    messages = d.counters.messages
    assert messages > 1500 and d.pipeline.stats["classified"] > 0  # the flight was read and classified to its end
    # one tick per TICK_PERIOD_S of loop time (each turn reads the clock about twice), never one per datagram
    assert 0 < d.ticks <= 2 * clock[0] / service.TICK_PERIOD_S + 2
    assert d.ticks < messages / 10


def test_onnxruntime_telemetry_is_off_before_the_library_loads():
    code = "import monitor.model, os, sys; assert 'onnxruntime' not in sys.modules; print(os.environ['ORT_DISABLE_TELEMETRY'])"
    env = {k: v for k, v in os.environ.items() if k != "ORT_DISABLE_TELEMETRY"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.strip() == "1"
