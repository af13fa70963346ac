"""Fixtures shared by the log and diagnose tests: a contract-conforming ONNX model
and synthetic flight logs written with pymavlink (tlog) and by hand (ULog).

The fixture model is a transparent rule, so tests can predict its verdict:
the mean over the window of each rotor's RPM minus the mean RPM, times ``gain``,
is the logit of "that propeller alone is faulty"; "no fault" has logit ``bias``;
every other label -20. A faulty propeller needs more RPM, so a log where rotor k
runs ``excess`` RPM above the others gets label 1 + k.
"""

from __future__ import annotations

import contextlib
import io
import json
import struct
from pathlib import Path

import numpy as np

from monitor.esc import PAPER_ESC
from monitor.features import PAPER_FEATURES
from monitor.labels import LABEL_MASKS, class_names

GAIN_PER_RPM = 0.01
BIAS = 2.0
HOVER_PWM_US = 1500.0
RPM_STD = 1000.0  # the fixture's "training" spread of each rotor's RPM (the envelope check reads it)


def build_model(
    path: Path,
    features=PAPER_FEATURES,
    window: int = 100,
    rate_hz: float = 20.0,
    trained_rpm: float | None = None,
    esc: dict | None = None,
) -> Path:
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    f = len(features)
    w = np.zeros((f, 16), np.float32)
    b = np.full(16, -20.0, np.float32)
    b[0] = BIAS
    rpm_idx = [features.index(f"rpm_{i + 1}") for i in range(4)]
    for k in range(4):
        b[1 + k] = 0.0
        for j in range(4):
            w[rpm_idx[j], 1 + k] = GAIN_PER_RPM * ((1.0 if j == k else 0.0) - 0.25)
    inits = [
        numpy_helper.from_array(w, "W"),
        numpy_helper.from_array(b, "B"),
        numpy_helper.from_array(LABEL_MASKS.astype(np.float32), "M"),
        numpy_helper.from_array(np.array([1], np.int64), "axes"),
    ]
    nodes = [
        helper.make_node("ReduceMean", ["features", "axes"], ["m"], keepdims=0),
        helper.make_node("MatMul", ["m", "W"], ["mw"]),
        helper.make_node("Add", ["mw", "B"], ["logits"]),
        helper.make_node("Softmax", ["logits"], ["label_probability"], axis=1),
        helper.make_node("MatMul", ["label_probability", "M"], ["fault_probability"]),
    ]
    graph = helper.make_graph(
        nodes,
        "fixture",
        [helper.make_tensor_value_info("features", TensorProto.FLOAT, ["N", window, f])],
        [
            helper.make_tensor_value_info("label_probability", TensorProto.FLOAT, ["N", 16]),
            helper.make_tensor_value_info("fault_probability", TensorProto.FLOAT, ["N", 4]),
        ],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)])
    model.ir_version = 8
    hover_rpm = float(PAPER_ESC.cmd_to_rpm(HOVER_PWM_US)) if trained_rpm is None else trained_rpm
    mean = [hover_rpm if n.startswith("rpm_") else 0.0 for n in features]
    std = [RPM_STD if n.startswith("rpm_") else 1.0 for n in features]
    meta = {
        "format_version": 1,
        "features": list(features),
        "sample_rate_hz": rate_hz,
        "window": window,
        "normalization": {"mean": mean, "std": std},
        "class_names": class_names(),
        "label_table": {str(k): [] for k in range(1, 17)},
        "vehicle": {
            "name": "fixture",
            "esc": esc
            or {
                "a_rpm_per_cmd2": PAPER_ESC.a_rpm_per_cmd2,
                "b_rpm_per_cmd": PAPER_ESC.b_rpm_per_cmd,
                "c_rpm": PAPER_ESC.c_rpm,
                "cmd_min": PAPER_ESC.cmd_min,
                "cmd_max": PAPER_ESC.cmd_max,
                "cmd_unit": "us",
            },
        },
    }
    for k, v in meta.items():
        helper.set_model_props(model, {**{p.key: p.value for p in model.metadata_props}, f"propwatch.{k}": json.dumps(v)})
    onnx.checker.check_model(model)
    path = Path(path)
    onnx.save(model, str(path))
    return path


