"""The report's drawing helpers: lines broken across landed gaps, yaw unwrapped, empty panels named."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.diagnose import report
from monitor.diagnose.report import broken_at_gaps


def test_probability_line_is_broken_across_a_landed_gap():
    t = np.array([10.0, 11.0, 12.0, 40.0, 41.0])  # one window a second, landed from 12 to 40 s
    p = np.arange(20, dtype=float).reshape(5, 4)
    tb, pb = broken_at_gaps(t, p, max_step_s=1.0)
    assert np.isnan(tb[3]) and np.isnan(pb[3]).all()
    assert np.array_equal(tb[~np.isnan(tb)], t) and np.array_equal(pb[~np.isnan(tb)], p)
    same, _ = broken_at_gaps(t[:3], p[:3], max_step_s=1.0)
    assert np.array_equal(same, t[:3])  # nothing inserted without a gap


def test_thrust_share_band_is_the_flights_own_start_and_a_later_loss_leaves_it():
    from monitor.flight import FlightTable

    n = 20 * 40  # 40 s at 20 Hz, airborne throughout; rotor 3 spins 10 % faster from 25 s (a lost piece of blade)
    rpm = np.full((n, 4), 7000.0)
    rpm[500:, 2] *= 1.10
    nan = np.full(n, np.nan)
    table = FlightTable(
        source="x",
        rate_hz=20.0,
        timestamp_us=(np.arange(n) * 50_000).astype(np.int64),
        motor_cmd=rpm,
        motor_rpm=rpm,
        roll_rad=nan,
        pitch_rad=nan,
        yaw_rad=nan,
        roll_rate_rad_s=nan,
        pitch_rate_rad_s=nan,
        yaw_rate_rad_s=nan,
        battery_v=nan,
        airborne=np.ones(n, bool),
    )
    share, band = report.thrust_shares(table)
    assert np.allclose(np.nansum(share, axis=1)[60:], 1.0)  # shares of one total
    assert band[:, 0] == pytest.approx(0.25 - report.SHARE_BAND) and band[:, 1] == pytest.approx(0.25 + report.SHARE_BAND)
    assert np.isnan(share[:39]).all()  # the 2-s mean needs 2 s of flight
    assert band[2, 0] <= share[400, 2] <= band[2, 1] and share[-1, 2] > band[2, 1]  # rotor 3 leaves its band
    short = FlightTable(**{**table.__dict__, "airborne": np.arange(n) < 150})  # 7.5 s airborne: no band to learn
    assert report.thrust_shares(short)[1] is None


def test_report_names_empty_panels_not_logged(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from monitor.diagnose.engine import Diagnosis
    from monitor.flight import FlightTable

    named = []
    original = report._not_logged
    monkeypatch.setattr(report, "_not_logged", lambda ax, what, *why: named.append(what) or original(ax, what, *why))

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
    # No window (no verdict): the classifier's panel says so; shares, motor outputs and attitude (roll) are drawn.
    assert named == ["no stretch of flight classified, so the classifier's probability"]


def test_the_share_band_follows_the_vehicle_memory_where_it_compared_the_flight():
    share = np.tile([0.30, 0.25, 0.25, 0.20], (50, 1))  # rotor 1 works 5 points harder than rotor 4
    # the memory: rotor 1 is 0.2 (shares summing to 4) above its normal, 4 of its healthy spreads
    memory = {"deviation": [0.2, 0.0, 0.0, -0.2], "deviation_sigma": [4.0, 0.0, 0.0, -4.0]}
    band = report.memory_band(share, memory)
    assert band is None  # a rotor exactly at its normal says nothing of its spread: no band rather than a guess
    memory["deviation_sigma"] = [4.0, 1.0, -1.0, -4.0]
    memory["deviation"] = [0.2, 0.04, -0.04, -0.2]
    band = report.memory_band(share, memory)
    centre, half = band.mean(axis=1), (band[:, 1] - band[:, 0]) / 2
    np.testing.assert_allclose(centre, [0.25, 0.24, 0.26, 0.25])  # the flight's share less its deviation
    np.testing.assert_allclose(half, [3 * 0.0125, 3 * 0.01, 3 * 0.01, 3 * 0.0125])  # 3 spreads
    assert not band[0, 0] <= share[0, 0] <= band[0, 1]  # rotor 1 is outside its normal, as the memory said
    assert report.memory_band(share, None) is None and report.memory_band(share, {"note": "no baseline yet"}) is None


def _table(airborne: np.ndarray):
    from monitor.flight import FlightTable

    n = len(airborne)
    return FlightTable(
        source="x.csv",
        rate_hz=20.0,
        timestamp_us=(np.arange(n) * 50_000).astype(np.int64),
        motor_cmd=np.full((n, 4), 1500.0),
        motor_rpm=np.full((n, 4), 7000.0),
        roll_rad=np.zeros(n),
        pitch_rad=np.zeros(n),
        yaw_rad=np.zeros(n),
        roll_rate_rad_s=np.zeros(n),
        pitch_rate_rad_s=np.zeros(n),
        yaw_rate_rad_s=np.zeros(n),
        battery_v=np.full(n, 16.0),
        airborne=airborne,
    )


def test_a_flight_airborne_for_a_second_is_not_called_never_airborne(monkeypatch):
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from monitor.diagnose.engine import Diagnosis
    from monitor.diagnose.verdict import verdict_of

    named = []
    original = report._not_logged
    monkeypatch.setattr(report, "_not_logged", lambda ax, what, *why: named.append(what) or original(ax, what, *why))
    airborne = np.zeros(200, bool)
    airborne[20:36] = True  # 0.8 s: less than one 2-s mean
    d = Diagnosis("x.csv", None, 0, [], reason="test")
    plt.close(report.figure(verdict_of(d.to_json()), d, _table(airborne)))
    assert "airborne too briefly for a 2-s mean: the share" in named and not any("never airborne" in w for w in named)


def test_the_next_step_is_never_drawn_over_the_first_panels_caption():
    pytest.importorskip("matplotlib")
    import dataclasses

    import matplotlib.pyplot as plt

    from monitor.diagnose.engine import Diagnosis
    from monitor.diagnose.verdict import verdict_of

    d = Diagnosis("x.csv", None, 0, [], reason="test")
    v = verdict_of(d.to_json())
    for words in (1, 30, 60):  # one, two and three lines of next step
        long = dataclasses.replace(v, headline="Propeller 3 (front-left) " * 6, next_step="inspect it " * words)
        fig = report.figure(long, d, _table(np.ones(400, bool)))
        fig.canvas.draw()
        r = fig.canvas.get_renderer()
        nxt = next(t for t in fig.texts if t.get_gid() == "verdict-next").get_window_extent(r)
        head = fig._suptitle.get_window_extent(r)
        caption = fig.axes[0].title.get_window_extent(r)
        plt.close(fig)
        assert nxt.y0 > caption.y1 and head.y0 > nxt.y1, (words, nxt, caption, head)
