"""A motor whose output is forced to its minimum in the air (our simulator, ``propwatch simulate --fault stopped``) is
named within 1 s, as a motor, by ``diagnose`` and by the daemon replaying the same log; a healthy flight of the same
route raises no motor alarm."""

from __future__ import annotations

import json

import pytest
from test_decision_daemon import SHIPPED, replay_shipped

from monitor.diagnose.engine import diagnose_file
from monitor.model import Classifier, choose_esc
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.sim.log import BOOT_OFFSET_US
from offline.simulate import SimulateSpec, write_flights

ONSET_S = 15.0


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    d = tmp_path_factory.mktemp("stop")
    stopped = write_flights(d / "stopped", SimulateSpec(label=4, fault="stopped", onset_s=ONSET_S, duration_s=25.0, seed=3))
    healthy = write_flights(d / "healthy", SimulateSpec(label=1, duration_s=25.0, seed=3))
    return stopped[0], healthy[0]


@pytest.mark.skipif(not SHIPPED.is_file(), reason="models/classifier.onnx not built")
def test_diagnose_names_the_stopped_motor_within_a_second(flights):
    clf = Classifier(SHIPPED)
    esc = choose_esc(clf, "")
    onset_boot_s = BOOT_OFFSET_US / 1e6 + ONSET_S
    _, d = diagnose_file(str(flights[0]), clf, esc, None, 20, load_vehicle(DEFAULT_VEHICLE))
    v = d.verdict
    assert v["source"] == "motor output" and v["faulty_propellers"] == [3] and v["confidence"] == "confident", v
    first = v["motor_output"][0]
    assert first["rotor"] == 3 and first["kind"] == "stopped"
    assert onset_boot_s <= first["since_boot_s"] < first["t_boot_s"] <= onset_boot_s + 1.0, first
    _, h = diagnose_file(str(flights[1]), clf, esc, None, 20, load_vehicle(DEFAULT_VEHICLE))
    assert h.verdict.get("source") != "motor output" and "motor_output" not in h.verdict


@pytest.mark.skipif(not SHIPPED.is_file(), reason="models/classifier.onnx not built")
def test_the_daemon_announces_the_stopped_motor_within_a_second(flights, tmp_path):
    d, alerts = replay_shipped(tmp_path, flights[0])
    motor = [a for a in alerts if a["evidence"] == "motor output"]
    assert motor and motor[0]["text"] == "MOTOR 3 STOPPED" and motor[0]["severity"] == "CRITICAL", alerts
    events = [json.loads(x) for x in (tmp_path / "events.jsonl").read_text().splitlines()]
    start = next(e for e in events if e.get("kind") == "decision" and e["text"] == "MOTOR 3 STOPPED")
    assert start["level"] == "fault" and start["faulty_propellers"] == [3]
    # its time, against the log's: within 1 s of the onset (boot clock of the simulated flight)
    assert 0 < start["t_s"] - (BOOT_OFFSET_US / 1e6 + ONSET_S) <= 1.0, start
    (tmp_path / "healthy").mkdir()
    _, healthy = replay_shipped(tmp_path / "healthy", flights[1])
    assert not [a for a in healthy if a["evidence"] == "motor output"], healthy
