"""The daemon's velocity: LOCAL_POSITION_NED on the 20 Hz grid, turned into the heading frame for StepInputs.

Optional context, never a reason to pause: missing, stale, NaN, absurd or frozen velocity gives
``vel_heading_m_s=None`` (bad samples counted), and the classifier's steps stay exactly as without it.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from fuzz_helpers import decoded, make_daemon
from pymavlink.dialects.v20 import common as mavlink
from test_daemon_helpers import synth_flight, toy_model
from test_daemon_pipeline import parse_all, run_pipeline

from monitor.daemon.resampler import StreamingHold, StreamSpec
from monitor.model import Classifier
from monitor.resample import hold

BOOT0_S = 100.0  # synth_flight's boot time at flight time 0
LOCAL_POSITION_NED_ID = 32


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return Classifier(toy_model(tmp_path_factory.mktemp("model") / "toy.onnx"))


def flight_s(step) -> float:
    return step.timestamp_us / 1e6 - BOOT0_S


def classifier_view(steps):
    return [
        (s.timestamp_us, s.valid, s.reason, None if s.fault_probability is None else s.fault_probability.tolist()) for s in steps
    ]


def test_a_stream_that_does_not_move_the_clock_is_held_as_in_batch_and_changes_no_instant():
    rng = np.random.default_rng(0)
    period, age = 50_000, 250_000
    t_a = np.arange(2_000_000, 12_000_000, 20_000)  # 50 Hz pacing stream
    t_a = t_a + rng.integers(0, 2_000, len(t_a))
    t_v = np.arange(1_500_000, 12_000_000, 33_333)  # 30 Hz, starts 0.5 s earlier
    t_v = t_v + rng.integers(0, 2_000, len(t_v))
    t_v = t_v[(t_v < 6_000_000) | (t_v > 6_600_000)]  # and stops for 0.6 s
    v = rng.normal(size=(len(t_v), 2))
    arrival = sorted([(int(t), "a", [float(t)]) for t in t_a] + [(int(t), "v", x) for t, x in zip(t_v, v)])
    specs = {"a": StreamSpec(1, age, True)}
    alone = StreamingHold(period, specs)
    both = StreamingHold(period, {**specs, "v": StreamSpec(2, age, False, moves_clock=False)})
    steps_alone, steps = [], []
    for t, name, x in arrival:
        if name == "a":
            steps_alone += alone.push(name, t, x)
        steps += both.push(name, t, x)
    steps_alone, steps = steps_alone + alone.flush(), steps + both.flush()
    grid = np.array([s.timestamp_us for s in steps])
    assert grid.tolist() == [s.timestamp_us for s in steps_alone] and grid[0] >= 2_000_000  # v never starts the grid
    held = np.array([s.values["v"] for s in steps])
    np.testing.assert_array_equal(held, hold(t_v, v, grid, age))  # NaN where equal too (the gap)
    assert np.isnan(held[:, 0]).sum() >= 6 and both.late == 0
    # Alone (no grid running) it never emits, never starts a clock, and stays bounded: nothing overflows.
    lone = StreamingHold(period, {**specs, "v": StreamSpec(2, age, False, moves_clock=False)})
    assert not any(lone.push("v", 1_000_000 + 33_333 * k, [k, k]) for k in range(5_000))
    assert lone.next_g is None and lone.clock_us is None and lone.overflow == 0


@pytest.mark.parametrize(
    ("vel_ned", "expected_fwd_right"),
    [((0.0, 5.0), (5.0, 0.0)), ((5.0, 0.0), (0.0, -5.0))],  # heading east: east is forward, north is left
    ids=["east-is-forward", "north-is-left"],
)
def test_local_position_becomes_each_steps_heading_frame_velocity(toy, vel_ned, expected_fwd_right):
    vn, ve = vel_ned

    def vel(t):  # +-2 cm/s wobble: a real estimate never repeats bit for bit (that would be a frozen channel)
        w = 0.02 * math.sin(3.0 * t)
        return (vn + w, ve + w, 0.1)

    frames = synth_flight(8.0, seed=11, pos_hz=30.0, vel_of_t=vel, yaw_of_t=lambda t: math.pi / 2)
    p, steps = run_pipeline(toy, parse_all(frames))
    later = [s for s in steps if flight_s(s) >= 0.5]
    assert len(later) > 140 and all(s.inputs.vel_heading_m_s is not None for s in later)
    v = np.array([s.inputs.vel_heading_m_s for s in later])
    assert v.shape == (len(later), 2)
    np.testing.assert_allclose(v, np.broadcast_to(expected_fwd_right, v.shape), atol=0.03)
    assert p.stats["velocity_steps"] >= len(later)
    assert not [k for k in p.plausible.dropped if k.startswith("velocity")]


def check_context_is_optional(toy, field: str, least_steps: int, **stream):
    """Without the context ``stream`` (synth_flight keywords) every ``StepInputs.<field>`` is None; with it at least
    ``least_steps`` carry one and the classifier's steps are the same. Returns the pipeline that had it."""
    _, plain = run_pipeline(toy, parse_all(synth_flight(9.0, faulty=(2,), seed=3)))
    p, with_it = run_pipeline(toy, parse_all(synth_flight(9.0, faulty=(2,), seed=3, **stream)))
    assert plain and all(getattr(s.inputs, field) is None for s in plain)
    assert sum(getattr(s.inputs, field) is not None for s in with_it) > least_steps
    assert classifier_view(with_it) == classifier_view(plain)  # same grid, same windows, same probabilities
    assert any(s.fault_probability is not None for s in plain)
    assert p.hold.late == 0
    return p


