"""The daemon against faults, floods and forgery (docs/SECURITY.md's table), in process and seeded.

Each test re-runs one row of the table: a sink that fails, finite but
impossible values, a flood on one frozen timestamp, a frozen/stepping/
rebooting autopilot clock, lost streams. The forged-stream and udpin cases
over real loopback sockets are in ``test_fuzz_link.py``.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
from fuzz_helpers import decoded, feed, make_daemon, px4_stream
from pymavlink.dialects.v20 import common as mavlink
from test_daemon_helpers import toy_model

from monitor.daemon.config import MonitorConfig, PlausibleConfig
from monitor.daemon.events import EventWriter
from monitor.daemon.latency import LatencyHistogram
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.resampler import MAX_PENDING_SAMPLES
from monitor.esc import PAPER_ESC
from monitor.model import Classifier

WINDOW_S = 5.0  # 100 steps at 20 Hz


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return Classifier(toy_model(tmp_path_factory.mktemp("model") / "toy.onnx"))


# --- row 1: the events file fails ------------------------------------------------------


# The decision rule needs the analytic fault threshold's worth of evidence first (about 8 s of saturated
# windows for the toy model, after the first 5 s window): FAULT at 116 s.
FAULT_BY_S = 125.0


@pytest.mark.parametrize("path", ["/dev/full", "/dev/null/not-a-dir/events.jsonl"])
def test_an_unwritable_events_file_never_stops_or_delays_an_alert(toy, path):
    # the toy network is the only evidence here: let it raise FAULT (the default lets only the shares)
    daemon, link = make_daemon(toy, path, {"alerts": {"fault_evidence": "all"}})
    feed(daemon, px4_stream(100.0, FAULT_BY_S, faulty=(3,)))
    texts = link.statustexts()
    alerts = [t for t in texts if t[0].startswith("PROP 3 FAULT")]
    assert daemon.counters.alerts >= 1 and alerts, texts  # the ground station heard of the fault
    ev = daemon.events
    assert ev.failures >= 1 and ev.pending >= 1 and ev.written == 0
    # Reported in STATUS and to the ground station (once per minute, not per failure).
    assert any("events file failing" in s for s in daemon.notifier.statuses())
    assert [t for t in texts if t[0] == "PROPWATCH: events file write failing"] == [("PROPWATCH: events file write failing", 4)]
    assert daemon.report()["events_file"]["failures"] == ev.failures
    daemon.events.close()  # closing a failing sink must not raise either


def test_a_failed_events_write_is_kept_and_retried_until_the_disk_has_room(tmp_path):
    now = [0.0]
    w = EventWriter(tmp_path / "events.jsonl", retry_s=5.0, backlog=3, clock=lambda: now[0])

    class FullDisk:
        def write(self, _):
            raise OSError(28, "No space left on device")

        def flush(self):
            pass

        def close(self):
            raise OSError(28, "No space left on device")

    w._fh = FullDisk()
    for i in range(5):
        assert w.write_record({"n": i}) is False
    assert w.failing and w.pending == 3 and w.dropped == 2  # bounded backlog, the oldest counted as lost
    assert "No space" in w.last_error
    now[0] = 4.0
    assert w.retry() is False  # not yet: one try per retry period, no busy loop on a full disk
    now[0] = 6.0
    assert w.retry() is True and not w.failing
    lines = [json.loads(x) for x in (tmp_path / "events.jsonl").read_text().splitlines()]
    assert lines == [{"n": 2}, {"n": 3}, {"n": 4}]


# --- row 2: finite but impossible values -----------------------------------------------


def _bad_attitude(t):
    if 104.0 <= t < 106.0:
        return (1e30, 0.0, 0.3, 0.0, 0.0, 0.0)
    return (0.02 * math.sin(t), 0.01, 0.3, 0.001 * math.sin(7 * t), 0.001, 0.001 * math.cos(5 * t))


@pytest.mark.parametrize(
    "case",
    ["roll 1e30 rad", "pwm 1 us", "pwm 65534 us", "rate 1e6 rad/s", "frozen pwm"],
)
def test_impossible_values_are_never_evidence(toy, case):
    seed = 3

    def pwm(t):
        base = [HOVER + int(3 * math.sin(11 * t + i)) for i, HOVER in enumerate((1450, 1452, 1449, 1451))]
        if 104.0 <= t < 106.0:
            if case == "pwm 1 us":
                base[1] = base[2] = 1
            elif case == "pwm 65534 us":
                base[1] = base[2] = 65534
            elif case == "frozen pwm":
                return [1500, 1600, 1600, 1500]
        return base

    def att(t):
        if case == "roll 1e30 rad":
            return _bad_attitude(t)
        r = 1e6 if case == "rate 1e6 rad/s" and 104.0 <= t < 106.0 else 0.001 * math.sin(7 * t)
        return (0.02 * math.sin(t), 0.01, 0.3, r, 0.001, 0.001 * math.cos(5 * t))

    daemon, link = make_daemon(toy, None, {"blind": {"after_s": 0.0, "notice_min_interval_s": 0.0}})
    steps = feed(daemon, px4_stream(100.0, 118.0, seed=seed, attitude=att, pwm=pwm))
    classified = [s for s in steps if s.fault_probability is not None]
    bad_from_s = 104.0 + (1.0 if case == "frozen pwm" else 0.0)  # frozen only after plausible.frozen_s
    # No window holds an implausible sample: a window ending at T holds the grid instants
    # [T - 4.95 s, T]; a sample is held at the instants up to the next one (< 40 ms later).
    assert not [s for s in classified if bad_from_s <= s.timestamp_us / 1e6 and s.timestamp_us / 1e6 - 4.95 < 106.0]
    assert classified, "the good parts of the flight are still classified"
    assert daemon.counters.alerts == 0 and not [t for t in link.statustexts() if t[0].startswith("PROP ")]
    assert daemon.pipeline.stats["implausible_samples"] > 0 and daemon.report()["implausible"]
    reasons = {s.reason for s in steps if not s.valid and s.airborne}
    assert any("implausible" in r for r in reasons), reasons
    # ... and the ground station is told the monitor is blind, then that it sees again.
    notices = [t for t, sev in link.statustexts() if sev == 5]
    assert any(n.startswith("PROPWATCH BLIND: implausible") for n in notices), notices
    assert "PROPWATCH OK: monitoring again" in notices
    assert all(len(n) <= 50 for n in notices)


def test_a_stream_that_stays_implausible_pauses_classification_with_a_reason(toy):
    daemon, link = make_daemon(toy, None)
    steps = feed(daemon, px4_stream(100.0, 110.0, pwm=lambda t: [1, 65534, 1, 65534]))
    assert daemon.pipeline.stats["classified"] == 0 and daemon.counters.alerts == 0
    assert any("motor implausible: motor command outside [1000, 2000]" in s.reason for s in steps)
    assert any("implausible" in s for s in daemon.notifier.statuses())


def test_seeded_random_extremes_never_reach_a_classified_window(toy):
    """Random finite extremes sprinkled over a flight: every classified window is clean."""
    rng = np.random.default_rng(15)
    bad_times = sorted(rng.uniform(101.0, 119.0, 6))
    impossible_angle = [1e30, -1e30, 7.0, -4.0, 3.3e38]  # beyond +-pi (pitch: +-pi/2)
    impossible_rate = [1e30, -1e9, 40.0, 3.3e38]  # beyond the 35 rad/s gyro range
    injected: list[float] = []

    def att(t):
        base = [0.02 * math.sin(t), 0.01, 0.3, 0.001 * math.sin(7 * t), 0.001, 0.001 * math.cos(5 * t)]
        for bt in bad_times:
            if abs(t - bt) < 0.011:
                i = int(rng.integers(0, 6))
                base[i] = float(rng.choice(impossible_angle if i < 3 else impossible_rate))
                injected.append(t)
        return tuple(base)

    daemon, _ = make_daemon(toy, None)
    steps = feed(daemon, px4_stream(100.0, 122.0, attitude=att))
    dropped = daemon.pipeline.stats["implausible_samples"]
    assert dropped >= 1
    for s in steps:
        if s.fault_probability is None:
            continue
        t = s.timestamp_us / 1e6  # a window ending at t spans the boot times (t - 5 s, t]
        assert not [b for b in injected if t - WINDOW_S < b <= t], (t, injected)


# --- row 4: a flood on one timestamp ---------------------------------------------------


def test_a_flood_on_one_frozen_timestamp_keeps_every_buffer_bounded(toy):
    pipe = Pipeline(toy, MonitorConfig(), PAPER_ESC)
    for m in px4_stream(100.0, 101.0):
        pipe.feed(m)
    att = decoded(mavlink.MAVLink_attitude_message(101_000, 0.01, 0.01, 0.3, 0.0, 0.0, 0.0))
    srv = decoded(mavlink.MAVLink_servo_output_raw_message(101_000_000, 0, 1450, 1450, 1450, 1450, 0, 0, 0, 0))
    for _ in range(10_000):
        pipe.feed(att)
        pipe.feed(srv)
    sizes = {k: len(s.times) for k, s in pipe.hold._streams.items()}
    assert max(sizes.values()) <= 8, sizes  # one sample per distinct time, not one per message
    # Times that keep arriving out of order on a stalled grid still stop at the hard cap.
    for i in range(MAX_PENDING_SAMPLES + 500):
        pipe.hold.push("battery", 101_000_000 - 1 - (i % 7919), (15.0,))
    assert len(pipe.hold._streams["battery"].times) <= MAX_PENDING_SAMPLES


def test_latency_record_is_a_fixed_histogram_with_honest_percentiles():
    rng = np.random.default_rng(0)
    h = LatencyHistogram()
    size = h.counts.nbytes
    x = rng.lognormal(np.log(2e-3), 0.6, 50_000)
    for v in x:
        h.add(float(v))
    assert h.counts.nbytes == size and h.n == len(x)
    for q in (50, 99):
        exact = float(np.percentile(x, q))
        assert exact <= h.percentile_s(q) <= exact * 1.03  # an upper bound, within one 2.3 % bin
    assert h.max_s == pytest.approx(x.max())


# --- row 5: say when blind -------------------------------------------------------------

# Events seen at once (frozen clock, clock step, reboot) do not wait for after_s; a long after_s
# keeps a busy test machine's scheduling pauses from adding "no data" spells to these tests.
BLIND_FAST = {
    "blind": {"after_s": 5.0, "frozen_clock_s": 0.1, "notice_min_interval_s": 0.0},
}


def _events(path):
    return [json.loads(x) for x in path.read_text().splitlines()]


def test_frozen_clock_is_blind_in_status_events_and_notice_then_recovers(toy, tmp_path):
    daemon, link = make_daemon(toy, tmp_path / "ev.jsonl", BLIND_FAST)
    feed(daemon, px4_stream(100.0, 108.0))
    assert daemon.pipeline.stats["classified"] > 0 and not daemon.blind.blind
    frozen = [
        decoded(mavlink.MAVLink_attitude_message(108_000, 0.01, 0.01, 0.3, 0.0, 0.0, 0.0)),
        decoded(mavlink.MAVLink_servo_output_raw_message(108_000_000, 0, 1450, 1451, 1449, 1450, 0, 0, 0, 0)),
    ]
    end = time.monotonic() + 0.4
    while time.monotonic() < end:  # messages keep coming; the autopilot's clock stands still
        for m in frozen:
            daemon.handle(m, time.perf_counter())
        daemon.tick(time.monotonic())
        time.sleep(0.01)
    assert daemon.blind.reason == "autopilot clock frozen"
    assert daemon.notifier.statuses()[-1].startswith("BLIND: autopilot clock frozen")
    assert "airborne: classifying" not in daemon.notifier.statuses()[-1]
    feed(daemon, px4_stream(108.02, 111.0, seed=1))
    assert not daemon.blind.blind
    texts = [t for t, sev in link.statustexts() if sev == 5]
    assert texts[-2:] == ["PROPWATCH BLIND: autopilot clock frozen", "PROPWATCH OK: monitoring again"]
    ev = _events(tmp_path / "ev.jsonl")
    assert [e["event"] for e in ev] == ["blind", "recovered"] and ev[0]["reason"] == "autopilot clock frozen"


def test_blind_pauses_the_sequential_decision_and_says_why(toy, tmp_path):
    # The default rule: a blind spell pauses the decision (nothing added, nothing frozen into an alert),
    # STATUS and the events line say so, and it runs again when the monitor sees again.
    cfg = {**BLIND_FAST, "alerts": {"rule": "sequential"}}
    daemon, link = make_daemon(toy, tmp_path / "ev.jsonl", cfg)
    feed(daemon, px4_stream(100.0, 108.0))
    assert daemon.pipeline.stats["classified"] > 0 and daemon.decision.paused_reason == ""
    frozen = [
        decoded(mavlink.MAVLink_attitude_message(108_000, 0.01, 0.01, 0.3, 0.0, 0.0, 0.0)),
        decoded(mavlink.MAVLink_servo_output_raw_message(108_000_000, 0, 1450, 1451, 1449, 1450, 0, 0, 0, 0)),
    ]
    end = time.monotonic() + 0.4
    while time.monotonic() < end:
        for m in frozen:
            daemon.handle(m, time.perf_counter())
        daemon.tick(time.monotonic())
        time.sleep(0.01)
    assert daemon.decision.paused_reason == "blind: autopilot clock frozen"
    status = daemon.notifier.statuses()[-1]
    assert status.startswith("BLIND: autopilot clock frozen") and "decision paused" in status, status
    feed(daemon, px4_stream(108.02, 111.0, seed=1))
    assert not daemon.blind.blind and daemon.decision.paused_reason == ""
    assert daemon.notifier.statuses()[-1].startswith("airborne: deciding")
    ev = _events(tmp_path / "ev.jsonl")
    blind = [(e["event"], e.get("decision")) for e in ev if e["event"] in ("blind", "recovered")]
    assert blind == [("blind", "paused"), ("recovered", "running")], ev


def test_a_lost_motor_stream_pauses_the_sequential_decision_until_it_returns(toy, tmp_path):
    cfg = {"alerts": {"rule": "sequential"}, "blind": {"after_s": 0.0}}
    daemon, link = make_daemon(toy, tmp_path / "ev.jsonl", cfg)
    feed(daemon, px4_stream(100.0, 107.0))
    feed(daemon, [m for m in px4_stream(107.0, 110.0) if m.get_type() != "SERVO_OUTPUT_RAW"])
    assert daemon.blind.reason == "no motor data" and daemon.decision.paused_reason == "blind: no motor data"
    held = daemon.decision.windows
    feed(daemon, px4_stream(110.0, 116.0))  # a new 5-s window fills, then is classified
    assert not daemon.blind.blind and daemon.decision.paused_reason == ""
    assert daemon.decision.windows > held  # evidence flows again
    ev = [(e["event"], e.get("decision")) for e in _events(tmp_path / "ev.jsonl")]
    # Both the step's reason and blind are recorded. Which comes first depends on the wall clock the loop ticks blind
    # with (after_s 0): in a full test run blind came first, in this file alone the step's reason.
    assert ("paused", None) in ev and ("blind", "paused") in ev, ev
    assert ev[-2:] == [("resumed", None), ("recovered", "running")], ev


def test_flapping_data_pauses_the_decision_at_every_step_but_is_written_at_most_once_per_period(toy, tmp_path):
    from monitor.daemon.alerts import RateLimiter
    from monitor.daemon.announce import PAUSE_LOG_PERIOD_S
    from monitor.daemon.pipeline import StepResult

    cfg = {"alerts": {"rule": "sequential"}, "blind": {"after_s": 60.0}}
    daemon, _ = make_daemon(toy, tmp_path / "ev.jsonl", cfg)
    now = [0.0]
    daemon.announce.pause_log_limit = RateLimiter(PAUSE_LOG_PERIOD_S, lambda: now[0])
    why = "motor missing, stale or NaN"

    def step(k, valid):
        return StepResult(100_000_000 + 50_000 * k, True, valid, 50 if valid else 0, 16.0, reason="" if valid else why)

    for k in range(200):  # NaN every other step, all within one period of the limit
        daemon._on_step(step(k, k % 2 == 1))
        assert daemon.decision.paused_reason == ("" if k % 2 else why)  # the decision itself follows every step
    lines = [e["event"] for e in _events(tmp_path / "ev.jsonl")]
    assert lines == ["paused", "resumed"], lines  # not 100 of each
    daemon._on_step(step(200, False))  # the motor stream now stays away: held back by the limit ...
    now[0] = PAUSE_LOG_PERIOD_S + 0.1
    daemon._on_step(step(201, False))  # ... and written at the next step once the period is over
    ev = _events(tmp_path / "ev.jsonl")
    assert [e["event"] for e in ev] == ["paused", "resumed", "paused"] and ev[-1]["reason"] == why


@pytest.mark.parametrize(
    "case,restart_s,reason",
    [("step back 5 s", 103.0, "clock stepped back"), ("reboot", 2.0, "autopilot rebooted")],
)
def test_clock_step_back_and_reboot_are_reported_and_recover(toy, tmp_path, case, restart_s, reason):
    daemon, link = make_daemon(toy, tmp_path / "ev.jsonl", BLIND_FAST)
    feed(daemon, px4_stream(100.0, 108.0))
    before = daemon.pipeline.stats["classified"]
    feed(daemon, px4_stream(restart_s, restart_s + 7.0, seed=2))
    notices = [t for t, sev in link.statustexts() if sev == 5]
    assert f"PROPWATCH BLIND: {reason}" in notices and notices[-1] == "PROPWATCH OK: monitoring again"
    ev = _events(tmp_path / "ev.jsonl")
    assert ev[0]["event"] == "blind" and ev[0]["reason"] == reason and ev[-1]["event"] == "recovered"
    assert any(
        s.startswith(f"BLIND: {'autopilot clock stepped back' if 'step' in case else 'autopilot rebooted'}")
        for s in daemon.notifier.statuses()
    )
    assert daemon.pipeline.stats["classified"] > before  # it classifies again on the new clock


def test_a_lost_motor_stream_is_blind_while_armed(toy, tmp_path):
    daemon, link = make_daemon(toy, tmp_path / "ev.jsonl", {"blind": {"after_s": 0.0}})
    feed(daemon, px4_stream(100.0, 107.0))
    only_attitude = [m for m in px4_stream(107.0, 110.0) if m.get_type() != "SERVO_OUTPUT_RAW"]
    feed(daemon, only_attitude)
    assert daemon.blind.reason == "no motor data"
    assert "PROPWATCH BLIND: no motor data" in [t for t, _ in link.statustexts()]
    feed(daemon, px4_stream(110.0, 112.0))
    assert not daemon.blind.blind


def test_blind_notices_are_rate_limited(toy):
    daemon, link = make_daemon(toy, None, {"blind": {"after_s": 0.0, "notice_min_interval_s": 60.0}})
    feed(daemon, px4_stream(100.0, 104.0))
    for k in range(5):  # five reboots in a row within a minute
        feed(daemon, px4_stream(1.0 + k * 0.0, 3.0, seed=k))
        feed(daemon, px4_stream(100.0 + 10 * k, 102.0 + 10 * k, seed=k))
    notices = [t for t, sev in link.statustexts() if sev == 5]
    assert len(notices) == 1 and daemon.blind.spells >= 5


def test_plausible_config_bounds():
    with pytest.raises(Exception, match="plausible.pwm_max_us"):
        PlausibleConfig(pwm_min_us=1000.0, pwm_max_us=900.0)


def test_an_autopilot_heard_long_after_start_up_is_not_a_frozen_clock(toy, tmp_path):
    """The monitor waits for its autopilot (here longer than ``frozen_clock_s``): the autopilot's first messages, whose
    clock is being confirmed, are no clock standing still (the try-out started the replay after the monitor, and the
    ground station read "BLIND: autopilot clock frozen")."""
    daemon, link = make_daemon(toy, tmp_path / "ev.jsonl", BLIND_FAST)
    time.sleep(0.3)  # three frozen_clock_s with nothing from the autopilot
    feed(daemon, px4_stream(100.0, 104.0), tick_every=1)
    assert daemon.blind.spells == 0 and not any(t.startswith("PROPWATCH BLIND") for t, _ in link.statustexts())
    time.sleep(0.3)  # the autopilot falls silent, then speaks again: its clock moves on
    feed(daemon, px4_stream(104.02, 106.0), tick_every=1)
    assert daemon.blind.spells == 0, daemon.notifier.statuses()
