"""The shared decision rule (monitor/decision/rule.py) on window sequences with known answers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from monitor.decision.config import DecisionConfig
from monitor.decision.regime import StepInputs
from monitor.decision.rule import Decision, WindowEvidence, statustext
from monitor.decision.thresholds import STATISTICS, Calibration, analytic_threshold, load_calibration, thresholds
from monitor.errors import ConfigError

RATE_HZ, WINDOW = 20.0, 100
HOVER_RPM = 6500.0


def fly(decision, p_of_t, duration_s, tilt_of_t=lambda t: 0.02, rpm_of_t=None, t0_s=0.0):
    """Feed steps and hop-1 windows like the daemon; window outputs p_of_t(t) -> (4,). Returns announcements."""
    out = []
    for j in range(int(duration_s * RATE_HZ)):
        t = t0_s + (j + 1) / RATE_HZ
        rpm = np.full(4, HOVER_RPM) if rpm_of_t is None else rpm_of_t(t)
        decision.step(t, StepInputs(True, float(np.mean(rpm)), tilt_of_t(t), 0.05, 15.5, rpm))
        if j >= WINDOW - 1:
            out += decision.window_evidence(t, WindowEvidence(np.asarray(p_of_t(t), dtype=np.float64)))
    return out


def analytic(cfg: DecisionConfig | None = None):
    return Decision(cfg or DecisionConfig(), RATE_HZ, WINDOW, use_stored_calibration=False)


def test_threshold_follows_the_configured_false_alarm_rate():
    window_s = WINDOW / RATE_HZ
    # Wald's bound by hand: 5 s windows -> 720 independent samples per hour per propeller, 4 propellers.
    assert analytic_threshold(0.1, window_s) == pytest.approx(5.0 * math.log(4 * 720 / 0.1))
    lo, hi = (thresholds(DecisionConfig(false_alarms_per_hour=r), window_s) for r in (1.0, 0.01))
    assert all(hi.fault[k] > lo.fault[k] for k in STATISTICS)
    cal = Calibration({"absolute": None, "change": (8.0, 0.4), "physics": (7.0, 0.3)}, "sha")
    lo, hi = (thresholds(DecisionConfig(false_alarms_per_hour=r), window_s, "sha", cal) for r in (1.0, 0.01))
    assert hi.fault["change"] > lo.fault["change"] and hi.fault["physics"] > lo.fault["physics"]
    # ln(rate) = a - b h, the fault budget shared by the two statistics that may raise FAULT: h = (a - ln(rate / 2)) / b
    assert lo.fault["change"] == pytest.approx((8.0 - math.log(1.0 / 2)) / 0.4)
    assert math.isinf(hi.fault["absolute"])  # disabled by the calibration
    # A calibration of another model is not used: analytic thresholds instead.
    other = thresholds(DecisionConfig(), window_s, "another-model", cal)
    assert other.source.startswith("analytic")


def test_config_bounds_and_bad_calibration_file_are_named(tmp_path):
    with pytest.raises(ConfigError, match="alerts.false_alarms_per_hour"):
        DecisionConfig(false_alarms_per_hour=0.0)
    with pytest.raises(ConfigError, match="alerts.suspect_false_alarms_per_hour"):
        DecisionConfig(false_alarms_per_hour=1.0, suspect_false_alarms_per_hour=0.5)
    bad = tmp_path / "cal.json"
    bad.write_text(
        json.dumps({"fits": {"absolute": {"a": 1.0, "b": -2.0}, "change": None, "physics": None}, "model_sha256": "x"})
    )
    with pytest.raises(ConfigError, match="cal.json"):
        load_calibration(bad)
    assert load_calibration(tmp_path / "absent.json") is None


def test_healthy_flight_with_short_bursts_raises_nothing():
    # What the shipped network does on healthy simulated flights: near 0, with 1-2 s bursts where all four
    # propellers read P ~ 1 (after a manoeuvre). Today's rule (20 windows >= 0.9) alerts on each burst.
    bursts = [(20.0, 21.5), (45.0, 46.0), (70.0, 71.8)]

    def p(t):
        return np.full(4, 0.999) if any(a <= t < b for a, b in bursts) else np.full(4, 0.01)

    d = analytic()
    assert fly(d, p, 80.0) == []
    assert d.verdict()["level"] == "none"


def test_onset_raises_suspect_then_fault_on_the_right_propeller():
    onset_s = 40.0

    def p(t):
        return np.array([0.01, 0.02, 0.999 if t >= onset_s + 2.5 else 0.01, 0.01])

    d = analytic(DecisionConfig(fault_evidence="all"))  # the network's evidence alone, allowed to raise FAULT
    ann = fly(d, p, 70.0)
    assert [a.level for a in ann] == ["suspect", "fault"], ann
    assert all(a.propellers == (3,) for a in ann) and all(a.t_s > onset_s for a in ann)
    assert ann[1].text.startswith("PROP 3 FAULT") and ann[1].severity == 4
    assert ann[1].t_s - onset_s < 15.0


def test_a_network_pinned_wrong_from_take_off_is_not_an_alarm_but_a_change_is():
    # A CG offset the network never saw: P(1) ~ 1 from the first window. The absolute statistic is
    # disabled by a calibration that saw this; the change statistic alerts only on what changes later.
    cal = Calibration({"absolute": None, "change": (8.0, 0.4), "physics": (8.0, 0.4)}, "sha")
    d = Decision(DecisionConfig(fault_evidence="all"), RATE_HZ, WINDOW, model_sha256="sha", calibration=cal)

    def p(t):
        return np.array([0.999, 0.01, 0.999 if t >= 50.0 else 0.01, 0.01])

    ann = fly(d, p, 90.0)
    assert ann and all(a.propellers == (3,) for a in ann), ann
    assert ann[-1].level == "fault"


def test_by_default_the_network_alone_raises_suspect_never_fault():
    # fault_evidence "physics" (the default): a network at P ~ 1 on propeller 3 with the omega^2 shares flat
    # is a NOTICE, not a FAULT; the same windows with "all" raise FAULT (the test above).
    def p(t):
        return np.array([0.01, 0.02, 0.999 if t >= 42.5 else 0.01, 0.01])

    ann = fly(analytic(), p, 70.0)
    assert [a.level for a in ann] == ["suspect"] and ann[0].propellers == (3,), ann
    with pytest.raises(ConfigError, match="fault_evidence"):
        DecisionConfig(fault_evidence="network")


def test_suspect_evidence_physics_lets_the_network_raise_nothing_and_gives_its_rate_to_the_shares():
    # The same confidently-wrong network as above, with alerts.suspect_evidence: physics: no NOTICE at all. The
    # suspect rate is then shared by the two physics statistics, not four, so their suspect thresholds are lower.
    def p(t):
        return np.array([0.01, 0.02, 0.999 if t >= 42.5 else 0.01, 0.01])

    cfg = DecisionConfig(suspect_evidence="physics")
    assert fly(analytic(cfg), p, 70.0) == []
    both, physics = analytic().thresholds, analytic(cfg).thresholds
    assert math.isinf(physics.suspect["absolute"]) and math.isinf(physics.suspect["change"])
    assert physics.suspect["physics"] < both.suspect["physics"] and physics.suspect["pair"] < both.suspect["pair"]
    assert physics.fault == both.fault  # the fault level is not touched
    with pytest.raises(ConfigError, match="suspect_evidence"):
        DecisionConfig(suspect_evidence="network")
    with pytest.raises(ConfigError, match="suspect_evidence"):
        DecisionConfig(fault_evidence="all", suspect_evidence="physics")


def test_omega2_share_rise_alerts_without_the_network():
    # Rotor 2 loses thrust at 40 s: the controller spins it 4 % faster (omega^2 +8 %); the network sees nothing.
    rng = np.random.default_rng(0)

    def rpm(t):
        base = HOVER_RPM * (1.0 + 0.01 * rng.standard_normal(4))
        if t >= 40.0:
            base[1] *= 1.04
        return base

    d = analytic()
    ann = fly(d, lambda t: np.full(4, 0.01), 80.0, rpm_of_t=rpm)
    assert ann and all(a.propellers == (2,) for a in ann), ann
    assert ann[-1].level == "fault" and d.verdict()["statistic"]["physics"][1] > 0


def test_aggressive_manoeuvre_holds_the_evidence():
    # The same onset as above, but the whole time the vehicle is banked beyond 45 deg: no window counts.
    def p(t):
        return np.array([0.01, 0.01, 0.999 if t >= 40.0 else 0.01, 0.01])

    d = analytic()
    assert fly(d, p, 70.0, tilt_of_t=lambda t: math.radians(50.0) if t >= 35.0 else 0.02) == []
    assert d.verdict()["held_windows"] > 0 and d.regime.counts["aggressive"] > 0


def test_landing_ends_the_evidence():
    d = analytic()
    fly(d, lambda t: np.array([0.01, 0.01, 0.999 if t >= 30.0 else 0.01, 0.01]), 34.0)
    assert d.S["absolute"][2] > 0
    d.step(34.1, StepInputs(False))
    assert all(not v.any() for v in d.S.values()) and d.baseline is None


def test_vibration_nan_absurd_and_frozen_are_ignored_and_counted():
    d = analytic()
    t = 0.0
    for k in range(400):  # airborne, a healthy level, then garbage of every kind
        t = k * 0.05
        d.step(t, StepInputs(True, HOVER_RPM, 0.02, 0.05, 15.5, np.full(4, HOVER_RPM)))
        d.vibration_sample(t, (0.01, 0.02, 0.3 + 0.01 * math.sin(k)), True)
    bad = [(math.nan, 0.0, 0.3), (0.0, 0.0, -1.0), (0.0, 0.0, 1e6)] + [(0.0, 0.0, 9.0)] * 200
    for v in bad:
        t += 0.05
        d.step(t, StepInputs(True, HOVER_RPM, 0.02, 0.05, 15.5, np.full(4, HOVER_RPM)))
        assert d.vibration_sample(t, v, True) == []
    r = d.vibration.rejected
    assert r["nan"] == 1 and r["negative"] == 1 and r["absurd"] == 1
    assert r["frozen"] == 200 - 19  # the 20th identical reading onwards
    assert d.vibe_level == "none"  # 9 m/s^2 frozen is 30x the baseline, yet no alert


def test_vibration_rise_is_an_unlocalised_suspect():
    d = analytic()
    rng = np.random.default_rng(1)
    ann = []
    for k in range(3000):
        t = k * 0.05
        d.step(t, StepInputs(True, HOVER_RPM, 0.02, 0.05, 15.5, np.full(4, HOVER_RPM)))
        level = 0.3 if t < 60.0 else 1.5  # a blade lets go: 5x the flight's own vibration
        ann += d.vibration_sample(t, (0.01, 0.02, level * (1 + 0.05 * rng.standard_normal())), True)
    assert [(a.level, a.propellers, a.text) for a in ann] == [("suspect", (), "VIBE HIGH PROP ?")]
    assert ann[0].t_s > 60.0


def test_statustext_wording():
    assert statustext("fault", [(3,)], 0.97) == "PROP 3 FAULT p=0.97"
    assert statustext("suspect", [(1,)]) == "PROP 1 SUSPECT"
    assert statustext("fault", [(1,), (1, 2)]) == "PROP 1 or 1+2?"
    long = statustext("fault", [(1,), (1, 2), (1, 3), (1, 4), (1, 2, 3), (1, 2, 4), (1, 3, 4), (1, 2, 3, 4)])
    assert len(long) <= 50 and long.startswith("PROP 1 or 1+2") and long.endswith("?")


def test_the_per_window_clip_is_np_clip_bit_for_bit():
    # RotorShare clips with minimum/maximum (cheaper per window): the same values as np.clip, NaN and -0.0 included.
    from monitor.decision.rotor_share import LLR_CLIP, _clip_llr

    x = np.array([np.nan, -np.inf, np.inf, -0.0, 0.0, LLR_CLIP, -LLR_CLIP, 1e300, -1e300, 0.3, -7.25])
    expected = np.clip(x, -LLR_CLIP, LLR_CLIP)
    assert _clip_llr(x).tobytes() == expected.tobytes()


def test_no_alert_before_the_shares_baseline_is_no_verdict_and_says_so():
    # Each flight first learns BASELINE_S (10 s) of evidence windows; the first window ends 5 s after take-off.
    # A 14 s hover is never tested: its silence is no verdict. The next flight (after a landing) hovers 40 s:
    # tested from 15 s on, 25 s of it, by hand.
    from monitor.decision.rotor_share import BASELINE_S
    from monitor.diagnose.cli import in_flight_summary

    rng = np.random.default_rng(1)
    rpm = lambda t: HOVER_RPM * (1.0 + 0.01 * rng.standard_normal(4))  # noqa: E731
    d = analytic()
    assert fly(d, lambda t: np.full(4, 0.01), 14.0, rpm_of_t=rpm) == []
    final = d.verdict()
    assert final["tested_s"] == 0.0 and final["windows"] > 0
    text = in_flight_summary({"alerts": [], "final": final})
    assert text.startswith("no verdict") and f"{BASELINE_S:.0f}-s baseline" in text, text
    d.step(14.05, StepInputs(False))
    assert fly(d, lambda t: np.full(4, 0.01), 40.0, rpm_of_t=rpm, t0_s=14.1) == []
    final = d.verdict()
    assert final["tested_s"] == pytest.approx(40.0 - WINDOW / RATE_HZ - BASELINE_S, abs=0.11), final
    assert in_flight_summary({"alerts": [], "final": final}).startswith(f"no alert ({final['tested_s']:.1f} s")
