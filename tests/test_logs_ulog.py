"""The ULog reader, on ULog files written here byte by byte (the format is documented
in PX4's "ULog File Format" page; pyulog ships no writer)."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from monitor.errors import LogFormatError
from monitor.esc import PAPER_ESC
from monitor.logs import detect_format, read_log

TYPES = {"uint64_t": "Q", "uint32_t": "I", "uint8_t": "B", "float": "f", "bool": "?"}


def _msg(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


class ULogWriter:
    """Header, flag bits, then every format (F), then subscriptions (A) and data (D):
    pyulog ends the definitions section at the first A."""

    def __init__(self):
        self.head = bytearray(b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0))
        self.head += _msg(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
        self.defs, self.body = bytearray(), bytearray()
        self.topics: dict[tuple[str, int], tuple[int, str]] = {}

    def topic(self, name: str, fields: list[tuple[str, str]], multi_id: int = 0) -> None:
        spec = "".join(f"{t} {n};" for t, n in fields)
        fmt = "<" + "".join(TYPES[t.split("[")[0]] * (int(t.split("[")[1][:-1]) if "[" in t else 1) for t, _ in fields)
        if all(n != name for n, _ in self.topics):
            self.defs += _msg(b"F", f"{name}:{spec}".encode())
        msg_id = len(self.topics)
        self.topics[(name, multi_id)] = (msg_id, fmt)
        self.body += _msg(b"A", struct.pack("<BH", multi_id, msg_id) + name.encode())

    def data(self, name: str, *values, multi_id: int = 0) -> None:
        msg_id, fmt = self.topics[(name, multi_id)]
        self.body += _msg(b"D", struct.pack("<H", msg_id) + struct.pack(fmt, *values))

    def bytes(self) -> bytes:
        return bytes(self.head + self.defs + self.body)


def quat_from_euler(roll, pitch, yaw):
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll / 2),
        math.sin(roll / 2),
        math.cos(pitch / 2),
        math.sin(pitch / 2),
        math.cos(yaw / 2),
        math.sin(yaw / 2),
    )
    return (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)


def write_ulog(path, duration_s=20.0, rate_hz=50.0, faulty=None, with_attitude=True, old_px4=False):
    w = ULogWriter()
    w.topic("actuator_outputs", [("uint64_t", "timestamp"), ("uint32_t", "noutputs"), ("float[16]", "output")])
    w.topic("actuator_outputs", [("uint64_t", "timestamp"), ("uint32_t", "noutputs"), ("float[16]", "output")], multi_id=1)
    if with_attitude:
        w.topic(
            "vehicle_attitude",
            [("uint64_t", "timestamp"), ("float[4]", "q")]
            + ([("float", "rollspeed"), ("float", "pitchspeed"), ("float", "yawspeed")] if old_px4 else []),
        )
    if not old_px4:
        w.topic("vehicle_angular_velocity", [("uint64_t", "timestamp"), ("float[3]", "xyz")])
    w.topic("vehicle_status", [("uint64_t", "timestamp"), ("uint8_t", "arming_state")])
    w.topic("vehicle_land_detected", [("uint64_t", "timestamp"), ("bool", "landed")])
    w.topic("battery_status", [("uint64_t", "timestamp"), ("float", "voltage_v")])
    n = int(duration_s * rate_hz)
    expect = {"t": [], "pwm": [], "euler": []}
    for i in range(n):
        t = 1_000_000 + int(i * 1e6 / rate_hz)
        s = (t - 1_000_000) / 1e6
        flying = 2.0 <= s < duration_s - 2.0
        pwm = [1500.0 + 10 * k + (60.0 if faulty == k + 1 else 0.0) if flying else 1000.0 for k in range(4)]
        w.data("actuator_outputs", t, 8, *(pwm + [900.0] * 12))
        w.data("actuator_outputs", t, 8, *([1234.0] * 16), multi_id=1)  # aux outputs: must not be read
        e = (0.1 * math.sin(s), -0.05 * math.cos(s), 2.5 * math.sin(0.3 * s))
        if with_attitude:
            w.data("vehicle_attitude", t, *quat_from_euler(*e), *((0.01, -0.02, 0.03) if old_px4 else ()))
        if not old_px4:
            w.data("vehicle_angular_velocity", t, 0.01, -0.02, 0.03)
        if i % int(rate_hz) == 0:
            w.data("vehicle_status", t, 2)
            w.data("vehicle_land_detected", t, not flying)
            w.data("battery_status", t, 15.5)
        expect["t"].append(t)
        expect["pwm"].append(pwm)
        expect["euler"].append(e)
    path.write_bytes(w.bytes())
    return path, {k: np.array(v) for k, v in expect.items()}


def test_ulog_round_trip(tmp_path):
    pytest.importorskip("pyulog")
    path, ex = write_ulog(tmp_path / "f.ulg")
    assert detect_format(path) == "ulog"
    table = read_log(path, esc=PAPER_ESC)
    idx = np.searchsorted(ex["t"], table.timestamp_us, side="right") - 1
    np.testing.assert_allclose(table.motor_cmd, ex["pwm"][idx])  # instance 0, outputs 1..4
    np.testing.assert_allclose(table.roll_rad, ex["euler"][idx, 0], atol=1e-5)
    np.testing.assert_allclose(table.pitch_rad, ex["euler"][idx, 1], atol=1e-5)
    np.testing.assert_allclose(table.yaw_rad, ex["euler"][idx, 2], atol=1e-5)
    np.testing.assert_allclose(table.pitch_rate_rad_s, -0.02, atol=1e-7)
    assert table.battery_v[len(table) // 2] == pytest.approx(15.5)
    seg = table.airborne_segments()
    assert len(seg) == 1 and abs((seg[0][1] - seg[0][0]) / 20.0 - 16.0) <= 1.05


def test_ulog_without_attitude_is_a_clear_error(tmp_path):
    pytest.importorskip("pyulog")
    path, _ = write_ulog(tmp_path / "f.ulg", duration_s=5.0, with_attitude=False)
    with pytest.raises(LogFormatError, match="vehicle_attitude"):
        read_log(path, esc=PAPER_ESC)


def test_truncated_ulog_reads_up_to_the_cut(tmp_path):
    pytest.importorskip("pyulog")
    path, ex = write_ulog(tmp_path / "f.ulg")
    data = path.read_bytes()
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(data[: int(len(data) * 0.6) + 3])
    table = read_log(cut, esc=PAPER_ESC)
    assert any("truncated" in w for w in table.warnings)
    assert not any("truncated" in w for w in read_log(path, esc=PAPER_ESC).warnings)
    span_s = (table.timestamp_us[-1] - table.timestamp_us[0]) / 1e6
    assert 0.5 * 20 < span_s < 0.7 * 20


def test_old_px4_rates_from_vehicle_attitude(tmp_path):
    pytest.importorskip("pyulog")
    path, ex = write_ulog(tmp_path / "old.ulg", duration_s=8.0, old_px4=True)
    table = read_log(path, esc=PAPER_ESC)
    np.testing.assert_allclose(table.pitch_rate_rad_s, -0.02, atol=1e-7)
    np.testing.assert_allclose(table.yaw_rate_rad_s, 0.03, atol=1e-7)
    assert any("before v1.11" in w for w in table.warnings)
