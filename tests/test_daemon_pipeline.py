"""The daemon's streaming core: decoding, streaming hold == batch hold, pipeline parity, STATUSTEXT queue, config."""

from __future__ import annotations

import math
import socket
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink
from test_daemon_helpers import synth_flight, toy_model

from monitor.daemon.alerts import RateLimiter, StatusTextQueue
from monitor.daemon.config import MonitorConfig, load_monitor_config, monitor_config_from_mapping
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.resampler import StreamingHold, StreamSpec
from monitor.daemon.sdnotify import Notifier
from monitor.errors import ConfigError, ModelError
from monitor.esc import PAPER_ESC
from monitor.features import compute_features, sliding_windows
from monitor.mavlink import decode as md
from monitor.model import Classifier
from monitor.resample import hold


def parse_all(frames, chunk_sizes=None, seed=0):
    """Frames -> pymavlink messages through one parser, optionally fed in random-size chunks."""
    p = mavlink.MAVLink(None)
    p.robust_parsing = True
    data = b"".join(f for _, f in frames)
    if chunk_sizes is None:
        return [m for m in (p.parse_buffer(data) or []) if m.get_type() != "BAD_DATA"]
    rng = np.random.default_rng(seed)
    out, i = [], 0
    while i < len(data):
        n = int(rng.integers(*chunk_sizes))
        out += p.parse_buffer(data[i : i + n]) or []
        i += n
    return [m for m in out if m.get_type() != "BAD_DATA"]


def msg(m, sys_id=1, comp=1):
    mav = mavlink.MAVLink(None, srcSystem=sys_id, srcComponent=comp)
    return mavlink.MAVLink(None).decode(bytearray(m.pack(mav)))


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return Classifier(toy_model(tmp_path_factory.mktemp("model") / "toy.onnx"))


# --- decoding ------------------------------------------------------------------------


