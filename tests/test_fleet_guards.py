"""``fleet ingest`` reads a log through the guards ``propwatch diagnose`` applies (``monitor.logs.guards``), on the
one path of ``monitor.diagnose.engine``: a log that fails a guard is refused with the same message by both."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np

from fleet.worker import IngestSettings, process_log
from monitor.diagnose.cli import main as diagnose

HEADER = (
    "timestamp_us,motor_pwm_us_1,motor_pwm_us_2,motor_pwm_us_3,motor_pwm_us_4,roll_rad,pitch_rad,yaw_rad,"
    "roll_rate_rad_s,pitch_rate_rad_s,yaw_rate_rad_s"
)


def _csv(path, t_us: np.ndarray):
    rows = [",".join(map(str, [t, 1500, 1510, 1520, 1530, 0.1, -0.1, 1.0, 0.01, 0.02, 0.03])) for t in t_us]
    path.write_text("\n".join([HEADER, *rows]) + "\n")
    return path


def _diagnose_error(*argv: str) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert diagnose([*argv, "--format", "propwatch", "--json"]) == 2
    return json.loads(out.getvalue())["error"]


def _fleet_error(path, settings: IngestSettings) -> str:
    row = process_log(str(path), "0" * 64, path.stat().st_size, settings)
    assert row["status"] == "error", row
    return row["error"]


def test_a_log_whose_clock_stands_still_is_refused_alike_by_diagnose_and_fleet(tmp_path):
    log = _csv(tmp_path / "stalled.csv", np.full(3000, 1_000_000))  # 3000 samples, one timestamp
    error = _diagnose_error(str(log))
    assert "stop advancing time" in error
    assert _fleet_error(log, IngestSettings(csv_format="propwatch")) == error


def test_a_log_longer_than_max_seconds_is_refused_alike_by_diagnose_and_fleet(tmp_path):
    log = _csv(tmp_path / "long.csv", 1_000_000 + np.arange(3000) * 10_000)  # 30 s of samples
    error = _diagnose_error(str(log), "--max-seconds", "20")
    assert "spans 30 s, more than --max-seconds 20" in error
    assert _fleet_error(log, IngestSettings(csv_format="propwatch", max_seconds=20.0)) == error
