"""The tlog reader's column decoding (monitor.logs.tlog_columns) gives the flight the shared decoder gives.

Each log is read three ways: columns where the file allows, the bulk message objects through
``MavlinkDecoder`` one by one, and pymavlink frame by frame. Every stream must be identical, and the
columns must be used on the logs they are meant for (else the comparison would prove nothing) and
refused where only the decoder knows what to do (a reboot, a wrapped clock, another output message).
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from pymavlink.dialects.v20 import common
from test_diagnose_fixtures import write_tlog

import monitor.logs.tlog as tlog
from monitor.logs.tlog import read_tlog

STREAMS = ("motor_cmd", "attitude_rad", "rates_rad_s", "battery_v", "armed", "landed", "vel_ned_m_s", "accel_frd_m_s2")


def read_three_ways(path, monkeypatch):
    used = []
    decode_columns = tlog.decode_columns

    def spy(*args):
        out = decode_columns(*args)
        used.append(out is not None)
        return out

    monkeypatch.setattr(tlog, "decode_columns", spy)
    columns = read_tlog(path, extras=False)
    monkeypatch.setattr(tlog, "decode_columns", lambda *args: None)
    objects = read_tlog(path, extras=False)
    frames = read_tlog(path, extras=False, bulk=False)
    for other in (objects, frames):
        for k in STREAMS:
            x, y = getattr(columns, k), getattr(other, k)
            assert (x is None) == (y is None), k
            if x is not None:
                assert x.t_us.dtype == y.t_us.dtype and x.values.dtype == y.values.dtype, k
                np.testing.assert_array_equal(x.t_us, y.t_us, err_msg=k)
                np.testing.assert_array_equal(x.values, y.values, err_msg=k)
        assert columns.warnings == other.warnings
    return columns, used == [True]


class Log:
    """A tlog written message by message: the autopilot (system 1), a ground station and another vehicle."""

    def __init__(self):
        self.ap = common.MAVLink(None, srcSystem=1, srcComponent=1)
        self.gcs = common.MAVLink(None, srcSystem=255, srcComponent=190)
        self.other = common.MAVLink(None, srcSystem=2, srcComponent=1)
        self.out = bytearray()

    def put(self, t_us, msg, link=None):
        link = link or self.ap
        self.out += struct.pack(">Q", int(t_us) + 1_700_000_000_000_000) + msg.pack(link)
        link.seq = (link.seq + 1) % 256

    def flight(self, t0_ms: int, seconds: float, rng=None):
        rng = rng or np.random.default_rng(0)
        for i in range(int(seconds * 50)):
            t_ms = t0_ms + 20 * i
            if i % 50 == 0:
                self.put(t_ms * 1000, self.ap.heartbeat_encode(2, 12, 128 | 1, 0, 4))
                self.put(t_ms * 1000, self.gcs.heartbeat_encode(6, 8, 0, 0, 4), self.gcs)
                self.put(t_ms * 1000, self.ap.extended_sys_state_encode(0, 2 if 2 < i / 50 < seconds - 2 else 1))
                self.put(t_ms * 1000, self.ap.sys_status_encode(0, 0, 0, 500, 16000 - i, -1, -1, 0, 0, 0, 0, 0, 0))
                cells = [3950, 3940, 3960, 3955] + [65535] * 6
                self.put(t_ms * 1000, self.ap.battery_status_encode(0, 0, 0, 2500, cells, -1, -1, -1, 80))
                self.put(t_ms * 1000, self.ap.vibration_encode(0 if i % 100 else t_ms * 1000, 0.1, 0.2, 0.3, 0, 0, 0))
            if i % 50 == 25:  # another vehicle, after the autopilot's first HEARTBEAT: never taken for it
                self.put(t_ms * 1000, self.other.heartbeat_encode(2, 12, 128, 0, 4), self.other)
            att = rng.normal(0.0, 0.1, 6)
            self.put(t_ms * 1000, self.ap.attitude_encode(t_ms, *att))
            self.put(t_ms * 1000, self.other.attitude_encode(t_ms, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0), self.other)
            pwm = [int(v) for v in rng.integers(1400, 1600, 4)]
            if i % 37 == 0:
                pwm[i % 4] = 0 if i % 2 else 65535  # unknown outputs
            t_servo = (t_ms * 1000) & 0xFFFFFFFF  # 32 bits: wraps 71.6 min after boot
            self.put(t_ms * 1000, self.ap.servo_output_raw_encode(t_servo, 0, *pwm, 1000, 1000, 1000, 1000))
            if i % 3 == 0:  # outputs 9..16: not motors
                self.put(t_ms * 1000, self.ap.servo_output_raw_encode(t_servo, 1, *pwm, 0, 0, 0, 0))
            self.put(t_ms * 1000, self.ap.local_position_ned_encode(t_ms, 0.0, 0.0, -1.0, *rng.normal(0.0, 1.0, 3)))
            acc = rng.normal(0.0, 1.0, 3) + [0.0, 0.0, -9.8]
            self.put(t_ms * 1000, self.ap.highres_imu_encode(t_ms * 1000, *acc, *[0.0] * 10, 0b111, 0))
            if i % 5 == 0:  # a second IMU: the decoder reads the first only
                self.put(t_ms * 1000, self.ap.highres_imu_encode(t_ms * 1000, 9.0, 9.0, 9.0, *[0.0] * 10, 0b111, 1))
            if i % 2 == 0:  # milli-g, read where HIGHRES_IMU is missing
                mg = [int(v) for v in acc / 9.80665 * 1000.0]
                self.put(t_ms * 1000, self.ap.scaled_imu_encode(t_ms, *mg, 0, 0, 0, 0, 0, 0, 0))

    def write(self, path):
        path.write_bytes(bytes(self.out))
        return path


def test_the_fixture_logs_decode_as_columns_to_the_same_flight(tmp_path, monkeypatch):
    path = write_tlog(tmp_path / "f.tlog", duration_s=30.0, faulty=2)
    raw, used = read_three_ways(path, monkeypatch)
    assert used and len(raw.attitude_rad) == 1500 and len(raw.vel_ned_m_s) == 300


def test_other_systems_unknown_outputs_and_messages_before_the_autopilot_speaks(tmp_path, monkeypatch):
    log = Log()
    # Before the autopilot's first HEARTBEAT: its attitude and outputs are not yet known to be its own.
    log.put(1_000_000, log.ap.attitude_encode(900, 0.5, 0.5, 0.5, 0.0, 0.0, 0.0))
    log.put(1_000_000, log.ap.servo_output_raw_encode(900_000, 0, 1100, 1100, 1100, 1100, 0, 0, 0, 0))
    log.flight(1_000, 40.0)
    raw, used = read_three_ways(log.write(tmp_path / "f.tlog"), monkeypatch)
    assert used
    assert raw.attitude_rad.t_us[0] == 1_000_000 and np.abs(raw.attitude_rad.values).max() < 1.0  # not system 2's
    assert np.isnan(raw.motor_cmd.values).sum() > 0 and raw.battery_v is not None and raw.armed.values.min() == 1.0
    assert len(raw.accel_frd_m_s2) == 2000 and raw.accel_frd_m_s2.values[:, 0].max() < 9.0  # IMU 0's, not IMU 1's


@pytest.mark.parametrize(
    "damage",
    [
        "reboot",  # the boot clock goes back by more than a reboot's jump: two sessions
        "wrap",  # SERVO_OUTPUT_RAW's 32-bit microseconds wrap mid-flight (71.6 min after boot)
        "actuator",  # the autopilot also sends ACTUATOR_OUTPUT_STATUS
    ],
)
def test_what_only_the_decoder_reads_is_left_to_it(tmp_path, monkeypatch, damage):
    log = Log()
    if damage == "reboot":
        log.flight(100_000, 20.0)
        log.flight(1_000, 30.0)
    elif damage == "wrap":
        log.flight((1 << 32) // 1000 - 10_000, 30.0)  # 10 s before the 32-bit clock wraps
    else:
        log.flight(1_000, 20.0)
        log.put(21_000_000, log.ap.actuator_output_status_encode(21_000_000, 15, [1500.0] * 32))
        log.flight(21_100, 10.0)
    raw, used = read_three_ways(log.write(tmp_path / "f.tlog"), monkeypatch)
    assert not used
    if damage == "reboot":
        assert any("rebooted" in w for w in raw.warnings)
    if damage == "wrap":
        assert raw.motor_cmd.t_us[-1] > 1 << 32


@pytest.mark.parametrize("damage", ["none", "cut mid-frame", "trailing bytes", "garbage", "receive clock jump"])
def test_the_numpy_frame_walk_finds_what_the_byte_walk_finds_or_leaves_it(tmp_path, monkeypatch, damage):
    data = bytearray(write_tlog(tmp_path / "f.tlog", duration_s=20.0).read_bytes())
    if damage == "cut mid-frame":
        data = data[: len(data) // 2 + 7]
    elif damage == "trailing bytes":
        data += b"\x00\x01\x02"
    elif damage == "garbage":
        data[len(data) // 3 : len(data) // 3 + 300] = bytes(range(256)) + bytes(44)
    elif damage == "receive clock jump":
        at = len(data) // 2
        at = data.index(bytes([0xFD]), at) - 8  # a record's receive time
        data[at : at + 8] = struct.pack(">Q", 1 << 62)
    buf = bytes(data)
    for wanted in (tlog.CORE_IDS, tlog.WANTED_IDS):
        clean = tlog.clean_frame_starts(buf, wanted)
        with monkeypatch.context() as m:
            m.setattr(tlog, "clean_frame_starts", lambda *args: None)
            starts, skipped, truncated = tlog.frame_starts(buf, wanted)
        if damage == "none":
            assert clean is not None and clean.tolist() == starts and (skipped, truncated) == (0, False)
        elif damage == "receive clock jump":  # followed by frames, the byte walk keeps it; the numpy one leaves it
            assert clean is None and (skipped, truncated) == (0, False)
        else:
            assert clean is None and (skipped or truncated)


def test_the_proposed_chain_is_checked_link_by_link_and_the_walk_gives_the_same_frames(tmp_path, monkeypatch):
    """The numpy chain is proposed from the records' receive times; a proposal holding a payload byte that looks like
    a frame start (every candidate proposed) must fail its check and give the same frames by the record walk."""
    buf = write_tlog(tmp_path / "f.tlog", duration_s=20.0).read_bytes()
    data = np.frombuffer(buf, dtype=np.uint8)
    false_starts = int(np.sum((data[8:] == 0xFD) | (data[8:] == 0xFE))) - len(tlog.clean_frame_starts(buf, range(1 << 24)))
    assert false_starts > 0  # the file has magic bytes inside payloads: the proposal below holds them
    proposed = tlog.clean_frame_starts(buf, tlog.WANTED_IDS)
    calls = []
    real = tlog._chain

    def spy(cand, k, data):
        out = real(cand, k, data)
        calls.append(len(out) < len(cand))
        return out

    monkeypatch.setattr(tlog, "_chain", spy)
    monkeypatch.setattr(tlog, "PROPOSAL_SPAN_US", float("inf"))  # every candidate proposed: the check must refuse it
    walked = tlog.clean_frame_starts(buf, tlog.WANTED_IDS)
    assert calls == [True] and proposed is not None and walked is not None
    assert proposed.tolist() == walked.tolist()