def test_servo_time_unwraps_across_the_32_bit_wrap():
    d = md.MavlinkDecoder()
    d.decode(msg(mavlink.MAVLink_heartbeat_message(2, 12, 128, 0, 4, 3)))
    wrap = 1 << 32
    t_before = wrap - 20_000  # 71.58 min after boot
    d.decode(msg(mavlink.MAVLink_attitude_message(t_before // 1000, 0, 0, 0, 0, 0, 0)))
    a = d.decode(msg(mavlink.MAVLink_servo_output_raw_message(t_before & 0xFFFFFFFF, 0, *[1500] * 8)))
    b = d.decode(msg(mavlink.MAVLink_servo_output_raw_message((wrap + 30_000) & 0xFFFFFFFF, 0, *[1500] * 8)))
    assert a[0].timestamp_us == t_before
    assert b[0].timestamp_us == wrap + 30_000  # 30 ms later, not 71 minutes earlier
    assert not any(isinstance(s, md.ClockReset) for s in a + b)


def test_other_systems_and_components_are_ignored_and_counted():
    d = md.MavlinkDecoder()
    assert d.decode(msg(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3), 255, 190)) == []  # GCS
    hb = d.decode(msg(mavlink.MAVLink_heartbeat_message(2, 12, 128 | 1, 0, 4, 3), 7, 1))
    assert d.system_id == 7 and hb[0].armed
    assert d.decode(msg(mavlink.MAVLink_attitude_message(1000, 0.1, 0, 0, 0, 0, 0), 8, 1)) == []  # another vehicle
    assert d.decode(msg(mavlink.MAVLink_attitude_message(1000, 0.1, 0, 0, 0, 0, 0), 7, 100)) == []  # a camera
    assert len(d.decode(msg(mavlink.MAVLink_attitude_message(1000, 0.1, 0, 0, 0, 0, 0), 7, 1))) == 1
    assert d.ignored[(255, 190)] == 1 and d.ignored[(8, 1)] == 1 and d.ignored[(7, 100)] == 1


def test_battery_voltage_and_unknown_values():
    d = md.MavlinkDecoder(system_id=1)
    cells = [4100, 4000, 4050, 3950] + [65535] * 6
    (b,) = d.decode(msg(mavlink.MAVLink_battery_status_message(0, 0, 0, 0, cells, 0, 0, 0, 80)))
    assert b.voltage_v == pytest.approx(16.1)
    (s,) = d.decode(msg(mavlink.MAVLink_sys_status_message(0, 0, 0, 0, 65535, 0, 0, 0, 0, 0, 0, 0, 0)))
    assert math.isnan(s.voltage_v)  # unknown stays unknown
    assert d.decode(msg(mavlink.MAVLink_battery_status_message(1, 0, 0, 0, cells, 0, 0, 0, 80))) == []  # other battery
    (o,) = d.decode(msg(mavlink.MAVLink_servo_output_raw_message(1000, 0, 1500, 0, 65535, 1600, 0, 0, 0, 0)))
    assert o.values_us[0] == 1500 and math.isnan(o.values_us[1]) and math.isnan(o.values_us[2])


def test_reboot_emits_a_clock_reset():
    d = md.MavlinkDecoder(system_id=1)
    d.decode(msg(mavlink.MAVLink_attitude_message(600_000, 0, 0, 0, 0, 0, 0)))
    out = d.decode(msg(mavlink.MAVLink_attitude_message(2_000, 0, 0, 0, 0, 0, 0)))
    assert isinstance(out[0], md.ClockReset) and out[1].timestamp_us == 2_000_000


# --- streaming hold == batch hold ------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_streaming_hold_equals_batch_hold(seed):
    rng = np.random.default_rng(seed)
    period, age = 50_000, 120_000
    specs = {"a": StreamSpec(2, age, True), "b": StreamSpec(1, age, True), "s": StreamSpec(1, 3_000_000, False)}
    samples = []
    for name, rate, width in (("a", 50, 2), ("b", 23, 1), ("s", 1, 1)):
        t = np.sort(rng.uniform(1e6, 21e6, int(20 * rate))).astype(np.int64)
        t = t[(t < 8e6) | (t > 8.5e6)] if name == "b" else t  # a gap longer than max age
        for ti in t:
            samples.append((int(ti), name, rng.normal(size=width)))
        samples += [(int(t[5]), name, rng.normal(size=width))]  # a duplicate time, written later
    # Arrival order: by time, streams interleaved, stream b 40 ms behind a (as SERVO_OUTPUT_RAW may lag ATTITUDE).
    arrival = sorted(range(len(samples)), key=lambda i: samples[i][0] + (40_000 if samples[i][1] == "b" else 0))
    sh = StreamingHold(period, specs)
    steps = []
    for i in arrival:
        t, name, v = samples[i]
        steps += sh.push(name, t, v)
    steps += sh.flush()
    assert sh.late == 0 and len(steps) > 300
    grid = np.array([s.timestamp_us for s in steps])
    assert np.all(np.diff(grid) == period) and grid[0] % period == 0
    for name in specs:
        # batch: the same samples, stably sorted by time (arrival order kept among equal times)
        idx = sorted((i for i in arrival if samples[i][1] == name), key=lambda i: samples[i][0])
        t = np.array([samples[i][0] for i in idx])
        v = np.array([samples[i][2] for i in idx])
        batch = hold(t, v, grid, specs[name].max_age_us)
        stream = np.array([s.values[name] for s in steps])
        np.testing.assert_array_equal(np.isnan(stream), np.isnan(batch))
        np.testing.assert_array_equal(np.nan_to_num(stream), np.nan_to_num(batch))
    b_nan = np.isnan(np.array([s.values["b"][0] for s in steps]))
    assert b_nan.any()  # the gap shows as NaN: nothing invented


def test_reordering_within_a_stream_is_exact_inside_the_reorder_window():
    sh = StreamingHold(50_000, {"a": StreamSpec(1, 200_000, True)}, reorder_us=60_000)
    out = []
    for t in (0, 40_000, 90_000, 70_000, 110_000, 160_000, 230_000):  # 70 ms arrives after 90 ms
        out += sh.push("a", t, [t])
    out += sh.flush()
    vals = {s.timestamp_us: s.values["a"][0] for s in out}
    assert vals[50_000] == 40_000 and vals[100_000] == 90_000 and vals[200_000] == 160_000 and sh.late == 0


# --- the pipeline ------------------------------------------------------------------------


def run_pipeline(clf, msgs, cfg=None):
    p = Pipeline(clf, cfg or MonitorConfig(), PAPER_ESC)
    steps = []
    for m in msgs:
        steps += p.feed(m)
    return p, steps + p.flush()


def test_pipeline_equals_the_batch_path_on_the_same_messages(toy):
    """hold() over the decoded samples + features + sliding windows gives the per-step probabilities."""
    frames = synth_flight(12.0, faulty=(2,), seed=3)
    msgs = parse_all(frames)
    p, steps = run_pipeline(toy, msgs)
    classified = [s for s in steps if s.fault_probability is not None]
    assert len(classified) > 50
    # batch path
    d = md.MavlinkDecoder()
    att, mot, arm, land = [], [], [], []
    for m in msgs:
        for s in d.decode(m):
            if isinstance(s, md.Attitude):
                att.append(
                    (
                        s.timestamp_us,
                        [s.roll_rad, s.pitch_rad, s.yaw_rad, s.roll_rate_rad_s, s.pitch_rate_rad_s, s.yaw_rate_rad_s],
                    )
                )
            elif isinstance(s, md.ActuatorOutputs):
                mot.append((s.timestamp_us, PAPER_ESC.cmd_to_rpm(np.array(s.values_us[:4]))))
            elif isinstance(s, md.Heartbeat) and s.timestamp_us is not None:
                arm.append((s.timestamp_us, [float(s.armed)]))
            elif isinstance(s, md.LandedState) and s.timestamp_us is not None:
                land.append((s.timestamp_us, [float(s.landed_state)]))

    def held(rows, age):
        rows = sorted(rows, key=lambda r: r[0])
        return hold(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]), grid, age)

    grid = np.array([s.timestamp_us for s in steps])
    a, r = held(att, 250_000), held(mot, 250_000)
    airborne = (held(arm, 3_000_000)[:, 0] == 1) & (held(land, 3_000_000)[:, 0] == md.MAV_LANDED_STATE_IN_AIR)
    sig = {
        "motor_rpm": r,
        "roll_rad": a[:, 0],
        "pitch_rad": a[:, 1],
        "yaw_rad": a[:, 2],
        "roll_rate_rad_s": a[:, 3],
        "pitch_rate_rad_s": a[:, 4],
        "yaw_rate_rad_s": a[:, 5],
    }
    f = compute_features(sig, toy.info.features)
    win = sliding_windows(f, 100)
    ok = np.array([airborne[i : i + 100].all() and np.isfinite(win[i]).all() for i in range(len(win))])
    ends = np.flatnonzero(ok) + 99
    assert [steps[i].timestamp_us for i in ends] == [s.timestamp_us for s in classified]
    _, faults = toy.predict(win[ok])
    np.testing.assert_allclose(np.array([s.fault_probability for s in classified]), faults, rtol=0, atol=1e-6)
    assert faults[:, 1].min() > 0.9 and np.delete(faults, 1, axis=1).max() < 0.2


