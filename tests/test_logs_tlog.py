"""The tlog reader: round trip through pymavlink, damage handling, missing messages."""

from __future__ import annotations

import numpy as np
import pytest
from test_diagnose_fixtures import flight_profile, write_tlog

from monitor.errors import LogFormatError
from monitor.esc import PAPER_ESC
from monitor.logs import detect_format, read_log, read_raw
from monitor.logs.tlog import iter_frames


def test_round_trip_values_on_the_grid(tmp_path):
    path = write_tlog(tmp_path / "f.tlog", duration_s=20.0, faulty=2, rate_hz=50.0)
    t_us, pwm, att, _, landed = flight_profile(20.0, 50.0, 2)
    table = read_log(path, esc=PAPER_ESC)
    assert detect_format(path) == "tlog"
    # Grid instants are multiples of 50 ms on the boot clock; samples at 20 ms land exactly on every other grid point.
    assert np.all(table.timestamp_us % 50_000 == 0)
    idx = np.searchsorted(t_us, table.timestamp_us, side="right") - 1
    expect_pwm = np.round(pwm[idx])  # SERVO_OUTPUT_RAW carries whole µs
    np.testing.assert_array_equal(table.motor_cmd, expect_pwm)
    np.testing.assert_allclose(table.motor_rpm, PAPER_ESC.cmd_to_rpm(expect_pwm))
    np.testing.assert_allclose(table.roll_rad, att[idx, 0], atol=1e-6)  # float32 on the wire
    np.testing.assert_allclose(table.yaw_rate_rad_s, att[idx, 5], atol=1e-6)
    # Airborne = armed and IN_AIR (EXTENDED_SYS_STATE at 1 Hz, held): 2 s .. 18 s, to within the 1 s message period.
    seg = table.airborne_segments()
    assert len(seg) == 1
    t0 = (table.timestamp_us[seg[0][0]] - t_us[0]) / 1e6
    t1 = (table.timestamp_us[seg[0][1] - 1] - t_us[0]) / 1e6
    assert 2.0 <= t0 <= 3.05 and 17.0 <= t1 < 18.0
    assert table.warnings == ()
    assert table.pos_ned_m is not None and table.battery_v[seg[0][0]] == pytest.approx(16.0)


def test_ground_station_messages_are_ignored(tmp_path):
    path = write_tlog(tmp_path / "f.tlog", duration_s=8.0)
    raw = read_raw(path)
    # The GCS heartbeat says "not armed"; the autopilot's says armed: only the autopilot's count.
    assert np.all(raw.armed.values == 1.0)


