"""Same log, two paths: the daemon's per-step streaming pipeline and diagnose's
batch path give identical probabilities at every step both classify."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_diagnose_fixtures import build_model, write_tlog

from monitor.daemon.config import MonitorConfig, ResampleConfig
from monitor.daemon.pipeline import Pipeline
from monitor.diagnose.engine import PREDICT_BATCH_WINDOWS, predict_at, window_ends
from monitor.esc import PAPER_ESC
from monitor.features import compute_features
from monitor.logs import raw as raw_mod
from monitor.logs import read_log
from monitor.model import Classifier
from monitor.resample import US_PER_S


def streamed(path, clf) -> dict[int, np.ndarray]:
    from pymavlink import mavutil

    pipe = Pipeline(clf, MonitorConfig(), PAPER_ESC)
    out = {}
    conn = mavutil.mavlink_connection(str(path), dialect="common")
    while (msg := conn.recv_match()) is not None:
        for step in pipe.feed(msg, received_s=0.0):
            if step.fault_probability is not None:
                out[step.timestamp_us] = step.fault_probability
    for step in pipe.flush():
        if step.fault_probability is not None:
            out[step.timestamp_us] = step.fault_probability
    conn.close()
    return out


def batch(path, clf, batch_size: int) -> dict[int, np.ndarray]:
    table = read_log(path, esc=PAPER_ESC)
    feats = compute_features(table.signals(), clf.info.features)
    ends = window_ends(table, feats, clf.info.window, hop=1)
    _, faults = predict_at(clf, feats, ends, clf.info.window, batch=batch_size)
    return dict(zip(table.timestamp_us[ends].tolist(), faults))


def test_holding_ages_match_the_daemon_defaults():
    r = ResampleConfig()
    assert raw_mod.MAX_AGE_US == round(r.max_gap_s * US_PER_S)
    assert raw_mod.STATE_MAX_AGE_US == round(r.state_max_age_s * US_PER_S)
    assert raw_mod.BATTERY_MAX_AGE_US == round(r.battery_max_age_s * US_PER_S)


@pytest.mark.parametrize("faulty", [None, 2])
def test_daemon_and_batch_give_identical_probabilities(tmp_path, faulty):
    clf = Classifier(build_model(tmp_path / "m.onnx"))
    path = write_tlog(tmp_path / "f.tlog", duration_s=30.0, faulty=faulty, seed=3)
    live, offline = streamed(path, clf), batch(path, clf, batch_size=1)
    common = sorted(set(live) & set(offline))
    # Both classify the airborne stretch (26 s minus the first 5 s window): nearly every step is common.
    assert len(common) > 0.9 * max(len(live), len(offline)) > 300
    # Same windows, same features, one window per inference as the daemon runs it: bit-identical.
    assert all(np.array_equal(live[t], offline[t]) for t in common)
    # Batched inference (diagnose's default) differs only by onnxruntime's float32 summation order.
    batched = batch(path, clf, batch_size=512)
    assert max(float(np.abs(live[t] - batched[t]).max()) for t in common) < 2e-5


SHIPPED = Path(__file__).resolve().parent.parent / "models" / "classifier.onnx"


@pytest.mark.skipif(not SHIPPED.is_file(), reason=f"no shipped classifier at {SHIPPED}")
def test_parity_with_the_shipped_cnn(tmp_path):
    clf = Classifier(SHIPPED)
    path = write_tlog(tmp_path / "f.tlog", duration_s=20.0, faulty=1, seed=5)
    live, offline = streamed(path, clf), batch(path, clf, batch_size=1)
    common = sorted(set(live) & set(offline))
    assert len(common) > 0.9 * max(len(live), len(offline)) > 150
    assert all(np.array_equal(live[t], offline[t]) for t in common)


@pytest.mark.parametrize("shipped", [False, True])
def test_diagnose_batches_give_the_outputs_of_one_call(tmp_path, shipped):
    """``diagnose`` classifies in calls of ``PREDICT_BATCH_WINDOWS`` windows: its outputs must be those of one call
    of all the windows (the JSON does not depend on how the windows were split), here for a count not a multiple
    of 4, whose last windows take the runtime's other path."""
    if shipped and not SHIPPED.is_file():
        pytest.skip(f"no shipped classifier at {SHIPPED}")
    clf = Classifier(SHIPPED if shipped else build_model(tmp_path / "m.onnx"))
    table = read_log(write_tlog(tmp_path / "f.tlog", duration_s=30.0, faulty=2, seed=3), esc=PAPER_ESC)
    feats = compute_features(table.signals(), clf.info.features)
    ends = window_ends(table, feats, clf.info.window, hop=1)
    ends = ends[: len(ends) - (len(ends) - 3) % 4]  # 3 windows past a multiple of 4
    assert len(ends) > 3 * PREDICT_BATCH_WINDOWS
    one = predict_at(clf, feats, ends, clf.info.window, batch=len(ends))
    split = predict_at(clf, feats, ends, clf.info.window, batch=PREDICT_BATCH_WINDOWS)
    assert all(np.array_equal(a, b) for a, b in zip(one, split))