def test_steps_do_not_depend_on_how_bytes_are_chunked(toy):
    frames = synth_flight(8.0, faulty=(4,), seed=5)
    _, whole = run_pipeline(toy, parse_all(frames))
    _, chunked = run_pipeline(toy, parse_all(frames, chunk_sizes=(1, 97), seed=9))
    a = [(s.timestamp_us, None if s.fault_probability is None else s.fault_probability.tolist()) for s in whole]
    b = [(s.timestamp_us, None if s.fault_probability is None else s.fault_probability.tolist()) for s in chunked]
    assert a == b and any(x[1] for x in a)


def test_nan_and_gaps_empty_the_buffer_and_are_never_classified(toy):
    frames = synth_flight(20.0, faulty=(1,), seed=1, nan_window_s=(9.0, 9.3), hole_s=(14.0, 14.6))
    p, steps = run_pipeline(toy, parse_all(frames))
    t0 = 100_000_000
    classified = [(s.timestamp_us - t0) / 1e6 for s in steps if s.fault_probability is not None]
    assert classified, "some windows are clean"
    # A window (100 steps, 4.95 s) never contains the NaN span or the hole (stale after max_gap_s = 0.25 s).
    for t in classified:
        assert not (9.0 < t < 9.3 + 4.95) and not (14.0 + 0.25 <= t < 14.6 + 4.95)
    assert any(t > 14.6 + 4.95 for t in classified)  # and it comes back
    assert p.stats["resets"] >= 2
    bad = [s for s in steps if not s.valid and s.airborne]
    assert any("attitude" in s.reason for s in bad)