def test_without_local_position_velocity_is_none_and_the_classifier_steps_are_the_same(toy):
    check_context_is_optional(toy, "vel_heading_m_s", 150, pos_hz=30.0)


def run_bad_context_flight(toy, field: str, **stream):
    """The flight of the NaN / absurd / frozen tests (here and ``test_daemon_imu``): the context ``stream`` (synth_flight
    keywords) is NaN 3-5 s into it, absurd 5-7 s, bit-identical 7-10 s (frozen after plausible.frozen_s, 1 s), good
    otherwise. Checks which steps carry ``StepInputs.<field>`` and that the classifier's steps are those of the
    flight without the stream; returns the pipeline for its counts."""
    flight = dict(duration_s=13.0, faulty=(3,), seed=4)
    _, plain = run_pipeline(toy, parse_all(synth_flight(**flight)))
    p, steps = run_pipeline(toy, parse_all(synth_flight(**flight, **stream)))

    def has(a, b):
        return {getattr(s.inputs, field) is not None for s in steps if a <= flight_s(s) < b}

    assert has(0.5, 3.0) == {True}
    assert has(3.3, 5.0) == {False}  # NaN
    assert has(5.3, 7.0) == {False}  # absurd
    assert has(7.3, 7.9) == {True}  # not frozen yet
    assert has(8.3, 10.0) == {False}  # frozen
    assert has(10.3, 13.0) == {True}  # moving again
    # Never evidence, and never a reason to stop the classifier: its steps are those of the flight without the stream.
    assert p.stats["implausible_samples"] == 0 and not p.plausible.last
    assert classifier_view(steps) == classifier_view(plain)
    return p


def bad_velocity(t):
    """The bad-context flight's velocity (``run_bad_context_flight``'s spans): NaN, absurd, stuck, good."""
    if 3.0 <= t < 5.0:
        return (math.nan, math.nan, math.nan)
    if 5.0 <= t < 7.0:
        return (80.0, 0.5 * math.sin(t), 0.0)  # 80 m/s: a diverged estimate
    if 7.0 <= t < 10.0:
        return (1.0, 2.0, 0.0)  # stuck: bit-identical from 7 s, frozen after plausible.frozen_s (1 s)
    return (1.0 + 0.3 * math.sin(t), 2.0, 0.0)


