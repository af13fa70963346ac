"""The share statistic against regimes that move the shares without a fault, and its calibration file.

A payload picked up mid-flight is a collective step that must re-learn the baseline, not add share
evidence; a small excursion below the reference (half the share shift of ``alerts.min_thrust_loss``) adds
nothing; slow drifts are absorbed; a calibration made for another share statistic is not used for it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from monitor.decision.config import DecisionConfig
from monitor.decision.regime import StepInputs
from monitor.decision.rotor_share import SHARE_SIGMA
from monitor.decision.rule import Decision, WindowEvidence
from monitor.decision.thresholds import Calibration, load_calibration, physics_statistic, thresholds

RATE_HZ, WINDOW = 20.0, 100
HOVER_RPM = 6500.0


def fly(d: Decision, rpm_of_t, duration_s: float, p=0.01):
    out = []
    for j in range(int(duration_s * RATE_HZ)):
        t = (j + 1) / RATE_HZ
        rpm = rpm_of_t(t)
        d.step(t, StepInputs(True, float(np.mean(rpm)), 0.05, 0.1, 15.5, rpm))
        if j >= WINDOW - 1:
            out += d.window_evidence(t, WindowEvidence(np.full(4, p)))
    return out


def shares(delta_1_2: float) -> np.ndarray:
    """RPM whose yaw-free omega^2 share moves rotor 1 up and rotor 2 down by ``delta_1_2`` (a CG shift's pattern)."""
    w2 = np.array([1.0 + delta_1_2, 1.0 - delta_1_2, 1.0, 1.0])
    return np.sqrt(w2)


def analytic():
    return Decision(DecisionConfig(), RATE_HZ, WINDOW, use_stored_calibration=False)


def test_payload_pick_up_mid_flight_re_learns_the_baseline_and_raises_nothing():
    # At 40 s an off-centre payload: 32 % more mass (RPM x 1.15) and rotor 1's share 3 % up, rotor 2's down: the
    # pattern of a 6 % thrust loss on rotor 1 at the reference's scale. It is a collective step, not a fault.
    rng = np.random.default_rng(3)

    def rpm(t):
        noise = 1.0 + 0.002 * rng.standard_normal(4)
        return HOVER_RPM * noise * (1.15 * shares(0.03) if t >= 40.0 else shares(0.0))

    d = analytic()
    assert fly(d, rpm, 100.0) == []
    assert d.regime.counts["collective_step"] >= 1 and d.share.baseline[0] > 0.02  # re-learnt at the new shares
    # The same share change without the collective step is evidence: the regime handling is what kept it out.
    d2 = analytic()
    ann = fly(d2, lambda t: HOVER_RPM * (shares(0.03) if t >= 40.0 else shares(0.0)), 100.0)
    assert ann and ann[0].propellers == (1,)


def test_a_payload_whose_trim_is_a_large_loss_is_held_until_the_step_rule_re_learns(monkeypatch):
    # Our simulator, seed 601: a 38 % payload picked up off-centre moved the trims at once and the
    # shares called rotor 3 FAULT 4.8 s later, 1.7 s before the 10-s median rule saw the step. Here the payload
    # moves rotor 1's share 6 % up (a 12 % loss's pattern, beyond the reference): while the last 2 s of mean RPM
    # stand apart from the 10 s before, windows are held; the step rule then re-learns. Nothing is raised.
    import monitor.decision.regime as regime

    def rpm(t):
        return HOVER_RPM * (1.15 * shares(0.06) if t >= 40.0 else shares(0.0))

    d = analytic()
    assert fly(d, rpm, 100.0) == []
    assert d.regime.shift_steps > 0 and d.regime.counts["collective_step"] >= 1
    # Without the hold the same flight is a FAULT on rotor 1 before the step rule fires: the hold kept it out.
    monkeypatch.setattr(regime, "COLLECTIVE_SHIFT_S", 1e9)
    d2 = analytic()
    ann = fly(d2, rpm, 100.0)
    assert any(a.level == "fault" and a.propellers == (1,) for a in ann), [a.text for a in ann]


def test_a_climb_is_held_but_neither_discounted_nor_re_learnt():
    # A 3-s climb at 10 % more RPM: held while its 2 s stand apart from the 10 s before, but it comes back, so it
    # is no collective step (no evidence halved, the baseline kept).
    d = analytic()
    assert fly(d, lambda t: HOVER_RPM * (1.10 if 40.0 <= t < 43.0 else 1.0) * np.ones(4), 70.0) == []
    assert d.regime.shift_steps > 0 and d.regime.counts["collective_step"] == 0
    assert d.share.baseline is not None and d.held_windows > 0


def test_share_excursion_below_the_reference_adds_nothing_and_a_slow_drift_is_absorbed():
    # 8 % minimum loss -> reference 2 %: a 1.5 % manoeuvre-sized excursion for 20 s, then a drift of 3 % over
    # 4 minutes (battery sag, warm motor): nothing builds up. Against a fixed baseline the drift would alert.
    def rpm(t):
        bump = 0.015 if 30.0 <= t < 50.0 else 0.0
        drift = 0.03 * max(t - 60.0, 0.0) / 240.0
        return HOVER_RPM * shares(bump + drift)

    d = analytic()
    assert fly(d, rpm, 300.0) == []
    assert d.S["physics"].max() < d.thresholds.suspect["physics"] / 2


def test_a_thrust_loss_of_the_minimum_size_is_called_on_its_rotor():
    # Rotor 3 loses 8 %: its omega^2 share +4 %, its same-spin partner 4's -4 % (yaw-free, as the controller does).
    def rpm(t):
        w2 = np.array([1.0, 1.0, 1.04, 0.96]) if t >= 40.0 else np.ones(4)
        return HOVER_RPM * np.sqrt(w2)

    d = analytic()
    ann = fly(d, rpm, 80.0)
    assert [a.level for a in ann] == ["suspect", "fault"] and all(a.propellers == (3,) for a in ann), ann
    assert ann[0].t_s > 40.0


def test_a_calibration_for_another_share_statistic_is_not_used_for_it(tmp_path):
    cfg = DecisionConfig()
    fits = {"absolute": None, "change": {"a": 8.0, "b": 0.4}, "physics": {"a": 3.0, "b": 1.5, "h_max_healthy": 9.0}}
    prov = {"flight_hours": 5.0, "physics_statistic": physics_statistic(cfg)}
    path = tmp_path / "cal.json"
    path.write_text(json.dumps({"fits": fits, "model_sha256": "sha", "provenance": prov}))
    cal = load_calibration(path)
    th = thresholds(cfg, WINDOW / RATE_HZ, "sha", cal)
    # 0.1/h shared by the two statistics that may raise FAULT (physics, pair) is rarer than 1 per 5 h: the fault
    # threshold is above the highest healthy value
    assert th.fault["physics"] > 9.0 and th.fault["physics"] == pytest.approx(max((3.0 - math.log(0.1 / 2)) / 1.5, 9.0), rel=1e-5)
    # 1/h shared by all four statistics is resolved by 5 h: the fitted tail alone
    assert th.suspect["physics"] == pytest.approx((3.0 - math.log(1.0 / 4)) / 1.5)
    other = thresholds(DecisionConfig(min_thrust_loss=0.05), WINDOW / RATE_HZ, "sha", cal)
    assert "analytic" in other.source and other.fault["physics"] != th.fault["physics"]
    assert other.fault["change"] == th.fault["change"]  # the network's statistics keep their calibration
    assert Calibration({"physics": None}, "x").threshold("physics", 0.1) == math.inf
    assert SHARE_SIGMA > 0


# -- replayed flights of our simulator (randomised physics from the assumption register) through the shipped
# classifier and calibration: what the daemon would see, step by step.
SHIPPED = Path(__file__).resolve().parents[1] / "models" / "classifier.onnx"


def _flight(kind: str, seed: int, **kw):
    from monitor.model import Classifier
    from monitor.vehicle import load_vehicle
    from offline.alerts.flights import FlightSet, simulate_set

    vehicle = load_vehicle(SHIPPED.parent / "vehicle.yaml")
    fs = FlightSet(kind, 1, chunk_flights=1, physics="randomised", seed=seed, **kw)
    return simulate_set(vehicle, fs, Classifier(SHIPPED), log=lambda m: None)[0]


@pytest.mark.skipif(not SHIPPED.is_file(), reason="models/classifier.onnx not built")
def test_replayed_healthy_flight_with_a_mid_flight_payload_pick_up_raises_nothing():
    from offline.alerts.rules import replay_decision

    f = _flight("healthy", 2, duration_s=60.0, pickup_fraction=1.0)
    assert "pickup+0.30@30s" in f.name  # 30 % more mass at 30 s, on a drawn airframe
    d = Decision(DecisionConfig(), f.rate_hz, f.window)
    assert replay_decision(f, d) == []
    assert d.regime.counts["collective_step"] >= 1 and d.windows > 1000


@pytest.mark.skipif(not SHIPPED.is_file(), reason="models/classifier.onnx not built")
def test_replayed_onset_raises_suspect_then_fault_on_the_right_propeller():
    from offline.alerts.rules import replay_decision

    f = _flight("single", 2, duration_s=50.0, onset_s=(20.0, 25.0))
    assert f.truth == (4,) and f.thrust_loss[0] >= 0.08  # 8.2 % thrust lost at hover, drawn from the register
    speed = np.linalg.norm(f.vel_heading_m_s, axis=1)  # kept for a speed-aware baseline: a route at cruise speed
    assert f.vel_heading_m_s.shape == (len(f.motor_rpm), 2) and 1.0 < np.nanmax(speed) < 12.0
    alerts = replay_decision(f, Decision(DecisionConfig(), f.rate_hz, f.window), with_sets=True)
    assert [lvl for _, lvl, _, _ in alerts[:2]] == ["suspect", "fault"] and all(p == (4,) for _, _, p, _ in alerts), alerts
    assert f.onset_s < alerts[0][0] and alerts[1][0] - f.onset_s <= 10.0
    # Later the yaw balance may widen the fault to rotor 4's same-spin pair ("PROP 4 or 3+4?"): at fault level,
    # rotor 4 first; never a NOTICE after the WARNING
    assert all(lvl == "fault" and sets[0] == (4,) for _, lvl, _, sets in alerts[2:]), alerts


def test_the_share_baseline_spans_ten_seconds_of_evidence_not_the_half_second_after_a_hold():
    # An airframe whose CG puts rotor 1's yaw-free share 0.08 up (rotor 2's down) in steady flight. A manoeuvre
    # beyond the training envelope (tilt 60 deg, 5-12 s) holds every window until 17 s; the recovery leaves the
    # shares at 0.11 until 19 s. A baseline finalised on the first windows after the hold would read the transient
    # as the trim, and rotor 2 (0.03 above it from then on: beyond the reference, half the shift of an 8 % loss)
    # would be called faulty within seconds. Over 10 s of evidence windows it reads the trim, and nothing is raised.
    rng = np.random.default_rng(7)

    def rpm(t):
        offset = 0.11 if 12.0 <= t < 19.0 else 0.08
        return HOVER_RPM * shares(offset) * (1.0 + 0.002 * rng.standard_normal(4))

    d = analytic()
    out = []
    for j in range(int(90 * RATE_HZ)):
        t = (j + 1) / RATE_HZ
        r = rpm(t)
        tilt = math.radians(60.0) if 5.0 <= t < 12.0 else 0.05
        d.step(t, StepInputs(True, float(np.mean(r)), tilt, 0.1, 15.5, r))
        if j >= WINDOW - 1:
            out += d.window_evidence(t, WindowEvidence(np.full(4, 0.01)))
        if t == 20.0:
            assert d.share.baseline is None  # 3 s of evidence windows since the hold, not 10
    assert d.regime.counts["aggressive"] >= 1
    assert out == [], [(a.t_s, a.text) for a in out]
    assert abs(d.share.baseline[0] - 0.08) < 0.02  # the trim, not the recovery transient


def test_after_a_fault_the_network_raises_no_notice_on_other_propellers_but_the_shares_still_may():
    # Rotor 3 loses 8 % at 30 s (its share +4 %, its partner 4's -4 %) and is called. From 50 s the network says
    # rotor 1 is faulty (P 0.999): the windows now carry rotor 3's fault, which a network trained on flights of one
    # fixed condition spreads over other propellers (on our onset flights: 8 NOTICEs naming a healthy propeller,
    # each after a correct fault). From 60 s rotor 1 loses 10 % too (share +5 %, partner 2's -5 %): physics.
    def rpm(t):
        w2 = np.ones(4)
        if t >= 30.0:
            w2 += np.array([0.0, 0.0, 0.04, -0.04])
        if t >= 60.0 and second_loss:
            w2 += np.array([0.05, -0.05, 0.0, 0.0])
        return HOVER_RPM * np.sqrt(w2)

    def network(t):
        return np.array([0.999, 0.01, 0.01, 0.01]) if t >= 50.0 else np.full(4, 0.01)

    def run():
        d = analytic()
        out = []
        for j in range(int(90 * RATE_HZ)):
            t = (j + 1) / RATE_HZ
            r = rpm(t)
            d.step(t, StepInputs(True, float(np.mean(r)), 0.05, 0.1, 15.5, r))
            if j >= WINDOW - 1:
                out += d.window_evidence(t, WindowEvidence(network(t)))
        return out

    second_loss = False
    ann = run()
    assert [(a.level, a.propellers) for a in ann] == [("suspect", (3,)), ("fault", (3,))], [(a.t_s, a.text) for a in ann]
    assert ann[1].t_s < 50.0
    second_loss = True  # the omega^2 shares of rotor 1 rise: that is physics, and it is told
    ann = run()
    assert any(1 in a.propellers and a.t_s > 60.0 for a in ann), [(a.t_s, a.text) for a in ann]
    # its NOTICE names rotor 1 alone: "PROP 1+3 SUSPECT" after "PROP 3 FAULT" would read as a downgrade of rotor 3
    later = [a for a in ann if a.t_s > 60.0 and a.level == "suspect"]
    assert later and later[0].text == "PROP 1 SUSPECT" and later[0].propellers == (1,), [(a.t_s, a.text) for a in ann]


def _loss_with_a_sag(loss: float, sag_at_s: float | None) -> list:
    """Hover at 6500 RPM on a 16 V pack; rotor 4 loses ``loss`` of its thrust at 60 s (spun faster to make it up);
    the pack sags 6 % in a second from ``sag_at_s`` (more current for the same thrust, a weak pack) and keeps
    sagging 1 % per 5 s after it."""
    d = Decision(DecisionConfig(), RATE_HZ, WINDOW, use_stored_calibration=False)
    rng = np.random.default_rng(3)
    out = []
    for j in range(int(100 * RATE_HZ)):
        t = (j + 1) / RATE_HZ
        w2 = np.ones(4)
        if loss and t >= 60.0:
            w2[3] /= 1.0 - loss
        rpm = 6500.0 * np.sqrt(w2) * (1.0 + 0.002 * rng.standard_normal(4))
        volts = 16.0
        if sag_at_s is not None and t >= sag_at_s:
            volts *= 1.0 - 0.06 * min(t - sag_at_s, 1.0) - 0.002 * (t - sag_at_s)
        d.step(t, StepInputs(True, float(np.mean(rpm)), 0.05, 0.1, volts, rpm))
        if j >= WINDOW - 1:
            out += d.window_evidence(t, WindowEvidence(np.full(4, 0.01)))
    return out, d


def test_a_battery_sag_does_not_hide_a_loss_from_the_omega2_shares():
    """A sag scales every rotor's speed for its command alike: the shares (ratios) do not see it, so a loss that
    draws enough current to sag the pack is still named; the sag is still counted (the network's evidence waits)."""
    out, d = _loss_with_a_sag(0.12, sag_at_s=60.5)
    assert d.regime.counts["battery_sag"] >= 1
    faults = [a for a in out if a.level == "fault"]
    # named within 5 s of the onset (64.2 s); with the shares held and halved for the sag it came at 69.4 s
    assert faults and faults[0].propellers == (4,) and faults[0].t_s <= 66.0, [(a.t_s, a.text) for a in out]
    healthy, d = _loss_with_a_sag(0.0, sag_at_s=60.5)
    assert d.regime.counts["battery_sag"] >= 1 and healthy == []


def test_the_collective_shift_kept_sorted_step_by_step_is_the_median_of_the_spans():
    """The shift test reads medians from spans kept sorted as values enter and leave; through climbs, payload
    steps, landings (a reset) and collective steps (a clear) they must be the medians of the RPM history itself."""
    from monitor.decision.regime import RegimeTracker

    tracker = RegimeTracker(DecisionConfig(), RATE_HZ, WINDOW)
    rng = np.random.default_rng(3)
    level, compared, events = HOVER_RPM, 0, set()
    for j in range(6000):
        if j % 700 == 350:
            level *= rng.choice([0.8, 0.97, 1.03, 1.25])  # steps the step rule catches, shifts it only holds
        airborne = j % 2500 < 2400
        rpm = level + 40.0 * rng.standard_normal() if j % 97 else math.nan  # an unknown RPM now and then
        events.add(tracker.update(StepInputs(airborne, rpm, 0.05, 0.1, 15.5)))
        history = list(tracker._rpm)
        if len(history) >= tracker._median_n + tracker._shift_n:
            assert tracker._collective_shifted() == tracker._collective_moved(tracker._shift_n)
            span = history[-(tracker._median_n + tracker._shift_n) :]
            assert tracker._old_sorted == sorted(span[: tracker._median_n])
            assert tracker._new_sorted == sorted(span[tracker._median_n :])
            compared += 1
    assert compared > 4000 and {"collective_step", "landed"} <= events and tracker.shift_steps > 0