def test_esc_rpm_source_and_motor_mapping(toy):
    frames = synth_flight(9.0, faulty=(3,), seed=2, esc_index_offset=4)  # ESCs reported as 5..8
    cfg = monitor_config_from_mapping({"input": {"motor_source": "esc", "motor_outputs": [5, 6, 7, 8]}})
    _, steps = run_pipeline(toy, parse_all(frames), cfg)
    probs = np.array([s.fault_probability for s in steps if s.fault_probability is not None])
    assert len(probs) and probs[:, 2].min() > 0.9
    # The same log with rotors 3 and 1 swapped in the mapping blames rotor 1.
    cfg = monitor_config_from_mapping({"input": {"motor_source": "esc", "motor_outputs": [7, 6, 5, 8]}})
    _, steps = run_pipeline(toy, parse_all(frames), cfg)
    probs = np.array([s.fault_probability for s in steps if s.fault_probability is not None])
    assert probs[:, 0].min() > 0.9 and probs[:, 2].max() < 0.2


def test_not_armed_or_on_the_ground_is_not_classified(toy):
    frames = synth_flight(9.0, faulty=(3,), takeoff_s=100.0)  # never leaves the ground
    _, steps = run_pipeline(toy, parse_all(frames))
    assert steps and not any(s.fault_probability is not None for s in steps)
    cfg = monitor_config_from_mapping({"input": {"landed_state": "ignore"}})
    _, steps = run_pipeline(toy, parse_all(frames), cfg)  # armed is then enough
    assert any(s.fault_probability is not None for s in steps)


def test_every_k_steps(toy):
    frames = synth_flight(10.0, seed=4)
    cfg = monitor_config_from_mapping({"inference": {"every_k_steps": 4}})
    _, steps = run_pipeline(toy, parse_all(frames), cfg)
    ts = [s.timestamp_us for s in steps if s.fault_probability is not None]
    assert len(ts) > 5 and set(np.diff(ts)) == {200_000}


def test_model_metadata_mismatch_is_a_clear_error(tmp_path):
    clf = Classifier(toy_model(tmp_path / "m50.onnx", window=50))
    with pytest.raises(ModelError, match="window"):
        Pipeline(clf, MonitorConfig(), PAPER_ESC)
    clf = Classifier(toy_model(tmp_path / "m10.onnx", sample_rate_hz=10.0))
    with pytest.raises(ModelError, match="10.0 Hz"):
        Pipeline(clf, MonitorConfig(), PAPER_ESC)


# --- alerts ---------------------------------------------------------------------------------


class FakeClock:
    def __init__(self):
        self.t = 1000.0

    def __call__(self):
        return self.t


def test_rate_limiter():
    clock = FakeClock()
    lim = RateLimiter(5.0, clock)
    assert lim.allow() and not lim.allow()
    clock.t += 4.9
    assert not lim.allow()
    clock.t += 0.1
    assert lim.allow()


# --- config ---------------------------------------------------------------------------------


