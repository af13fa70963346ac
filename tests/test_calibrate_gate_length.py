"""The held-out gain gate scales with the log's length: MIN_DELTA_BIC per GATE_HELDOUT_S of held-out log, never
below MIN_DELTA_BIC. An effect the flights carry and the vehicle file lacks gains in proportion to the log's length,
so a fixed gate set on 2 x 40 s flights names it on longer ones (docs/CALIBRATION.md, "The gain gate and the log's
length")."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.calibrate.fit import (
    GATE_HELDOUT_S,
    MIN_DELTA_BIC,
    Data,
    GateCheck,
    Step,
    TermFit,
    Verdict,
    gain_threshold,
    gate_checks,
)
from offline.calibrate.nominal_flights import fixed_flights
from offline.calibrate.prepare import prepare

NOM = load_vehicle(DEFAULT_VEHICLE)
DT_S = 0.05


def _data(heldout_s: float) -> Data:
    """One 20 Hz stand-in segment whose held-out blocks hold ``heldout_s`` seconds, and a residual signal."""
    n = int(round(2 * heldout_s / DT_S))
    held = np.arange(n) % 2 == 1
    return Data([SimpleNamespace(dt_s=DT_S)], [~held], [held], {"roll_accel_rad_s2": 1.0})


def test_the_gate_is_min_delta_bic_per_40_s_of_heldout_log_and_never_below_it():
    assert gain_threshold(_data(10.0)) == MIN_DELTA_BIC
    assert gain_threshold(_data(GATE_HELDOUT_S)) == pytest.approx(MIN_DELTA_BIC)
    assert gain_threshold(_data(75.0)) == pytest.approx(MIN_DELTA_BIC * 75.0 / GATE_HELDOUT_S)
    assert gain_threshold(_data(2 * GATE_HELDOUT_S)) == pytest.approx(2 * MIN_DELTA_BIC)


def test_a_gain_that_clears_the_gate_on_a_40_s_log_does_not_on_an_80_s_log():
    """A candidate with a held-out gain of 100 and no signal worse: named on 35 s of held-out log (2 x 40-s
    flights), not on 75 s (2 x 80 s), where the gate is 150."""
    rng = np.random.default_rng(0)
    for heldout_s, passes in ((35.0, True), (75.0, False)):
        data = _data(heldout_s)
        res = [{"roll_accel_rad_s2": rng.normal(size=len(data.held_masks[0]))}]
        trial = TermFit([], np.zeros(0), np.zeros(0), NOM, res, bic=-100.0, held_rms={"roll_accel_rad_s2": 1.0})
        checks = {c.gate: c for c in gate_checks(trial, 0.0, {"roll_accel_rad_s2": 1.0}, res, data)}
        gain = checks["heldout_bic_gain"]
        assert gain.passed is passes, gain.why
        assert gain.numbers["threshold"] == pytest.approx(gain_threshold(data), abs=0.05)
        assert gain.numbers["heldout_s"] == pytest.approx(heldout_s)
        assert checks["consistency"].passed


def test_the_vetoed_leader_note_uses_the_rounds_gate():
    """A leader with gain 120, rejected by identifiability: a note on a 2 x 40 s log (gate 80), none on a log whose
    gate is 150 (its gain would not have named it anyway)."""
    bad = GateCheck("identifiable", False, {}, "not identifiable")
    verdicts = {"drag": Verdict("drag", False, "identifiable", bad.why, 120.0, [bad])}
    assert Step(0.0, {}, None, 0.0, verdicts, None, MIN_DELTA_BIC).vetoed_leader().term == "drag"
    assert Step(0.0, {}, None, 0.0, verdicts, None, 150.0).vetoed_leader() is None


def test_our_40_s_flights_keep_the_fixed_gate_and_80_s_flights_double_it():
    """The gate set on 2 x 40 s flights is unchanged on them: their held-out blocks hold at most 40 s."""
    short = Data.split(prepare(fixed_flights(NOM, 2, 0, 40.0), NOM))
    assert short.heldout_s <= GATE_HELDOUT_S and gain_threshold(short) == MIN_DELTA_BIC
    long = Data.split(prepare(fixed_flights(NOM, 2, 0, 80.0), NOM))
    assert 1.6 * MIN_DELTA_BIC < gain_threshold(long) <= 2 * MIN_DELTA_BIC


def test_derive_gates_counts_pairs_in_force_at_each_candidates_own_gate():
    """``derive_gates``' in-force count uses the gate each verdict records, not a fixed MIN_DELTA_BIC."""
    from offline.calibrate.derive_gates import wrongly_named

    def row(gain, threshold):
        gates = {
            "identifiable": {"passed": True},
            "consistency": {"passed": True},
            "heldout_bic_gain": {"threshold": threshold, "pooled_rms_cut_pct": 5.0},
        }
        return {"candidates": {"drag": {"heldout_bic_gain": gain, "gates": gates}}}

    rows = [row(90.0, 80.0), row(90.0, 150.0), row(160.0, 150.0)]
    assert wrongly_named(rows, None, 0.0) == ["drag", None, "drag"]
    assert wrongly_named(rows, MIN_DELTA_BIC, 0.0) == ["drag", "drag", "drag"]
