"""The daemon on the shared decision rule: which evidence is live, pauses, VIBRATION-only streams, bad VIBRATION."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink
from test_daemon_helpers import WALL_T0_S, synth_flight, toy_model, write_tlog

from monitor.daemon.alerts import EventWriter
from monitor.daemon.config import monitor_config_from_mapping
from monitor.daemon.link import Link
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.service import Daemon
from monitor.model import Classifier, choose_esc

BOOT0_S = 100.0  # synth_flight's boot time at flight time 0


class StatusLog:
    """Stands in for systemd's notifier: keeps every STATUS line."""

    watchdog_s = None

    def __init__(self):
        self.lines: list[str] = []

    def ready(self, text):
        self.lines.append(text)

    def status(self, text):
        self.lines.append(text)

    def stopping(self):
        pass

    def watchdog(self):
        pass


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return toy_model(tmp_path_factory.mktemp("model") / "toy.onnx")


def vibration_frames(duration_s, level_of_t, rate_hz=10.0, noise=0.03):
    """VIBRATION at ``rate_hz``; vibration_z = level_of_t(t) with 3 % noise (a real metric never repeats exactly)."""
    ap = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    rng = np.random.default_rng(5)
    out = []
    for k in range(int(duration_s * rate_hz)):
        t = k / rate_hz + 0.0031
        z = level_of_t(t) * (1.0 + noise * rng.standard_normal())
        msg = mavlink.MAVLink_vibration_message(int((BOOT0_S + t) * 1e6), 0.01, 0.02, z, 0, 0, 0)
        out.append((WALL_T0_S + t + 0.003, msg.pack(ap)))
    return out


def run_daemon(tmp_path, model, frames):
    tlog = write_tlog(tmp_path / "flight.tlog", sorted(frames, key=lambda f: f[0]))
    cfg = monitor_config_from_mapping({"link": {"tlog_speed": 0.0}})
    clf = Classifier(model)
    pipeline = Pipeline(clf, cfg, choose_esc(clf, ""))
    events_path = tmp_path / "events.jsonl"
    status = StatusLog()
    d = Daemon(cfg, Link(str(tlog), 191, 0.0), pipeline, EventWriter(events_path), status)
    d.run()
    events = [json.loads(x) for x in events_path.read_text().splitlines()] if events_path.exists() else []
    return d, status.lines, events


def test_vibration_only_stream_is_used_and_the_status_says_so(tmp_path, model):
    # No SERVO_OUTPUT_RAW at all (servo_hz=0): the classifier cannot run; VIBRATION still can.
    frames = synth_flight(90.0, servo_hz=0.0) + vibration_frames(90.0, lambda t: 0.3 if t < 50.0 else 1.8)
    d, status, events = run_daemon(tmp_path, model, frames)
    assert any("classifier paused: motor missing" in s and "evidence live: vibration" in s for s in status), status
    paused = [e for e in events if e["kind"] == "paused"]
    assert paused and paused[0]["evidence_live"] == ["vibration"] and "motor" in paused[0]["reason"]
    alerts = [e for e in events if e["kind"] == "decision"]
    assert [(a["level"], a["faulty_propellers"], a["evidence"]) for a in alerts] == [("suspect", [], "vibration")]
    assert alerts[0]["t_s"] > BOOT0_S + 50.0
    assert d.report()["pipeline"]["classified"] == 0  # nothing invented for the missing motor stream


def test_nan_and_frozen_vibration_is_counted_never_an_alert(tmp_path, model):
    def level(t):
        if t < 30.0:
            return 0.3 + 0.01 * math.sin(7 * t)  # varies: never frozen
        return float("nan") if int(t * 10) % 2 else 25.0  # NaN, and a value stuck far above the baseline

    frames = synth_flight(70.0, servo_hz=0.0) + vibration_frames(70.0, level, noise=0.0)
    d, _, events = run_daemon(tmp_path, model, frames)
    rejected = d.report()["decision"]["vibration_rejected"]
    assert rejected["nan"] > 100 and rejected["frozen"] > 100, rejected
    assert not [e for e in events if e["kind"] == "decision"], events


def test_a_stream_that_stops_pauses_the_decision_and_it_resumes(tmp_path, model):
    # SERVO_OUTPUT_RAW drops out for 3 s mid-flight (a hole in every stream): paused with the reason, then resumed.
    frames = synth_flight(40.0, hole_s=(20.0, 23.0))
    d, status, events = run_daemon(tmp_path, model, frames)
    kinds = [e["kind"] for e in events if e["kind"] in ("paused", "resumed")]
    assert "paused" in kinds and "resumed" in kinds[kinds.index("paused") :], events
    assert any(s.startswith("classifier paused:") for s in status)
    assert np.isfinite(d.report()["latency_ms"]["p99"])