def test_nan_absurd_and_frozen_velocity_is_ignored_and_counted_never_a_pause(toy):
    p = run_bad_context_flight(toy, "vel_heading_m_s", pos_hz=30.0, vel_of_t=bad_velocity)
    dropped = p.plausible.dropped
    assert dropped["velocity: not finite"] >= 55 and dropped["velocity: beyond 60 m/s"] >= 55, dropped
    assert dropped["velocity: frozen"] >= 55, dropped


def run_daemon(toy, msgs, field: str):
    """The daemon (decision rule) over ``msgs``; returns it and (flight time s, StepInputs.<field>) of each step."""
    d, _ = make_daemon(toy)
    seen = []
    real_step = d.decision.step
    d.decision.step = lambda t, inputs: (seen.append((t - BOOT0_S, getattr(inputs, field))), real_step(t, inputs))[1]
    for m in msgs:
        d.handle(m, time.perf_counter())
    return d, seen


def test_status_says_whether_velocity_is_live_and_a_stopped_stream_gives_none(toy):
    msgs = parse_all(synth_flight(16.0, seed=7, pos_hz=30.0))
    stop_ms = (BOOT0_S + 8.0) * 1000  # LOCAL_POSITION_NED stops 8 s into the flight, the rest flows on
    msgs = [m for m in msgs if not (m.get_type() == "LOCAL_POSITION_NED" and m.time_boot_ms > stop_ms)]
    d, seen = run_daemon(toy, msgs, "vel_heading_m_s")
    statuses = [s.split("; shares learning")[0] for s in d.notifier.statuses()]  # learning: its own test
    # Context, not evidence of a fault: listed apart.
    assert "airborne: deciding; evidence live: classifier, esc_rpm; context live: velocity" in statuses, statuses
    assert statuses[-1] == "airborne: deciding; evidence live: classifier, esc_rpm", statuses  # 2 s after it stopped
    assert not [s for s in statuses if "paused" in s or "BLIND" in s], statuses
    assert all(v is not None for t, v in seen if 0.5 <= t <= 8.0)
    assert all(v is None for t, v in seen if t >= 8.3)  # stale after resample.max_gap_s (0.25 s)
    assert d.report()["pipeline"]["velocity_steps"] > 140


def test_status_says_while_the_shares_learn_their_baseline_and_stops_once_learnt(toy):
    # The first 10 s of evidence windows after take-off (the first window ends 5 s in) teach the shares the
    # flight's baseline: no FAULT can come from them yet, and STATUS says so, once per second learnt, not per step.
    d, _ = run_daemon(toy, parse_all(synth_flight(24.0, seed=7, pos_hz=30.0)), "vel_heading_m_s")
    statuses = d.notifier.statuses()
    learning = [s for s in statuses if "; shares learning baseline (" in s]
    assert learning and learning[0].endswith("; shares learning baseline (0 of 10 s)"), statuses
    assert any(s.endswith("(9 of 10 s)") for s in learning), learning
    assert len({s.rsplit("(", 1)[1] for s in learning}) == 10 and len(learning) <= 20, learning
    assert statuses[-1].startswith("airborne: deciding") and "learning" not in statuses[-1], statuses
    assert d.decision.share.learning_s is None and d.decision.verdict()["tested_s"] > 0


def requested_rates(toy) -> dict[int, float]:
    """Message id -> rate (Hz) the daemon asks of the autopilot once it hears its heartbeat."""
    d, link = make_daemon(toy)
    d.handle(decoded(mavlink.MAVLink_heartbeat_message(2, 12, 128 | 1, 0, 4, 3)), time.perf_counter())
    d.tick(time.monotonic())
    return {s[3]: s[4] for s in link.sent if s[0] == "COMMAND_LONG"}


def test_local_position_ned_is_requested_beside_attitude_for_the_decision(toy):
    rates = requested_rates(toy)
    assert rates[30] >= 20.0  # ATTITUDE, as before
    assert rates[LOCAL_POSITION_NED_ID] == 30.0  # PX4's onboard-link rate, >= the 20 Hz grid
