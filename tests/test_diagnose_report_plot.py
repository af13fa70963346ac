"""The report's drawing helpers: lines broken across landed gaps, yaw unwrapped, empty panels named."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.diagnose.report import broken_at_gaps, unwrap_deg


def test_probability_line_is_broken_across_a_landed_gap():
    t = np.array([10.0, 11.0, 12.0, 40.0, 41.0])  # one window a second, landed from 12 to 40 s
    p = np.arange(20, dtype=float).reshape(5, 4)
    tb, pb = broken_at_gaps(t, p, max_step_s=1.0)
    assert np.isnan(tb[3]) and np.isnan(pb[3]).all()
    assert np.array_equal(tb[~np.isnan(tb)], t) and np.array_equal(pb[~np.isnan(tb)], p)
    same, _ = broken_at_gaps(t[:3], p[:3], max_step_s=1.0)
    assert np.array_equal(same, t[:3])  # nothing inserted without a gap


def test_yaw_is_unwrapped_across_180_and_keeps_gaps():
    yaw = np.deg2rad([170.0, 179.0, -179.0, np.nan, -170.0])  # turning right through 180
    deg = unwrap_deg(yaw)
    assert deg[:3] == pytest.approx([170.0, 179.0, 181.0])
    assert np.isnan(deg[3]) and deg[4] == pytest.approx(190.0)


def test_report_names_empty_panels_not_logged(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from monitor.diagnose import report
    from monitor.diagnose.engine import Diagnosis
    from monitor.flight import FlightTable

    named = []
    original = report._not_logged
    monkeypatch.setattr(report, "_not_logged", lambda ax, what: named.append(what) or original(ax, what))

    n = 200
    t_us = (np.arange(n) * 50_000).astype(np.int64)
    nan = np.full(n, np.nan)
    table = FlightTable(
        source="x.csv",
        rate_hz=20.0,
        timestamp_us=t_us,
        motor_cmd=np.full((n, 4), 1500.0),
        motor_rpm=np.full((n, 4), 7000.0),
        roll_rad=np.zeros(n),
        pitch_rad=nan,
        yaw_rad=np.linspace(-3, 3, n),
        roll_rate_rad_s=nan,
        pitch_rate_rad_s=nan,
        yaw_rate_rad_s=nan,
        battery_v=nan,
        airborne=np.ones(n, bool),
    )
    d = Diagnosis("x.csv", None, 0, [], reason="test")
    page = report.write_report(d, table, tmp_path)
    assert page.is_file() and page.with_suffix(".png").stat().st_size > 10_000
    # No window (no verdict) and no body rate at all: both panels say so; attitude (roll, yaw) is drawn.
    assert named == ["no window classified, so P(faulty)", "body rates"]
