"""Config files and diagnose inputs from the hardening table: every one ends in a clear line and its exit code.

Seeded random bytes, non-finite and huge numbers for every numeric config
key, zeros behind a valid log header, a damaged DataFlash file under
``--json``, a log whose time stops advancing, and the ``--max-seconds`` guard.
"""

from __future__ import annotations

import dataclasses
import json
import struct
import typing
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink
from test_daemon_helpers import synth_flight, write_tlog

from monitor.cli import main as propwatch
from monitor.daemon.config import MonitorConfig, monitor_config_from_mapping
from monitor.errors import ConfigError
from monitor.logs.guards import MAX_GARBAGE_BYTES

REPO = Path(__file__).resolve().parent.parent
MODEL = REPO / "models" / "classifier.onnx"
needs_model = pytest.mark.skipif(not MODEL.is_file(), reason="models/classifier.onnx not built")


# --- config ------------------------------------------------------------------------------


def numeric_keys(cls=MonitorConfig, prefix=""):
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            yield from numeric_keys(tp, f"{prefix}{f.name}.")
        elif tp in (int, float):
            yield f"{prefix}{f.name}", tp


def nested(key: str, value) -> dict:
    out: dict = value
    for part in reversed(key.split(".")):
        out = {part: out}
    return out


@pytest.mark.parametrize("key,tp", list(numeric_keys()))
def test_every_numeric_config_key_has_finite_bounds(key, tp):
    for value in [float("inf"), float("-inf"), 1e300, -1e300] if tp is float else [10**12, -(10**12)]:
        with pytest.raises(ConfigError, match=key.split(".")[-1]):
            monitor_config_from_mapping(nested(key, value))


@pytest.mark.parametrize("seed", range(4))
def test_config_of_random_bytes_is_one_line_naming_the_file(tmp_path, capsys, seed):
    p = tmp_path / "monitor.yaml"
    p.write_bytes(np.random.default_rng(seed).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    rc = propwatch(["monitor", "--connect", "udpin:127.0.0.1:9", "--config", str(p)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and str(p) in err and len(err.splitlines()) == 1 and "Traceback" not in err, err


@pytest.mark.parametrize(
    "text,expect",
    [
        ("- 1\n- 2\n", "top level must be a mapping"),
        ("resample:\n  max_gap_s: .inf\n", "resample.max_gap_s"),
        ("link:\n  heartbeat_rate_hz: .inf\n", "link.heartbeat_rate_hz"),
        ("link:\n  stream_rate_hz: .inf\n", "link.stream_rate_hz"),
        ("alerts:\n  statustext_min_interval_s: .inf\n", "alerts.statustext_min_interval_s"),
        ("alerts:\n  false_alarms_per_hour: 99999999999999999999999\n", "alerts.false_alarms_per_hour"),
        ("alerts:\n  rule: consecutive\n", "use 'sequential' (the default)"),
        ("alerts:\n  refractory_s: 30.0\n", "alerts.refractory_s: a key of the consecutive rule"),
    ],
)
def test_config_the_table_named(tmp_path, capsys, text, expect):
    p = tmp_path / "monitor.yaml"
    p.write_text(text)
    rc = propwatch(["monitor", "--connect", "udpin:127.0.0.1:9", "--config", str(p)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and expect in err and str(p) in err and len(err.splitlines()) == 1, err


# --- diagnose ------------------------------------------------------------------------------


def diagnose(capsys, *args) -> tuple[int, object, str]:
    rc = propwatch(["diagnose", *map(str, args), "--json"])
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err
    return rc, json.loads(cap.out), cap.err  # stdout is JSON and nothing else


def dataflash_head() -> bytes:
    """One DataFlash FMT message (the format of FMT itself): what every .bin starts with."""
    payload = struct.pack("<BB4s16s64s", 128, 89, b"FMT", b"BBnNZ", b"Type,Length,Name,Format,Columns")
    return b"\xa3\x95\x80" + payload


@needs_model
@pytest.mark.parametrize("seed", range(2))
def test_crazypad_format_on_random_bytes_exits_2(tmp_path, capsys, seed):
    p = tmp_path / "E1_log00.csv"
    p.write_bytes(np.random.default_rng(seed).integers(0, 256, 20_000, dtype=np.uint8).tobytes())
    rc, out, err = diagnose(capsys, p, "--format", "crazypad")
    assert rc == 2 and "error" in out and str(p) in out["error"]


@needs_model
@pytest.mark.parametrize("header", ["tlog", "dataflash"])
def test_zeros_behind_a_valid_header_are_refused_quickly(tmp_path, capsys, header):
    p = tmp_path / ("zeros.tlog" if header == "tlog" else "zeros.bin")
    if header == "tlog":
        head = write_tlog(tmp_path / "head.tlog", synth_flight(1.0)).read_bytes()[:3000]
    else:
        head = dataflash_head()
    p.write_bytes(head + bytes(MAX_GARBAGE_BYTES + 1_000_000))
    rc, out, _ = diagnose(capsys, p)
    assert rc == 2 and "without any" in out["error"] and "message" in out["error"]


@needs_model
def test_malformed_dataflash_under_json_keeps_stdout_json_only(tmp_path, capsys):
    p = tmp_path / "bad.bin"
    rng = np.random.default_rng(7)
    p.write_bytes(dataflash_head() + rng.integers(0, 256, 30_000, dtype=np.uint8).tobytes())
    rc, out, err = diagnose(capsys, p)
    assert rc == 2 and "error" in out  # and json.loads above proved stdout held only JSON


@needs_model
def test_a_log_whose_time_stops_advancing_is_refused(tmp_path, capsys):
    ap = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = [(1.7e9, mavlink.MAVLink_heartbeat_message(2, 12, 129, 0, 4, 3).pack(ap))]
    for k in range(3000):
        t = 1.7e9 + 1 + k * 1e-4
        frames.append((t, mavlink.MAVLink_attitude_message(5000, 0.01, 0.0, 0.3, 0.0, 0.0, 0.0).pack(ap)))
        frames.append((t, mavlink.MAVLink_servo_output_raw_message(5_000_000, 0, *[1450] * 8).pack(ap)))
    p = write_tlog(tmp_path / "stuck.tlog", frames)
    rc, out, _ = diagnose(capsys, p)
    assert rc == 2 and "stop advancing time" in out["error"]


@needs_model
def test_max_seconds_bounds_the_log_span(tmp_path, capsys):
    p = write_tlog(tmp_path / "f.tlog", synth_flight(12.0, seed=1))
    rc, out, _ = diagnose(capsys, p, "--max-seconds", "5")
    assert rc == 2 and "--max-seconds" in out["error"]
    rc, out, _ = diagnose(capsys, p, "--max-seconds", "60")
    assert rc in (0, 1, 3) and "error" not in out  # a verdict: healthy, faulty or ambiguous, not an error