def flight_profile(duration_s: float, rate_hz: float, faulty: int | None, excess_pwm: float = 60.0, seed: int = 0):
    """Ground 2 s, flight, ground 2 s. Returns t_us, pwm (N,4), att (N,6), armed, landed_state."""
    rng = np.random.default_rng(seed)
    n = int(duration_s * rate_hz)
    t_us = (np.arange(n) * (1e6 / rate_hz)).astype(np.int64) + 1_000_000
    ts = (t_us - t_us[0]) / 1e6
    flying = (ts >= 2.0) & (ts < duration_s - 2.0)
    pwm = np.where(flying[:, None], HOVER_PWM_US, 1000.0) + np.where(flying[:, None], rng.normal(0, 5, (n, 4)), 0)
    if faulty is not None:
        pwm[flying, faulty - 1] += excess_pwm
    att = np.zeros((n, 6))
    att[:, 0] = 0.02 * np.sin(ts)
    att[:, 1] = 0.02 * np.cos(0.7 * ts)
    att[:, 2] = 0.3
    att[:, 3:] = rng.normal(0, 0.01, (n, 3))
    landed = np.where(flying, 2, 1)  # MAV_LANDED_STATE_IN_AIR / ON_GROUND
    return t_us, pwm, att, np.ones(n, bool), landed


def write_tlog(
    path: Path,
    duration_s: float = 30.0,
    faulty: int | None = None,
    rate_hz: float = 50.0,
    excess_pwm: float = 60.0,
    seed: int = 0,
    with_extras: bool = True,
) -> Path:
    """A PX4-like telemetry log: ATTITUDE + SERVO_OUTPUT_RAW at rate_hz, 1 Hz HEARTBEAT/EXTENDED_SYS_STATE/SYS_STATUS."""
    from pymavlink.dialects.v20 import common

    mav = common.MAVLink(None, srcSystem=1, srcComponent=1)
    gcs = common.MAVLink(None, srcSystem=255, srcComponent=190)
    t_us, pwm, att, armed, landed = flight_profile(duration_s, rate_hz, faulty, excess_pwm, seed)
    every = max(1, int(round(rate_hz)))
    out = bytearray()

    def put(t, msg, link=mav):
        out.extend(struct.pack(">Q", int(t) + 1_700_000_000_000_000))
        out.extend(msg.pack(link))
        link.seq = (link.seq + 1) % 256

    for i, t in enumerate(t_us):
        if i % every == 0:
            base = 128 if armed[i] else 0
            put(t, mav.heartbeat_encode(2, 12, base | 1, 0, 4))  # MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_PX4
            put(t, gcs.heartbeat_encode(6, 8, 0, 0, 4), gcs)  # a ground station: must be ignored
            put(t, mav.extended_sys_state_encode(0, int(landed[i])))
            put(t, mav.sys_status_encode(0, 0, 0, 500, 16000, -1, -1, 0, 0, 0, 0, 0, 0))
        put(t, mav.attitude_encode(int(t // 1000), *att[i]))
        put(t, mav.servo_output_raw_encode(int(t) & 0xFFFFFFFF, 0, *[int(round(v)) for v in pwm[i]], 0, 0, 0, 0))
        if with_extras and i % 5 == 0:
            put(t, mav.local_position_ned_encode(int(t // 1000), 0.0, 0.0, -1.0 if landed[i] == 2 else 0.0, 0.0, 0.0, 0.0))
    Path(path).write_bytes(bytes(out))
    return Path(path)


def run_diagnose(argv) -> tuple[int, str]:
    """``propwatch diagnose ARGV`` in this process: (exit code, stdout); stderr is swallowed."""
    from monitor.diagnose.cli import main as diagnose

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = diagnose([str(a) for a in argv])
    return code, out.getvalue()


def test_fixture_model_follows_its_rule(tmp_path):
    from monitor.model import Classifier

    clf = Classifier(build_model(tmp_path / "m.onnx"))
    x = np.zeros((2, 100, 10), np.float32)
    x[:, :, :4] = 6000.0
    x[1, :, 2] += 1000.0  # rotor 3 runs faster -> label 4 (propeller 3 alone)
    labels, faults = clf.predict(x)
    assert np.argmax(labels, axis=1).tolist() == [0, 3]
    assert faults[1, 2] > 0.9 and faults[0].max() < 0.2
    np.testing.assert_allclose(faults, labels @ LABEL_MASKS, atol=1e-6)
