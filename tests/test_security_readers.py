"""Readers stream: a 200 MB tail of zeros behind a real log costs what the log costs (docs/SECURITY.md).

Each read runs in a child process (its own peak memory); the tail is a sparse extension of the file, so the
test writes no 200 MB. A reader that walked or held the tail would take minutes or a gigabyte: the child's
timeout and its peak RSS catch both.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_logs_ulog import write_ulog

from monitor.logs import read_log

TAIL_BYTES = 200 * 1024 * 1024
CHILD = """
import json, resource, sys
from monitor.logs import read_log
t = read_log(sys.argv[1], fmt=sys.argv[2] or None)
rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"rows": len(t), "warnings": t.warnings, "rss_mb": rss_mb}))
"""
BASELINE = """
import json, resource
import monitor.logs, numpy, pyulog
print(json.dumps({"rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def _child(code: str, *args: str) -> dict:
    r = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def _zero_tail(src: Path, dst: Path) -> Path:
    dst.write_bytes(src.read_bytes())
    with open(dst, "r+b") as fh:
        fh.truncate(dst.stat().st_size + TAIL_BYTES)  # sparse zeros
    return dst


def _csv(path: Path) -> Path:
    n = 2000
    t = 1_000_000 + np.arange(n) * 10_000
    header = (
        "timestamp_us,motor_pwm_us_1,motor_pwm_us_2,motor_pwm_us_3,motor_pwm_us_4,roll_rad,pitch_rad,yaw_rad,"
        "roll_rate_rad_s,pitch_rate_rad_s,yaw_rate_rad_s"
    )
    rows = [",".join(map(str, [t[i], 1500, 1510, 1520, 1530, 0.1, -0.1, 1.0, 0.01, 0.02, 0.03])) for i in range(n)]
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


@pytest.mark.parametrize("kind", ["ulog", "csv"])
def test_a_200_mb_zero_tail_is_cut_with_a_warning_at_the_cost_of_the_log_itself(tmp_path, kind):
    if kind == "ulog":
        clean, _ = write_ulog(tmp_path / "clean.ulg")
        fmt = ""
    else:
        clean, fmt = _csv(tmp_path / "clean.csv"), "propwatch"
    tailed = _zero_tail(Path(clean), tmp_path / f"tailed{Path(clean).suffix}")
    got = _child(CHILD, str(tailed), fmt)
    assert got["rows"] == len(read_log(clean, fmt=fmt or None)) > 0  # the same flight as without the tail
    assert any("zeros or junk" in w for w in got["warnings"]), got["warnings"]
    # Memory: what importing the readers costs, plus the log (a few MB), never the 200 MB tail.
    base = _child(BASELINE)["rss_mb"]
    assert got["rss_mb"] < base + 60, (got["rss_mb"], base)


def test_junk_after_a_ulog_is_cut_but_a_newer_message_type_between_known_ones_is_kept(tmp_path):
    clean, _ = write_ulog(tmp_path / "clean.ulg", duration_s=5.0)
    data = Path(clean).read_bytes()
    junk = tmp_path / "junk.ulg"
    junk.write_bytes(data + np.random.default_rng(1).integers(0, 256, 300_000, dtype=np.uint8).tobytes())
    t = read_log(junk)
    assert len(t) == len(read_log(clean)) and any("zeros or junk" in w for w in t.warnings)
    newer = tmp_path / "newer.ulg"  # an unknown type 'Z' (3 payload bytes) followed by the real messages
    head = 16
    newer.write_bytes(data[:head] + b"\x03\x00Z" + b"abc" + data[head:])
    t = read_log(newer)
    assert len(t) == len(read_log(clean)) and not any("zeros or junk" in w for w in t.warnings)


def test_nan_timestamps_are_named_not_read_as_a_span_of_billions_of_seconds(tmp_path):
    from types import SimpleNamespace

    from monitor.errors import LogFormatError
    from monitor.logs.guards import check_time_advances

    t = np.arange(2000, dtype=np.float64) * 10_000.0
    t[100:110] = np.nan  # a stream's times as a reader hands them over (``t_us``)
    with pytest.raises(LogFormatError, match=r"attitude: 10 of 2000 timestamps are not numbers"):
        check_time_advances({"attitude": SimpleNamespace(t_us=t)}, tmp_path / "f.csv")
