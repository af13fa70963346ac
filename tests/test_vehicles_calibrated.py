"""The calibrated vehicle's predicted hover shares (offline/vehicles/calibrated.py), checked against hand trims."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from monitor.memory.judge import judge
from monitor.memory.normal import normal_of
from monitor.memory.summary import ShareAccumulator
from monitor.vehicle import DEFAULT_VEHICLE, GRAVITY_M_S2, load_vehicle
from offline.vehicles.calibrated import hover_shares, hover_trim, prior_normal, pulled_normal

NOMINAL = load_vehicle(DEFAULT_VEHICLE)


def test_nominal_hover_is_four_equal_shares_and_balances():
    trim = hover_trim(NOMINAL)
    assert trim["total_thrust_n"] == pytest.approx(NOMINAL.mass_kg * GRAVITY_M_S2)
    assert np.allclose(trim["moment_nm"], 0.0, atol=1e-12)
    assert np.allclose(hover_shares(NOMINAL, NOMINAL.esc), 1.0)


def test_cg_one_cm_forward_moves_the_front_pair_by_c_over_d():
    # By hand: rotors at x = +-d (d = arm / sqrt 2); pitch about a CG at x = c: F (d - c) = R (d + c), F + R = m g;
    # roll and yaw balance make f1 = f3 = F / 2, f2 = f4 = R / 2, so the thrust (= omega^2, one ESC curve, every
    # efficiency 1) shares are 1 + c / d at the front, 1 - c / d at the rear: +-0.0884 for c = 1 cm, d = 0.1131 m.
    d = NOMINAL.arm_length_m / math.sqrt(2.0)
    v = dataclasses.replace(NOMINAL, cg_offset_frd_m=(0.01, 0.0, 0.0))
    trim = hover_trim(v)
    assert trim["total_thrust_n"] == pytest.approx(v.mass_kg * GRAVITY_M_S2)
    assert np.allclose(trim["moment_nm"], 0.0, atol=1e-9)
    s = hover_shares(v, NOMINAL.esc)
    assert 0.01 / d == pytest.approx(0.08839, abs=1e-5)
    assert np.allclose(s, [1 + 0.01 / d, 1 - 0.01 / d, 1 + 0.01 / d, 1 - 0.01 / d], atol=1e-6)


def test_a_weak_motor_raises_its_own_share_by_the_hand_computed_amount():
    # By hand: the thrust split is unchanged (each rotor's torque/thrust ratio is ktau / kf whatever its efficiency),
    # so every rotor spins at the same speed w; rotor 1 at efficiency 0.9 is commanded to w / 0.9, which the log
    # reads (same ESC curve) as omega^2 = w^2 / 0.81: share 4 (1/0.81) / (3 + 1/0.81) = 1.16618, the others 0.94461.
    v = dataclasses.replace(NOMINAL, motor_efficiency=(0.9, 1.0, 1.0, 1.0))
    s = hover_shares(v, NOMINAL.esc)
    assert s[0] == pytest.approx(4 / 0.81 / (3 + 1 / 0.81), abs=1e-6)
    assert s[0] == pytest.approx(1.16618, abs=1e-5)
    assert np.allclose(s[1:], 4 / (3 + 1 / 0.81), atol=1e-6)


def test_the_shares_are_read_through_the_nominal_esc_curve():
    # A vehicle whose ESC gives 0.95 x the nominal RPM for a command needs a higher command on every rotor; read
    # back through the nominal curve (as monitor.logs reads a log) every rotor reads 1 / 0.95 faster, so the shares
    # are those of the same CG offset with the nominal ESC (a common scale cancels in a share).
    esc = dataclasses.replace(
        NOMINAL.esc,
        a_rpm_per_cmd2=0.95 * NOMINAL.esc.a_rpm_per_cmd2,
        b_rpm_per_cmd=0.95 * NOMINAL.esc.b_rpm_per_cmd,
        c_rpm=0.95 * NOMINAL.esc.c_rpm,
    )
    v = dataclasses.replace(NOMINAL, esc=esc, cg_offset_frd_m=(0.01, 0.0, 0.0))
    ref = hover_shares(dataclasses.replace(NOMINAL, cg_offset_frd_m=(0.01, 0.0, 0.0)), NOMINAL.esc)
    assert np.allclose(hover_shares(v, NOMINAL.esc), ref, atol=1e-6)
    # an RPM offset does not cancel: the shares depend on which curve the log is read with
    shifted = dataclasses.replace(NOMINAL.esc, c_rpm=NOMINAL.esc.c_rpm + 1000.0)
    assert not np.allclose(hover_shares(v, shifted), ref, atol=1e-3)


def _flight(shares: np.ndarray, seed: int, seconds: float = 60.0):
    rng = np.random.default_rng(seed)
    n = int(seconds * 20)
    x = np.asarray(shares) * (1.0 + 0.004 * rng.standard_normal((n, 4)))
    acc = ShareAccumulator("omega2", 20.0)
    tilt = 0.02 * rng.standard_normal((n, 2))
    acc.table(x, tilt[:, 0], tilt[:, 1], np.ones(n, dtype=bool))
    return acc.summary


def test_prior_normal_names_the_weak_rotor_and_pulled_normal_moves_half_way():
    cg = hover_shares(dataclasses.replace(NOMINAL, cg_offset_frd_m=(0.01, 0.0, 0.0)), NOMINAL.esc)
    healthy = _flight(cg, 1)
    # a 10 % thrust loss on rotor 2: its omega^2 rises by 1 / 0.9 for the same thrust
    damaged = _flight(cg * np.array([1.0, 1 / 0.9, 1.0, 1.0]), 2)
    v_h = judge(prior_normal(cg, healthy), healthy)
    v_d = judge(prior_normal(cg, damaged), damaged)
    assert v_h["faulty_propellers"] == [] and v_h["confidence"] == "confident"
    assert v_d["faulty_propellers"] == [2] and v_d["confidence"] == "confident"
    # against the nominal vehicle's shares the healthy CG-offset flight is called faulty: what calibration is for
    assert judge(prior_normal(np.ones(4), healthy), healthy)["faulty_propellers"] != []

    own = normal_of([_flight(cg, s) for s in (3, 4, 5)])
    pulled = pulled_normal(own, np.ones(4), weight_flights=3.0)
    assert np.allclose(pulled.intercept, (own.intercept + 1.0) / 2.0)
    assert pulled.n_flights == 6


def test_the_table_counts_what_its_columns_say():
    from offline.vehicles.localise import RULES, table

    def row(faulty, named, confidence, in_set):
        v = {"faulty_propellers": named, "confidence": confidence, "set": in_set}
        return {"faulty": faulty, "loss": 0.1 if faulty else 0.0, "verdicts": {RULES[0]: v}}

    rows = [
        row([2], [2], "confident", [2]),  # exact & confident, in set
        row([2], [1, 2], "ambiguous", [1, 2]),  # in set only
        row([2], [], "confident", []),  # confidently healthy on a damaged flight: confident wrong
        row([], [3], "ambiguous", [3]),  # a propeller named on a healthy flight, not confidently: not FAULTY
        row([], [4], "confident", [4]),  # FAULTY on healthy: confident wrong
        row([], [], "confident", []),  # exact & confident healthy
    ]
    res = table(rows)
    singles, healthy = res["singles >= 6 %"][RULES[0]], res["healthy later"][RULES[0]]
    assert (singles["exact_confident"], singles["in_set"], singles["confident_wrong"]) == (1, 2, 1)
    assert (healthy["exact_confident"], healthy["confident_wrong"], healthy["faulty_on_healthy"]) == (1, 1, 1)
    assert healthy["named_on_healthy"] == 2