def test_config_rejects_unknown_and_bad_keys_by_name(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("alerts:\n  treshold: 0.9\n")
    with pytest.raises(ConfigError, match="treshold"):
        load_monitor_config(bad)
    bad.write_text("link:\n  stream_rate_hz: 10\n")
    with pytest.raises(ConfigError, match="stream_rate_hz"):
        load_monitor_config(bad)
    bad.write_text("input:\n  motor_outputs: [1, 1, 2, 3]\n")
    with pytest.raises(ConfigError, match="motor_outputs"):
        load_monitor_config(bad)
    good = tmp_path / "good.yaml"
    good.write_text("alerts:\n  statustext_min_interval_s: 2.0\n")
    assert load_monitor_config(good).alerts.statustext_min_interval_s == 2.0


@pytest.mark.parametrize(
    "text,expect",
    [
        ("alerts:\n  rule: consecutive\n", "alerts.rule: 'consecutive' is no longer an onboard rule; use 'sequential'"),
        ("alerts:\n  rule: consecutive\n  threshold: 0.9\n", "offline comparison in offline/alerts"),
        ("alerts:\n  threshold: 0.9\n  refractory_s: 30\n", "alerts.threshold, alerts.refractory_s: keys of the consecutive"),
        ("alerts:\n  critical_threshold: 0.95\n", "alerts.critical_threshold: a key of the consecutive rule"),
    ],
)
def test_the_consecutive_rule_and_its_keys_are_named_with_their_replacement(tmp_path, text, expect):
    cfg = tmp_path / "monitor.yaml"
    cfg.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_monitor_config(cfg)
    assert str(err.value).startswith(f"{cfg}: ") and expect in str(err.value), err.value
    with pytest.raises(ConfigError, match="no longer an onboard rule"):
        monitor_config_from_mapping({"alerts": {"rule": "consecutive"}})


def test_shipped_example_config_loads():
    cfg = load_monitor_config(Path(__file__).resolve().parent.parent / "deploy" / "monitor.yaml")
    assert cfg.link.component_id == 191 and cfg.link.stream_rate_hz >= 20


# --- sd_notify ------------------------------------------------------------------------------


def test_sd_notify_speaks_the_systemd_protocol(tmp_path):
    path = str(tmp_path / "notify.sock")
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    srv.bind(path)
    srv.settimeout(2.0)
    n = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "4000000"})
    assert n.watchdog_s == 4.0
    assert n.ready("ok") and n.watchdog() and n.stopping()
    assert [srv.recv(256) for _ in range(3)] == [b"READY=1\nSTATUS=ok", b"WATCHDOG=1", b"STOPPING=1"]
    n.close()
    srv.close()
    off = Notifier({})
    assert not off.enabled and not off.ready() and off.watchdog_s is None


def test_esc_status_decodes_even_from_a_parser_that_calls_it_unknown_291():
    from monitor.mavlink import esc as mavlink_esc

    ap = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    frame = mavlink_esc.encode_esc_status(ap, 123_456_789, [5000, 5100, 5200, 5300], index=0)
    unknown = mavlink.MAVLink_unknown(291, bytearray(frame))  # what a stock pymavlink 2.4.50 yields
    d = md.MavlinkDecoder(system_id=1)
    (e,) = d.decode(unknown)
    assert e == md.EscRpm(123_456_789, 0, (5000.0, 5100.0, 5200.0, 5300.0))
    other = mavlink.MAVLink(None, srcSystem=2, srcComponent=1)
    stranger = mavlink.MAVLink_unknown(291, bytearray(mavlink_esc.encode_esc_status(other, 1, [1, 2, 3, 4])))
    assert d.decode(stranger) == [] and d.ignored[(2, 1)] == 1  # the ids come from the frame


def test_actuator_output_status_uses_the_active_bitmask():
    d = md.MavlinkDecoder(system_id=1)
    values = [1500.0, 1510.0, 1520.0, 1530.0] + [0.0] * 28
    (o,) = d.decode(msg(mavlink.MAVLink_actuator_output_status_message(2_000_000, 0b0111, values)))
    assert o.source == "ACTUATOR_OUTPUT_STATUS" and o.timestamp_us == 2_000_000 and o.first_channel == 1
    assert o.values_us[:3] == (1500.0, 1510.0, 1520.0) and math.isnan(o.values_us[3])  # output 4 not active


def test_servo_port_1_carries_outputs_9_to_16(toy):
    frames = synth_flight(9.0, faulty=(2,), servo_port=1)
    cfg = monitor_config_from_mapping({"input": {"motor_outputs": [9, 10, 11, 12]}})
    _, steps = run_pipeline(toy, parse_all(frames), cfg)
    probs = np.array([s.fault_probability for s in steps if s.fault_probability is not None])
    assert len(probs) and probs[:, 1].min() > 0.9
    p, steps = run_pipeline(toy, parse_all(frames))  # outputs 1..4 are not in these messages
    assert not any(s.fault_probability is not None for s in steps) and p.stats["motor_msgs_unmapped"] > 100


def test_statustext_rate_limit_holds_and_never_drops_an_announcement():
    clock = FakeClock()
    q = StatusTextQueue(5.0, clock)
    assert q.due() is None  # nothing pending
    q.add_text("PROP 1 FAULT p=0.90", 4)
    assert q.due() == ("PROP 1 FAULT p=0.90", 4)
    clock.t += 1.0
    q.add_text("PROP 3 FAULT p=0.97", 4)
    q.add_text("PROP 3 FAULT p=0.97", 4)  # the same text twice is sent once
    clock.t += 1.0
    q.add_text("PROP 2 FAULT p=0.85", 4)
    assert q.due() is None  # too soon, and no more severe than the last: held
    clock.t += 3.0
    first = q.due()
    assert first is not None and q.due() is None  # one per interval
    clock.t += 5.0
    second = q.due()
    assert {first, second} == {("PROP 3 FAULT p=0.97", 4), ("PROP 2 FAULT p=0.85", 4)}
    clock.t += 5.0
    assert q.due() is None


