"""The hidden-effect matrix's scoring of a ``telemetry_delay`` report on our simulator (bench/evalsim_calibration.py):
true where the run's flights drew an attitude log delay of at least the resolution, false below it. No flight is
simulated."""

import json

import pytest

from bench.evalsim_calibration import (
    DELAY_REPORT_RESOLUTION_S,
    NOM,
    OWN_NOMINAL_SEED_BASE,
    _effects,
    _nominal_summary,
    own_attitude_delays_s,
    rescore,
    score_delay_report,
)

DELAY_LINE = "telemetry_delay (+0.0235 s): yaw_accel_rad_s2, held-out RMS 42.1 % of it, held-out BIC gain 105.0 > 80"
SLOW_LINE = (
    "slow_kinematic_error: roll_kin_rad_s correlated over 9.1 samples (> 8; healthy logs about 3), its slow part "
    "0.01 rad/s RMS of 0.02: the logged rates and attitude disagree slowly (coloured noise, a drifting gyro bias or "
    "estimator error)"
)


def run(drawn_ms, summary=None, named=()):
    return {
        "sim": "own",
        "effect": "none",
        "seed": 0,
        "named": list(named),
        "unexplained": summary is not None,
        "unexplained_summary": summary or "none above the gate",
        "rival": [],
        "attitude_log_delay_ms": drawn_ms,
    }


def test_a_delay_report_is_true_where_a_flight_carries_the_delay_and_false_where_none_does():
    res_ms = 1000 * DELAY_REPORT_RESOLUTION_S
    assert score_delay_report(run([24.6, 21.6], DELAY_LINE)) is True
    # One flight of the pair at the resolution is enough: the delay is in the flights the run calibrated.
    assert score_delay_report(run([res_ms, 2.0], f"{SLOW_LINE}; {DELAY_LINE}")) is True
    assert score_delay_report(run([0.7, 14.4], DELAY_LINE)) is False
    assert score_delay_report(run([res_ms - 0.1, res_ms - 0.1], DELAY_LINE)) is False
    # The resolution is the scorer's argument: the same run flips with it.
    assert score_delay_report(run([14.4, 0.7], DELAY_LINE), resolution_s=0.010) is True


def test_no_score_without_a_delay_report_or_without_the_drawn_delay():
    assert score_delay_report(run([29.0, 25.0])) is None
    assert score_delay_report(run([29.0, 25.0], SLOW_LINE)) is None
    evalsim = run([], DELAY_LINE) | {"sim": "evalsim"}
    del evalsim["attitude_log_delay_ms"]
    assert score_delay_report(evalsim) is None


def test_nothing_hidden_separates_a_named_cause_from_the_delay_the_flights_carry():
    rows = [
        run([24.6, 21.6], named=["motor_time_constant"]),
        run([24.6, 21.6], DELAY_LINE),
        run([28.9, 25.9], DELAY_LINE),
        run([0.7, 14.4], DELAY_LINE),
        run([0.7, 14.4]),
    ]
    s = _nominal_summary(rows)
    assert (s["runs"], s["wrong_named"], s["unexplained"]) == (5, 1, 3)
    assert (s["delay_true"], s["delay_false"]) == (2, 1)


def test_rescore_gives_each_own_run_the_delay_its_flights_drew(tmp_path):
    rows = [
        run([]) | {"seed": 2},
        {**run([]), "effect": "mass", "size": 0.05, "seed": 1},
        {**run([]), "sim": "evalsim", "seed": 3},
    ]
    for r in rows:
        del r["attitude_log_delay_ms"]
    path = tmp_path / "runs.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows), encoding="utf-8")
    nominal, mass, evalsim = rescore([path], _effects())
    # The nothing-hidden runs fly own_tables(NOM, OWN_NOMINAL_SEED_BASE + seed); a cell's run its own seed.
    assert nominal["attitude_log_delay_ms"] == pytest.approx(
        [1000 * d for d in own_attitude_delays_s(NOM, OWN_NOMINAL_SEED_BASE + 2)], abs=0.01
    )
    assert mass["attitude_log_delay_ms"] == pytest.approx([1000 * d for d in own_attitude_delays_s(NOM, 1)], abs=0.01)
    assert nominal["attitude_log_delay_ms"] != mass["attitude_log_delay_ms"]
    assert all(0.0 <= d <= 30.0 for d in nominal["attitude_log_delay_ms"] + mass["attitude_log_delay_ms"])
    assert "attitude_log_delay_ms" not in evalsim


def test_a_cell_with_no_runs_gives_no_resolution():
    from bench.evalsim_calibration import summarise

    effects = _effects()
    name = next(iter(effects))
    res = summarise([], {name: effects[name]}, [], {})
    assert res["own"][name]["resolution"] is None  # an empty cell names nothing, not "every run"
    assert all(c["runs"] == 0 for c in res["own"][name]["cells"])