def test_truncated_log_is_read_up_to_the_cut(tmp_path):
    full = write_tlog(tmp_path / "full.tlog", duration_s=20.0)
    data = full.read_bytes()
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(data[: len(data) // 2 + 7])  # mid-frame
    whole, part = read_raw(full), read_raw(cut)
    assert any("truncated" in w for w in part.warnings)
    n = len(part.attitude_rad)
    assert 0.45 * len(whole.attitude_rad) < n < 0.55 * len(whole.attitude_rad)
    np.testing.assert_array_equal(part.attitude_rad.values, whole.attitude_rad.values[:n])


def test_corrupted_bytes_are_skipped_and_reading_goes_on(tmp_path):
    full = write_tlog(tmp_path / "full.tlog", duration_s=20.0)
    data = bytearray(full.read_bytes())
    mid = len(data) // 3
    data[mid : mid + 300] = bytes(range(256)) + bytes(44)  # garbage over several frames
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(bytes(data))
    whole, part = read_raw(full), read_raw(bad)
    assert any("corrupted" in w for w in part.warnings)
    # Frames after the damage are still read: the last attitude sample is the same.
    assert part.attitude_rad.t_us[-1] == whole.attitude_rad.t_us[-1]
    assert len(whole.attitude_rad) - 10 < len(part.attitude_rad) < len(whole.attitude_rad)


def test_frame_walk_skips_unwanted_ids_without_decoding(tmp_path):
    path = write_tlog(tmp_path / "f.tlog", duration_s=4.0)
    ids = [fr[7] | fr[8] << 8 for _, fr in iter_frames(path.read_bytes(), wanted=frozenset({30}))]
    assert ids and set(ids) == {30}  # ATTITUDE only


def test_missing_motor_outputs_is_a_clear_error(tmp_path):
    import struct

    from pymavlink.dialects.v20 import common

    mav = common.MAVLink(None, srcSystem=1, srcComponent=1)
    out = bytearray()
    for i in range(50):
        for msg in (mav.heartbeat_encode(2, 12, 129, 0, 4), mav.attitude_encode(i * 100, 0, 0, 0, 0, 0, 0)):
            out += struct.pack(">Q", i * 100_000) + msg.pack(mav)
    path = tmp_path / "nomotor.tlog"
    path.write_bytes(bytes(out))
    with pytest.raises(LogFormatError, match="motor outputs"):
        read_raw(path)


def test_unknown_format_is_a_clear_error(tmp_path):
    path = tmp_path / "x.log"
    path.write_bytes(b"this is not a flight log at all\n" * 10)
    with pytest.raises(LogFormatError, match="unknown log format"):
        read_raw(path)


def _assert_same_streams(a, b):
    for k in (
        "motor_cmd",
        "attitude_rad",
        "rates_rad_s",
        "battery_v",
        "armed",
        "landed",
        "esc_rpm",
        "accel_frd_m_s2",
        "vel_ned_m_s",
        "pos_ned_m",
    ):
        x, y = getattr(a, k), getattr(b, k)
        assert (x is None) == (y is None), k
        if x is not None:
            np.testing.assert_array_equal(x.t_us, y.t_us, err_msg=k)
            np.testing.assert_array_equal(x.values, y.values, err_msg=k)
    assert a.warnings == b.warnings


def test_bulk_unpacking_equals_pymavlink_frame_by_frame(tmp_path):
    import struct

    from pymavlink.dialects.v10 import common as v1
    from pymavlink.dialects.v20 import common as v2

    from monitor.logs.tlog import read_tlog

    path = write_tlog(tmp_path / "f.tlog", duration_s=12.0, faulty=3)
    # Append MAVLink 1 frames (and a truncated MAVLink 2 payload of trailing zeros) to the same log.
    m1, m2 = v1.MAVLink(None, srcSystem=1, srcComponent=1), v2.MAVLink(None, srcSystem=1, srcComponent=1)
    extra = bytearray()
    for i in range(40):  # the receive clock jumps back by years here (a reset wall clock): still read
        t_ms = 14_000 + 20 * i
        extra += struct.pack(">Q", t_ms * 1000) + m1.attitude_encode(t_ms, 0.1, -0.2, 0.3, 0.0, 0.0, 0.0).pack(m1)
        extra += struct.pack(">Q", t_ms * 1000) + m2.servo_output_raw_encode(
            t_ms * 1000, 0, 1500, 1510, 1520, 1530, 0, 0, 0, 0
        ).pack(m2)
    path.write_bytes(path.read_bytes() + bytes(extra))
    for extras in (True, False):
        fast, slow = read_tlog(path, extras=extras, bulk=True), read_tlog(path, extras=extras, bulk=False)
        _assert_same_streams(fast, slow)
    assert fast.attitude_rad.t_us[-1] == 14_780_000 and fast.motor_cmd.values[-1].tolist() == [1500, 1510, 1520, 1530]


def test_the_bulk_crc_is_mavlinks_and_a_clean_log_passes_it(tmp_path):
    """A wrong bulk CRC would only make every log fall back to the slow frame-by-frame read (same streams): here it
    must equal pymavlink's X.25 over rows of any bytes and CRC extra, and a clean log's frames must all pass it."""
    from pymavlink.generator.mavcrc import x25crc

    from monitor.logs.mavbulk import unpack_groups, x25_crc
    from monitor.logs.tlog import CORE_IDS, _mavlink, frame_starts

    rows = np.random.default_rng(3).integers(0, 256, size=(37, 45), dtype=np.uint8)[:, 2:]  # not contiguous
    for extra in (0, 39, 255):
        want = []
        for r in rows:
            crc = x25crc(bytes(r))
            crc.accumulate(bytes([extra]))
            want.append(crc.crc)
        assert x25_crc(rows, extra).tolist() == want
    buf = write_tlog(tmp_path / "f.tlog", duration_s=12.0, faulty=3).read_bytes()
    starts, skipped, _ = frame_starts(buf, CORE_IDS)
    assert skipped == 0 and unpack_groups(buf, starts, _mavlink()[1]) is not None


def test_a_bad_crc_falls_back_to_frame_by_frame(tmp_path):
    from monitor.logs.tlog import read_tlog

    path = write_tlog(tmp_path / "f.tlog", duration_s=12.0)
    data = bytearray(path.read_bytes())
    i = data.index(bytes([0xFD, 28]), len(data) // 2)  # an ATTITUDE frame (28-byte payload) mid-file
    data[i + 14] ^= 0xFF  # one payload byte: length intact, CRC wrong
    path.write_bytes(bytes(data))
    fast, slow = read_tlog(path, bulk=True), read_tlog(path, bulk=False)
    _assert_same_streams(fast, slow)
    assert any("failing their CRC" in w for w in fast.warnings)


def test_slow_streams_are_held_and_flagged(tmp_path):
    path = write_tlog(tmp_path / "slow.tlog", duration_s=20.0, rate_hz=8.0)
    table = read_log(path, esc=PAPER_ESC)
    assert any("attitude_rad logged at 8.0 Hz" in w for w in table.warnings)
    assert any("motor_cmd logged at 8.0 Hz" in w for w in table.warnings)
    seg = table.airborne_segments()
    # 125 ms between samples, held up to 250 ms: the 20 Hz grid has no gaps in flight.
    assert np.isfinite(table.roll_rad[seg[0][0] : seg[0][1]]).all()


def test_a_diagnosis_reads_the_accelerometer_the_daemon_uses(tmp_path):
    """The decision rule's baseline plane takes the specific force (the daemon requests HIGHRES_IMU): a log read for a
    diagnosis (``extras=False``) carries it too, the same samples as a full read, or forward flight reads as a change."""
    import struct

    from pymavlink.dialects.v20 import common as v2

    from monitor.diagnose.engine import read_guarded
    from monitor.logs.tlog import read_tlog

    path = write_tlog(tmp_path / "f.tlog", duration_s=12.0, faulty=0)
    m2 = v2.MAVLink(None, srcSystem=1, srcComponent=1)
    extra = bytearray()
    for i in range(200):  # 50 Hz for 4 s after the log's end (boot clock in µs); 1 m/s^2 forward, gravity along -z
        t_us = 12_100_000 + 20_000 * i
        imu = m2.highres_imu_encode(t_us, 1.0, 0.0, -9.8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0b111, 0).pack(m2)
        extra += struct.pack(">Q", t_us) + imu
    path.write_bytes(path.read_bytes() + bytes(extra))
    core, full = read_tlog(path, extras=False), read_tlog(path, extras=True)
    assert core.accel_frd_m_s2 is not None and len(core.accel_frd_m_s2.t_us) == 200
    np.testing.assert_array_equal(core.accel_frd_m_s2.values, full.accel_frd_m_s2.values)
    assert core.accel_frd_m_s2.values[0].tolist() == pytest.approx([1.0, 0.0, -9.8])
    assert read_guarded(path, None).accel_frd_m_s2 is not None
