"""The daemon's per-step feature function equals the batch one, bit for bit (monitor.features)."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.features import FEATURES, PAPER_FEATURES, feature_function, step_feature_function

ALL = tuple(FEATURES)


def reference(names, rpm: np.ndarray, att: np.ndarray) -> np.ndarray:
    """What the daemon computed before: feature_function on one step (T = 1)."""
    signals = {"motor_rpm": rpm[None, :]}
    for i, n in enumerate(("roll_rad", "pitch_rad", "yaw_rad", "roll_rate_rad_s", "pitch_rate_rad_s", "yaw_rate_rad_s")):
        signals[n] = att[i : i + 1]
    return feature_function(names)(signals)[0]


def fast(names, rpm: np.ndarray, att: np.ndarray) -> np.ndarray:
    out = np.full(len(names), -123.0, dtype=np.float32)
    step_feature_function(names)(rpm, att, out)
    return out


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def random_steps(n: int, seed: int):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        rpm = rng.choice([rng.normal(9000.0, 3000.0, 4), rng.uniform(-2.0, 2.0, 4), rng.normal(0.0, 1e6, 4)])
        att = np.concatenate([rng.uniform(-np.pi, np.pi, 3), rng.normal(0.0, 3.0, 3)])
        yield rpm, att


@pytest.mark.parametrize("names", [ALL, PAPER_FEATURES, tuple(reversed(ALL)), ("yaw_cos", "rpm_rel_3", "collective_krpm2")])
def test_step_features_equal_the_batch_function_on_random_steps(names):
    for rpm, att in random_steps(400, seed=len(names)):
        assert same_bits(fast(names, rpm, att), reference(names, rpm, att)), (rpm, att)


@pytest.mark.filterwarnings("ignore:overflow encountered", "ignore:invalid value encountered")
def test_step_features_equal_the_batch_function_at_the_edges():
    """NaN and inf pass through exactly as in the batch path; a mean RPM near zero takes the same branch."""
    specials = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1.0, -1.0, 1.0000000001, 5e-324, 1e308]
    rng = np.random.default_rng(1)
    for v in specials:
        for pos in range(4):
            rpm = rng.normal(9000.0, 100.0, 4)
            rpm[pos] = v
            att = rng.normal(0.0, 1.0, 6)
            att[pos % 6] = v
            assert same_bits(fast(ALL, rpm, att), reference(ALL, rpm, att))
        const = np.full(4, v)
        assert same_bits(fast(ALL, const, np.full(6, v)), reference(ALL, const, np.full(6, v)))


def test_step_features_equal_the_batch_function_on_a_px4_stream():
    """Every grid step the daemon's pipeline builds from a PX4-like stream (the end-to-end tests' flight)."""
    pytest.importorskip("onnx")
    from pymavlink.dialects.v20 import common as mavlink
    from test_daemon_helpers import synth_flight

    from monitor.daemon.config import monitor_config_from_mapping
    from monitor.daemon.pipeline import Pipeline
    from monitor.esc import PAPER_ESC

    class Recorder:  # a classifier stand-in: the pipeline only needs its features and never a full window here
        path = "none"

        class info:
            features = ALL

        @staticmethod
        def check_compatible(*a):
            pass

    cfg = monitor_config_from_mapping({"inference": {"window": 10000}})
    pipe = Pipeline(Recorder, cfg, PAPER_ESC)
    steps = []
    real = pipe.hold.push

    def record(stream, t_us, values):
        out = real(stream, t_us, values)
        steps.extend(g.values for g in out)
        return out

    pipe.hold.push = record
    parser = mavlink.MAVLink(None)
    for _, frame in synth_flight(20.0, faulty=(2,), seed=3):
        for m in parser.parse_buffer(frame) or []:
            pipe.feed(m, 0.0)
    finite = [v for v in steps if np.isfinite(v["motor"]).all() and np.isfinite(v["attitude"]).all()]
    assert len(finite) > 300
    for v in steps:
        assert same_bits(fast(ALL, v["motor"], v["attitude"]), reference(ALL, v["motor"], v["attitude"]))
