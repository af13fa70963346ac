"""``propwatch inspect``: message statistics, motors, and the CSV of exactly what diagnose feeds the model."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_diagnose_fixtures import build_model, write_tlog

from monitor.cli import main as propwatch
from monitor.inspect.log import stream_stats
from monitor.model import Classifier

ULOG = Path(__file__).resolve().parents[2] / "shared" / "data" / "px4_ulog" / "sample_px4_events.ulg"


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    d = tmp_path_factory.mktemp("inspect")
    return write_tlog(d / "f2.tlog", duration_s=15.0, faulty=2, seed=2), build_model(d / "m.onnx")


def test_stream_stats_by_hand():
    t_us = np.array([0, 100_000, 200_000, 300_000, 1_300_000, 1_400_000])  # 10 Hz with one 1 s gap
    s = stream_stats("X", t_us)
    assert s["count"] == 6 and s["first_s"] == 0.0 and s["last_s"] == 1.4
    assert s["rate_hz"] == pytest.approx(5 / 1.4) and s["max_gap_s"] == pytest.approx(1.0) and s["gaps"] == 1
    assert stream_stats("Y", np.array([np.nan, np.nan]))["count"] == 2  # counted, not timed


def test_inspect_json_on_a_tlog(capsys, case):
    log, model = case
    assert propwatch(["inspect", str(log), "--model", str(model), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    names = {s["name"]: s for s in info["messages"]}
    assert {"HEARTBEAT", "ATTITUDE", "SERVO_OUTPUT_RAW"} <= set(names)
    assert names["ATTITUDE"]["rate_hz"] == pytest.approx(50.0, rel=0.05)
    assert info["vehicle_type"] == "MAV_TYPE_QUADROTOR"
    assert info["motors"]["names"] == ["1", "2", "3", "4"] and info["motors"]["cmd_unit"] == "us"
    assert info["grid"]["rate_hz"] == 20.0 and info["grid"]["airborne_steps"] > 100


def test_csv_is_exactly_what_diagnose_fed_the_model(capsys, case, tmp_path):
    log, model = case
    assert propwatch(["inspect", str(log), "--model", str(model), "--csv", str(tmp_path)]) == 0
    capsys.readouterr()
    assert propwatch(["diagnose", str(log), "--model", str(model), "--json"]) in (0, 3)
    diag = json.loads(capsys.readouterr().out)
    feats = np.genfromtxt(tmp_path / "f2.tlog.features.csv", delimiter=",", names=True)
    clf = Classifier(model)
    x = np.column_stack([feats[f] for f in clf.info.features]).astype(np.float32)
    ends = np.flatnonzero(feats["window_end"] == 1)
    assert len(ends) == diag["windows"]
    assert np.allclose(feats["timestamp_us"][ends] / 1e6, diag["timeline"]["t_boot_s"])
    windows = np.stack([x[e - clf.info.window + 1 : e + 1] for e in ends])
    _, faults = clf.predict(windows)
    assert np.allclose(faults, diag["timeline"]["fault_probability"], atol=1e-4)
    signals = np.genfromtxt(tmp_path / "f2.tlog.signals.csv", delimiter=",", names=True)
    assert len(signals) == len(feats) and {"motor_cmd_1", "motor_rpm_4", "yaw_rate_rad_s", "airborne"} <= set(signals.dtype.names)


@pytest.mark.realdata
@pytest.mark.skipif(not ULOG.is_file(), reason=f"real PX4 ULog not found at {ULOG}")
def test_inspect_a_real_ulog(capsys):
    assert propwatch(["inspect", str(ULOG), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    topics = {s["name"]: s for s in info["messages"]}
    assert topics["actuator_outputs[0]"]["rate_hz"] == pytest.approx(10.0, rel=0.05)  # the README's figure
    assert topics["vehicle_attitude[0]"]["rate_hz"] == pytest.approx(20.0, rel=0.05)
    assert info["vehicle_type"] == "MAV_TYPE_QUADROTOR (2)"
    assert info["parameters"]["PWM_MAIN_FUNC1"] == 101 and info["parameters"]["CA_ROTOR_COUNT"] == 4  # motor 1 on output 1
