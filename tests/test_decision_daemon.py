"""The daemon on the shared decision rule: which evidence is live, pauses, VIBRATION-only streams, bad VIBRATION."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink
from test_daemon_helpers import WALL_T0_S, synth_flight, toy_model, write_tlog

from monitor.daemon.config import monitor_config_from_mapping
from monitor.daemon.events import EventWriter
from monitor.daemon.link import Link
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.service import Daemon
from monitor.model import Classifier, choose_esc
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

BOOT0_S = 100.0  # synth_flight's boot time at flight time 0
REPO = Path(__file__).resolve().parent.parent


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
    paused = [e for e in events if e.get("event") == "paused"]
    assert paused and paused[0]["evidence_live"] == ["vibration"] and "motor" in paused[0]["reason"]
    alerts = [e for e in events if e.get("kind") == "decision"]
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
    assert not [e for e in events if e.get("kind") == "decision"], events


def test_a_stream_that_stops_pauses_the_decision_and_it_resumes(tmp_path, model):
    # SERVO_OUTPUT_RAW drops out for 3 s mid-flight (a hole in every stream): paused with the reason, then resumed.
    frames = synth_flight(40.0, hole_s=(20.0, 23.0))
    d, status, events = run_daemon(tmp_path, model, frames)
    kinds = [e["event"] for e in events if e.get("event") in ("paused", "resumed")]
    assert "paused" in kinds and "resumed" in kinds[kinds.index("paused") :], events
    assert any(s.startswith("classifier paused:") for s in status)
    assert np.isfinite(d.report()["latency_ms"]["p99"])


# -- the shipped classifier on simulated flights replayed from .tlog ------------------------------------
SHIPPED = REPO / "models" / "classifier.onnx"


def simulated_tlog(tmp_path, faulty: dict[int, int], onset_s: float, duration_s: float, wind_m_s: float, seed: int):
    """One flight of our simulator on a random route with steady wind; ``faulty`` = {rotor: 1 bent / 2 cracked}
    switched on at ``onset_s``; written as the .tlog PX4 would stream."""
    pytest.importorskip("torch")
    from monitor.vehicle import load_vehicle
    from offline.dataset.generate import DatasetSpec, routes, simulate_flights
    from offline.dataset.onset import SwitchedPropellers
    from offline.propellers import build_propellers
    from offline.sim.io_tlog import write_tlog as write_sim_tlog

    vehicle = load_vehicle(REPO / "models" / "vehicle.yaml")
    vehicle = dataclasses.replace(vehicle, wind_ned_m_s=(wind_m_s, 0.3 * wind_m_s, 0.0))
    cond = np.zeros((1, 4), np.int8)
    for rotor, kind in faulty.items():
        cond[0, rotor - 1] = kind
    spec = DatasetSpec("e2e", waypoints=("random",), duration_s=duration_s, propellers="quadratic", seed=seed)
    wps, _ = routes(spec, 1, seed=seed)
    before = build_propellers(vehicle, np.zeros_like(cond), kind="quadratic", rng_seed=seed)
    after = build_propellers(vehicle, cond, kind="quadratic", rng_seed=seed + 1)
    props = SwitchedPropellers(before, after, np.array([onset_s]))
    log = simulate_flights(vehicle, wps, cond, np.zeros(1), spec, seed, propellers=props)
    return write_sim_tlog(tmp_path / "flight.tlog", log, 0)


def replay_shipped(tmp_path, tlog):
    cfg = monitor_config_from_mapping({"link": {"tlog_speed": 0.0}})
    clf = Classifier(SHIPPED)
    pipeline = Pipeline(clf, cfg, choose_esc(clf, ""))
    events_path = tmp_path / "events.jsonl"
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    d = Daemon(cfg, Link(str(tlog), 191, 0.0), pipeline, EventWriter(events_path), StatusLog(), vehicle=vehicle)
    d.run()
    events = [json.loads(x) for x in events_path.read_text().splitlines()] if events_path.exists() else []
    return d, [e for e in events if e.get("kind") == "decision"]


@pytest.mark.slow
@pytest.mark.skipif(not SHIPPED.is_file(), reason="models/classifier.onnx not built")
def test_replayed_healthy_windy_flight_raises_nothing(tmp_path):
    tlog = simulated_tlog(tmp_path, {}, math.inf, 80.0, wind_m_s=5.0, seed=31)
    d, alerts = replay_shipped(tmp_path, tlog)
    assert d.report()["pipeline"]["classified"] > 1000  # it did watch the flight
    assert alerts == [], alerts


@pytest.mark.slow
@pytest.mark.skipif(not SHIPPED.is_file(), reason="models/classifier.onnx not built")
def test_replayed_onset_flight_raises_suspect_then_fault_on_the_right_propeller(tmp_path):
    onset_s = 30.0
    tlog = simulated_tlog(tmp_path, {2: 2}, onset_s, 75.0, wind_m_s=3.0, seed=32)
    d, alerts = replay_shipped(tmp_path, tlog)
    levels = [a["level"] for a in alerts]
    assert "suspect" in levels and "fault" in levels and levels.index("suspect") < levels.index("fault"), alerts
    assert all(a["faulty_propellers"] == [2] for a in alerts if a["level"] == "fault"), alerts
    t0 = d.pipeline.decoder.clock_us  # boot time at the end; the flight started duration earlier
    first_fault = next(a for a in alerts if a["level"] == "fault")
    assert first_fault["t_s"] - (t0 / 1e6 - 75.0) > onset_s  # never before the onset
    # The event carries the moment balance's reading of the 5 s before it: propeller 2 delivers the least.
    eff = first_fault["rotor_effectiveness"]
    assert eff is not None and len(first_fault["rotor_effectiveness_std"]) == 4
    assert int(np.argmin(eff)) == 1, eff
    # and the alert is worded from the windows that see the fault, not from the healthy half minute before it
    assert first_fault["text"].startswith("PROP 2 "), first_fault["text"]
