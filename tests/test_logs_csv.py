"""CSV logs through named mappings; CrazyPAD read through its mapping (facts from its README)."""

from __future__ import annotations

import csv
import gzip
import io
from pathlib import Path

import numpy as np
import pytest

from monitor.errors import ConfigError, LogFormatError
from monitor.logs import read_log, read_raw
from monitor.logs.csvlog import load_formats

CRAZYPAD = Path(__file__).resolve().parents[2] / "shared" / "data" / "crazypad"
needs_crazypad = pytest.mark.skipif(not CRAZYPAD.is_dir(), reason=f"CrazyPAD data not found at {CRAZYPAD}")
HEALTHY = CRAZYPAD / "motor" / "normal_flight" / "E8_log00.csv.gz"


def _columns(path: Path) -> dict[str, np.ndarray]:
    rows = list(csv.reader(io.StringIO(gzip.decompress(path.read_bytes()).decode())))
    return {h: np.array([float(r[i]) for r in rows[1:]]) for i, h in enumerate(rows[0])}


@pytest.mark.realdata
@needs_crazypad
def test_crazypad_motors_map_to_px4_order_and_units():
    table = read_log(HEALTHY, fmt="crazypad")
    assert table.motor_names == ("M1", "M3", "M4", "M2")
    cols = _columns(HEALTHY)
    t_us = np.round(cols["t_ms"] * 1000).astype(np.int64)
    idx = np.searchsorted(t_us, table.timestamp_us, side="right") - 1
    ok = idx >= 0
    for j, m in enumerate(("motor.m1", "motor.m3", "motor.m4", "motor.m2")):
        np.testing.assert_array_equal(table.motor_cmd[ok, j], cols[m][idx[ok]])
        np.testing.assert_array_equal(table.extras["motor_cmd_applied"][ok, j], cols[f"pwm.m{m[-1]}_pwm"][idx[ok]])
    np.testing.assert_allclose(table.roll_rad[ok], np.deg2rad(cols["stateEstimate.roll"][idx[ok]]))
    np.testing.assert_allclose(table.yaw_rad[ok], -np.deg2rad(cols["stateEstimate.yaw"][idx[ok]]))  # CCW-up -> CW-down
    assert np.isnan(table.pitch_rad).all() and np.isnan(table.roll_rate_rad_s).all()  # not logged in this config
    assert any("pitch is not logged" in w for w in table.warnings)
    np.testing.assert_allclose(table.battery_v[ok], cols["pm.vbatMV"][idx[ok]] / 1000.0)


@pytest.mark.realdata
@needs_crazypad
def test_crazypad_airborne_time_matches_readme():
    # README: each log ~25.7 s, airborne (z > 0.25 m) for about 15.5 s; motors 0 before take-off and after landing.
    for path in sorted((CRAZYPAD / "motor" / "normal_flight").glob("*.csv.gz"))[:4]:
        table = read_log(path, fmt="crazypad")
        airborne_s = table.airborne.sum() / table.rate_hz
        assert 13.5 < airborne_s < 17.5, (path.name, airborne_s)
        assert np.all(table.motor_cmd[table.airborne].mean(axis=1) > 0.15 * 65535)


@pytest.mark.realdata
@needs_crazypad
def test_crazypad_quirky_files():
    # README: 3 files under motor/cut_propeller_M3_2mm/E9_log0* use the controller config.
    quirky = CRAZYPAD / "motor" / "cut_propeller_M3_2mm" / "E9_log00.csv.gz"
    with pytest.raises(LogFormatError, match="crazypad-controller"):
        read_raw(quirky, "crazypad")
    assert np.isfinite(read_raw(quirky, "crazypad-controller").rates_rad_s.values).all()
    # README: 6 motor files (cut_propeller_M3_2mm/E8_*) have no yaw column.
    no_yaw = read_log(CRAZYPAD / "motor" / "cut_propeller_M3_2mm" / "E8_log00.csv.gz", fmt="crazypad")
    assert np.isnan(no_yaw.yaw_rad).all() and any("stateEstimate.yaw" in w for w in no_yaw.warnings)


@pytest.mark.realdata
@needs_crazypad
def test_truncated_gzip_is_read_up_to_the_damage(tmp_path):
    data = HEALTHY.read_bytes()
    cut = tmp_path / "cut.csv.gz"
    cut.write_bytes(data[: len(data) // 2])
    full, part = read_raw(HEALTHY, "crazypad"), read_raw(cut, "crazypad")
    assert any("gzip stream ends early" in w for w in part.warnings)
    n = len(part.motor_cmd)
    assert 0.3 * len(full.motor_cmd) < n < 0.7 * len(full.motor_cmd)
    np.testing.assert_array_equal(part.motor_cmd.values, full.motor_cmd.values[:n])


def test_propwatch_csv_round_trip(tmp_path):
    n = 400
    t = 1_000_000 + np.arange(n) * 10_000
    pwm = np.column_stack([np.full(n, 1500.0 + 10 * k) for k in range(4)])
    header = (
        "timestamp_us,motor_pwm_us_1,motor_pwm_us_2,motor_pwm_us_3,motor_pwm_us_4,roll_rad,pitch_rad,yaw_rad,"
        "roll_rate_rad_s,pitch_rate_rad_s,yaw_rate_rad_s"
    )
    lines = [header] + [",".join(map(str, [t[i], *pwm[i], 0.1, -0.1, 1.0, 0.01, 0.02, 0.03])) for i in range(n)]
    lines.append("123,1500")  # a cut-off last line
    path = tmp_path / "f.csv"
    path.write_text("\n".join(lines))
    table = read_log(path, fmt="propwatch")
    assert table.timestamp_us[0] == 1_000_000 and len(table) == 80
    np.testing.assert_array_equal(table.motor_cmd[5], [1500.0, 1510.0, 1520.0, 1530.0])
    assert table.pitch_rad[3] == pytest.approx(-0.1) and table.yaw_rate_rad_s[3] == pytest.approx(0.03)
    assert any("malformed row" in w for w in table.warnings)
    with pytest.raises(LogFormatError, match="unknown CSV format"):
        read_raw(path, "no-such-format")
    with pytest.raises(LogFormatError, match="--format"):
        read_raw(path)


def test_format_file_rejects_unknown_keys(tmp_path):
    bad = tmp_path / "formats.yaml"
    bad.write_text(
        "x:\n  description: d\n  time: {column: t, unit: ms}\n  cmd_unit: us\n  motors: [a, b, c, d]\n"
        "  motor_names: ['1', '2', '3', '4']\n  roll: {column: r, unit: deg}\n  pitch: {column: p, unit: deg}\n"
        "  yaw: {column: y, unit: deg}\n  roll_rate: {column: null}\n  pitch_rate: {column: null}\n"
        "  yaw_rate: {column: null}\n  hieght: {column: z, unit: m}\n"
    )
    with pytest.raises(ConfigError, match="hieght"):
        load_formats(bad)
    assert {"crazypad", "crazypad-controller", "propwatch"} <= set(load_formats())