def test_statustext_escalation_is_not_held_behind_its_own_notice():
    clock = FakeClock()
    q = StatusTextQueue(5.0, clock)
    q.add_text("PROP 3 SUSPECT", 5)
    assert q.due() == ("PROP 3 SUSPECT", 5)
    clock.t += 1.0
    q.add_text("PROP 1 SUSPECT", 5)  # as severe as the last: waits for the rate limit
    assert q.due() is None
    q.add_text("PROP 3 FAULT p=0.97", 4)  # more severe: goes out now
    assert q.due() == ("PROP 3 FAULT p=0.97", 4)
    clock.t += 1.0
    assert q.due() is None  # the NOTICE still waits; the interval restarted with the WARNING
    q.add_text("PROP 1 or 1+3?", 2)
    assert q.due() == ("PROP 1 or 1+3?", 2)  # CRITICAL: more severe again
    clock.t += 1.0
    assert q.due() is None
    clock.t += 5.0
    assert q.due() == ("PROP 1 SUSPECT", 5)  # never dropped


def test_an_exception_inside_the_pipeline_is_logged_and_survived(tmp_path, toy, caplog):
    from test_daemon_helpers import write_tlog

    from monitor.daemon.events import EventWriter
    from monitor.daemon.link import Link
    from monitor.daemon.service import Daemon

    frames = synth_flight(2.0)
    link = Link(str(write_tlog(tmp_path / "f.tlog", frames)), 191, tlog_speed=0)
    pipe = Pipeline(toy, MonitorConfig(), PAPER_ESC)
    daemon = Daemon(MonitorConfig(), link, pipe, EventWriter(None))
    real_feed, calls = pipe.feed, []

    def flaky(msg, received_s=None):
        calls.append(msg.get_type())
        if len(calls) == 5:
            raise RuntimeError("boom")
        return real_feed(msg, received_s)

    pipe.feed = flaky
    msgs = parse_all(frames)
    for m in msgs:
        daemon.handle(m, 0.0)
    link.close()
    assert daemon.counters.internal_errors == 1 and len(calls) == len(msgs)
    assert "error while processing" in caplog.text and "boom" in caplog.text


LOG171 = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "ardupilot_log171" / "log171.bin"


@pytest.mark.realdata
@pytest.mark.skipif(not LOG171.is_file(), reason=f"real ArduPilot log not found at {LOG171} (../shared/data)")
def test_streaming_hold_equals_batch_hold_on_a_real_logs_timing():
    """Real clocks and jitter (ArduCopter RCOU 50 Hz, ATT and RATE 10 Hz), streams interleaved in time order."""
    from monitor.logs.dataflash import read_dataflash

    raw = read_dataflash(LOG171)
    streams = {"motor": raw.motor_cmd, "att": raw.attitude_rad, "rate": raw.rates_rad_s}
    age = 250_000
    sh = StreamingHold(50_000, {k: StreamSpec(s.values.shape[1], age, True) for k, s in streams.items()})
    arrivals = sorted(((int(t), k, i) for k, s in streams.items() for i, t in enumerate(s.t_us)), key=lambda e: e[0])
    steps = []
    for t, k, i in arrivals:
        steps += sh.push(k, t, streams[k].values[i])
    steps += sh.flush()
    assert sh.late == 0 and len(steps) > 4000
    grid = np.array([s.timestamp_us for s in steps])
    for k, s in streams.items():
        batch = hold(s.t_us, s.values, grid, age)
        stream = np.array([st.values[k] for st in steps])
        np.testing.assert_array_equal(np.isnan(stream), np.isnan(batch))
        np.testing.assert_array_equal(np.nan_to_num(stream), np.nan_to_num(batch))
    held = np.array([st.values["att"] for st in steps])
    assert np.isfinite(held).all(axis=1).mean() > 0.9  # 10 Hz attitude is held across the 20 Hz grid, not lost
