"""The daemon's specific force: HIGHRES_IMU (or SCALED_IMU) averaged over each 20 Hz step into StepInputs.

Context like velocity (``test_daemon_velocity``): missing, stale, NaN, absurd or frozen IMU data gives
``accel_xy_frd_m_s2=None`` (bad samples counted), never a pause, and the classifier's steps stay as without it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from fuzz_helpers import decoded
from pymavlink.dialects.v20 import common as mavlink
from test_daemon_helpers import synth_flight, toy_model
from test_daemon_pipeline import parse_all, run_pipeline
from test_daemon_velocity import (
    BOOT0_S,
    bad_velocity,
    check_context_is_optional,
    flight_s,
    requested_rates,
    run_bad_context_flight,
    run_daemon,
)

from monitor.daemon.resampler import StreamingHold, StreamSpec
from monitor.mavlink import decode as md
from monitor.model import Classifier

PERIOD_US = 50_000  # the 20 Hz grid
HIGHRES_IMU_ID = 105


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return Classifier(toy_model(tmp_path_factory.mktemp("model") / "toy.onnx"))


def imu_samples(msgs) -> tuple[np.ndarray, np.ndarray]:
    """Boot times (µs) and (x, y) of the HIGHRES_IMU messages, as sent."""
    imu = [m for m in msgs if m.get_type() == "HIGHRES_IMU"]
    return np.array([m.time_usec for m in imu]), np.array([(m.xacc, m.yacc) for m in imu])


def test_highres_imu_samples_in_a_step_are_averaged_and_a_bad_one_is_left_out(toy):
    def accel(t):  # vibration at 37 and 29 Hz around a drag of (1.0, -0.5); every 7th sample NaN
        if int(round(t * 100)) % 7 == 3:
            return (math.nan, math.nan, math.nan)
        return (1.0 + 3.0 * math.sin(2 * math.pi * 37 * t), -0.5 + 2.0 * math.cos(2 * math.pi * 29 * t), -9.8)

    msgs = parse_all(synth_flight(8.0, seed=5, imu_hz=100.0, accel_of_t=accel))
    p, steps = run_pipeline(toy, msgs)
    t_s, xy = imu_samples(msgs)
    later = [s for s in steps if flight_s(s) >= 0.5]
    assert len(later) > 140 and all(s.inputs.accel_xy_frd_m_s2 is not None for s in later)
    got = np.array([s.inputs.accel_xy_frd_m_s2 for s in later])
    span = [(t_s > s.timestamp_us - PERIOD_US) & (t_s <= s.timestamp_us) for s in later]
    expected = np.array([np.nanmean(xy[m], axis=0) for m in span])  # the finite samples of (g - 50 ms, g]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    held = np.array([xy[np.flatnonzero(t_s <= s.timestamp_us)[-1]] for s in later])  # a zero-order hold instead
    assert np.nanmedian(np.abs(held - got)) > 0.5  # the vibration it would have passed on
    assert p.stats["imu_late"] == 0 and p.stats["imu_steps"] >= len(later)
    assert p.plausible.dropped["imu: not finite"] >= 100


def test_scaled_imu_in_milli_g_stands_in_only_while_highres_imu_is_absent(toy):
    def scaled(t):  # x -102 mG = -1.0003 m/s^2; y moves so the channel is not frozen
        return (-102 * md.M_S2_PER_MG, (10 + int(t * 50) % 5) * md.M_S2_PER_MG, -1000 * md.M_S2_PER_MG)

    def highres(t):
        return (2.0 + 0.1 * math.sin(3 * t), 0.0, -9.8)

    both = synth_flight(12.0, seed=6, imu_hz=50.0, accel_of_t=scaled, imu_msg="SCALED_IMU")
    highres_frames = synth_flight(12.0, seed=6, imu_hz=50.0, accel_of_t=highres)
    mav = mavlink.MAVLink(None)
    until_s = 6.0 + BOOT0_S  # HIGHRES_IMU stops 6 s into the flight; SCALED_IMU flows throughout
    for when, frame in highres_frames:
        m = mav.decode(bytearray(frame))
        if m.get_type() == "HIGHRES_IMU" and m.time_usec / 1e6 < until_s:
            both.append((when, frame))
    both.sort(key=lambda f: f[0])
    p, steps = run_pipeline(toy, parse_all(both))

    def x(a, b):
        return np.array([s.inputs.accel_xy_frd_m_s2[0] for s in steps if a <= flight_s(s) < b])

    np.testing.assert_allclose(x(0.5, 6.0), 2.0, atol=0.11)  # HIGHRES_IMU; SCALED_IMU beside it is ignored
    np.testing.assert_allclose(x(6.3, 12.0), -1.0003, atol=1e-4)  # then SCALED_IMU, milli-g converted
    assert x(6.3, 12.0)[0] == pytest.approx(-102 * 9.80665e-3, rel=1e-12)
    assert not p.plausible.dropped


def test_without_an_imu_stream_the_specific_force_is_none_and_the_classifier_steps_are_the_same(toy):
    p = check_context_is_optional(toy, "accel_xy_frd_m_s2", 170, imu_hz=50.0)
    assert p.stats["imu_late"] == 0


def bad_accel(t):
    """The bad-context flight's accelerometer (``run_bad_context_flight``'s spans): NaN, absurd, stuck, good."""
    if 3.0 <= t < 5.0:
        return (math.nan, 0.2, -9.8)
    if 5.0 <= t < 7.0:
        return (170.0 + math.sin(t), 0.2, -9.8)  # beyond the 16 g range
    if 7.0 <= t < 10.0:
        return (0.3, -0.2, -9.8)  # stuck: bit-identical from 7 s, frozen after plausible.frozen_s (1 s)
    return (0.3 + 0.2 * math.sin(40.0 * t), -0.2, -9.8)


def test_nan_absurd_and_frozen_imu_data_is_ignored_and_counted_never_a_pause(toy):
    p = run_bad_context_flight(toy, "accel_xy_frd_m_s2", imu_hz=50.0, accel_of_t=bad_accel)
    dropped = p.plausible.dropped
    assert dropped["imu: not finite"] >= 95 and dropped["imu: beyond 160 m/s^2"] >= 95, dropped
    assert dropped["imu: frozen"] >= 95, dropped


def test_a_mean_stream_averages_each_period_and_holds_across_an_empty_one():
    hold = StreamingHold(PERIOD_US, {"a": StreamSpec(1, 10_000_000, True), "f": StreamSpec(1, 250_000, False, False, 50_000)})
    for t, f in [(1_010_000, 1.0), (1_030_000, 3.0), (1_050_000, 5.0), (1_060_000, math.nan), (1_120_000, 7.0)]:
        hold.push("f", t, [f])
    steps = [g for t in range(1_000_000, 1_500_001, 20_000) for g in hold.push("a", t, [0.0])]
    got = {g.timestamp_us: g.values["f"][0] for g in steps}
    assert got[1_050_000] == 3.0  # (1.0 + 3.0 + 5.0) / 3: (1.00, 1.05] s
    assert math.isnan(got[1_100_000])  # only a NaN in its period: unknown, not the older mean
    assert got[1_150_000] == 7.0 and got[1_200_000] == 7.0  # a period without a sample holds the latest one
    assert math.isnan(got[1_400_000])  # stale after max_age (250 ms)


def test_only_the_autopilots_first_imu_is_decoded():
    dec = md.MavlinkDecoder()
    dec.decode(decoded(mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3)))
    msg = mavlink.MAVLink_highres_imu_message(5_000_000, 0.5, -0.25, -9.8, *[0.0] * 10, fields_updated=7, id=0)
    second = mavlink.MAVLink_highres_imu_message(5_000_000, 9.0, 9.0, -9.8, *[0.0] * 10, fields_updated=7, id=1)
    (s,) = dec.decode(decoded(msg))
    assert (s.timestamp_us, s.accel_frd_m_s2[:2], s.source) == (5_000_000, (0.5, -0.25), "HIGHRES_IMU")
    assert dec.decode(decoded(second)) == []  # IMU 2
    assert dec.decode(decoded(msg, sys_id=255, comp=190)) == []  # a ground station's
    scaled = mavlink.MAVLink_scaled_imu_message(5_020, -102, 51, -1000, 0, 0, 0, 0, 0, 0)
    (s,) = dec.decode(decoded(scaled))
    assert s.timestamp_us == 5_020_000 and s.source == "SCALED_IMU"
    assert s.accel_frd_m_s2 == pytest.approx((-1.0003, 0.50014, -9.80665), abs=1e-4)


def test_status_lists_velocity_and_imu_as_context_apart_from_evidence(toy):
    msgs = parse_all(synth_flight(16.0, seed=7, pos_hz=30.0, imu_hz=50.0))
    stop_us = (BOOT0_S + 8.0) * 1e6  # HIGHRES_IMU stops 8 s into the flight, the rest flows on
    msgs = [m for m in msgs if not (m.get_type() == "HIGHRES_IMU" and m.time_usec > stop_us)]
    d, seen = run_daemon(toy, msgs, "accel_xy_frd_m_s2")
    statuses = [s.split("; shares learning")[0] for s in d.notifier.statuses()]  # learning: its own test
    live = "airborne: deciding; evidence live: classifier, esc_rpm; context live: velocity, imu"
    assert live in statuses, statuses
    assert statuses[-1] == "airborne: deciding; evidence live: classifier, esc_rpm; context live: velocity", statuses
    assert not [s for s in statuses if "paused" in s or "BLIND" in s], statuses
    assert all(a is not None for t, a in seen if 0.5 <= t <= 8.0)
    assert all(a is None for t, a in seen if t >= 8.3)  # stale after resample.max_gap_s (0.25 s)
    assert d.report()["pipeline"]["imu_steps"] > 140


def test_highres_imu_is_requested_at_50_hz_beside_local_position(toy):
    rates = requested_rates(toy)
    assert rates[HIGHRES_IMU_ID] == 50.0  # PX4's onboard-link rate: 2-3 samples in each 50 ms step


def test_diagnose_reads_each_steps_specific_force_as_the_daemon_does(toy, tmp_path):
    """The same recorded flight, live through the daemon's pipeline and from its .tlog through diagnose's reader:
    the decision gets the same per-step specific force (the mean of the step's own samples, bad ones left out),
    not a sample held by one and a mean by the other."""
    from test_daemon_helpers import write_tlog

    from monitor.logs import read_log

    def accel(t):  # vibration around a drag of (0.8, -0.3); every 9th sample NaN
        if int(round(t * 130)) % 9 == 4:
            return (math.nan, math.nan, math.nan)
        return (0.8 + 2.5 * math.sin(2 * math.pi * 41 * t), -0.3 + 1.5 * math.cos(2 * math.pi * 23 * t), -9.8)

    frames = synth_flight(8.0, seed=9, imu_hz=130.0, accel_of_t=accel)
    _, steps = run_pipeline(toy, parse_all(frames))
    table = read_log(write_tlog(tmp_path / "f.tlog", frames))
    at = {int(t): i for i, t in enumerate(table.timestamp_us)}
    later = [s for s in steps if flight_s(s) >= 0.5 and s.inputs.accel_xy_frd_m_s2 is not None]
    assert len(later) > 140
    live = np.array([s.inputs.accel_xy_frd_m_s2 for s in later])
    logged = np.array([table.accel_frd_m_s2[at[int(s.timestamp_us)], :2] for s in later])
    np.testing.assert_allclose(logged, live, rtol=0, atol=1e-9)


def test_diagnose_reads_scaled_imu_in_milli_g_where_the_log_has_no_highres_imu(toy, tmp_path):
    """A link that carries SCALED_IMU only (milli-g): the daemon converts it; so does diagnose's reader, through the
    same decoder (it read HIGHRES_IMU alone, by hand, before)."""
    from test_daemon_helpers import write_tlog

    from monitor.logs import read_log

    def scaled(t):
        return (-102 * md.M_S2_PER_MG, (10 + int(t * 50) % 5) * md.M_S2_PER_MG, -1000 * md.M_S2_PER_MG)

    frames = synth_flight(8.0, seed=6, imu_hz=50.0, accel_of_t=scaled, imu_msg="SCALED_IMU")
    _, steps = run_pipeline(toy, parse_all(frames))
    table = read_log(write_tlog(tmp_path / "scaled.tlog", frames))
    at = {int(t): i for i, t in enumerate(table.timestamp_us)}
    later = [s for s in steps if flight_s(s) >= 0.5 and s.inputs.accel_xy_frd_m_s2 is not None]
    assert len(later) > 140
    logged = np.array([table.accel_frd_m_s2[at[int(s.timestamp_us)], :2] for s in later])
    np.testing.assert_allclose(logged, [s.inputs.accel_xy_frd_m_s2 for s in later], rtol=0, atol=1e-9)
    assert np.allclose(logged[:, 0], -1.0003, atol=1e-3)  # -102 mG in m/s^2


def test_diagnose_ignores_the_context_samples_the_daemon_ignores(toy, tmp_path):
    """NaN, absurd and frozen velocity and IMU samples in a recorded flight: diagnose's reader drops the samples the
    daemon drops (``monitor.decision.envelope``), says so in a warning, and the steps that carry context are the daemon's."""
    from test_daemon_helpers import write_tlog

    from monitor.logs import read_log

    frames = synth_flight(13.0, faulty=(3,), seed=4, pos_hz=30.0, vel_of_t=bad_velocity, imu_hz=50.0, accel_of_t=bad_accel)
    _, steps = run_pipeline(toy, parse_all(frames))
    table = read_log(write_tlog(tmp_path / "bad.tlog", frames))
    assert any("velocity samples ignored as implausible" in w and "beyond 60 m/s" in w for w in table.warnings)
    assert any("imu samples ignored as implausible" in w and "frozen" in w for w in table.warnings)
    at = {int(t): i for i, t in enumerate(table.timestamp_us)}
    later = [s for s in steps if flight_s(s) >= 0.5 and int(s.timestamp_us) in at]
    assert len(later) > 230
    acc_live = np.array([s.inputs.accel_xy_frd_m_s2 is not None for s in later])
    acc_log = np.array([np.isfinite(table.accel_frd_m_s2[at[int(s.timestamp_us)], :2]).all() for s in later])
    vel_live = np.array([s.inputs.vel_heading_m_s is not None for s in later])
    vel_log = np.array([np.isfinite(table.vel_ned_m_s[at[int(s.timestamp_us)], :2]).all() for s in later])
    assert not acc_live.all() and not vel_live.all()  # the bad spans are there to be dropped
    np.testing.assert_array_equal(acc_log, acc_live)
    np.testing.assert_array_equal(vel_log, vel_live)
