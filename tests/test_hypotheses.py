"""The verdict as a hypothesis set: conformal threshold, set, fused score, alert text, rule file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from monitor.errors import ModelError
from monitor.hypotheses import flight_score, hypothesis_set, load_rule, rule_path
from offline.classifier.conformal import conformal_threshold, measure


def _flights(rng, n, sharp):
    """n flights of 16-label scores: the truth gets a Dirichlet-drawn share that grows with ``sharp``."""
    truth = rng.integers(0, 16, n)
    g = rng.gamma(np.ones((n, 16)))
    g[np.arange(n), truth] += rng.gamma(sharp, size=n)  # a Dirichlet draw with the truth's weight raised
    return g / g.sum(axis=1, keepdims=True), truth


def test_conformal_threshold_holds_its_coverage_on_new_flights():
    rng = np.random.default_rng(3)
    cal, cal_truth = _flights(rng, 400, sharp=2.0)
    thr = conformal_threshold(cal[np.arange(400), cal_truth], 0.9)
    new, new_truth = _flights(rng, 4000, sharp=2.0)
    m = measure(new, new_truth, thr)
    assert 0.88 <= m["truth_in_set"] <= 0.94  # split conformal: >= 0.9 in expectation, not far above
    # A threshold that ignores the calibration (the best label alone) covers far less on these flights.
    assert measure(new, new_truth, 1.0)["truth_in_set"] < 0.5


def test_conformal_threshold_refuses_too_few_flights():
    with pytest.raises(ValueError, match="cannot support coverage"):
        conformal_threshold(np.full(10, 0.5), 0.95)


def test_hypothesis_set_keeps_the_best_and_orders_by_probability():
    s = np.full(16, 0.01)
    s[1], s[5] = 0.5, 0.36  # label 2 = {1}, label 6 = {1, 2}
    s /= s.sum()
    hs = hypothesis_set(s, 0.2)
    assert [h["faulty_propellers"] for h in hs] == [[1], [1, 2]]
    assert hs[0]["probability"] > hs[1]["probability"]
    assert [h["faulty_propellers"] for h in hypothesis_set(s, 0.99)] == [[1]]  # nothing reaches it: the best alone


def test_moment_balance_likelihood_moves_the_score():
    p = np.full(16, 1 / 16)
    ll = np.zeros(16)
    ll[3] = 8.0  # the balance strongly favours label 4 = {3}
    fused = flight_score(p, ll, "classifier x moment balance")
    assert np.argmax(fused) == 3 and fused.sum() == pytest.approx(1.0)
    assert np.allclose(flight_score(p, ll, "classifier"), p)  # the classifier alone ignores it
    p2 = np.full(16, 0.5 / 15)
    p2[0] = 0.5
    assert np.argmax(flight_score(p2, ll, "moment balance")) == 3  # the balance alone ignores the classifier
    assert np.allclose(flight_score(p, None, "classifier x moment balance"), p)  # no balance: classifier alone
    with pytest.raises(ValueError):
        flight_score(np.full(16, np.nan), None, "classifier")


def test_rule_file_is_read_and_a_bad_one_is_named(tmp_path):
    model = tmp_path / "classifier.onnx"
    assert load_rule(model) is None  # no rule beside the model: none
    rule = {"rule": {"score": "classifier", "threshold": 0.2, "coverage": 0.95, "calibration_flights": 160}}
    rule_path(model).write_text(json.dumps(rule))
    r = load_rule(model)
    assert (r.score, r.threshold, r.coverage, r.calibration_flights) == ("classifier", 0.2, 0.95, 160)
    rule["rule"]["threshold"] = 1.5
    rule_path(model).write_text(json.dumps(rule))
    with pytest.raises(ModelError, match="classifier.sets.json"):
        load_rule(model)
    rule_path(model).write_text("{not json")
    with pytest.raises(ModelError, match="classifier.sets.json"):
        load_rule(model)


def test_flight_sets_word_the_daemons_alerts_as_the_flights_hypotheses():
    from monitor.decision import Decision, DecisionConfig, StepInputs, WindowEvidence
    from monitor.hypotheses import FlightSets, SetRule

    rule = SetRule("classifier x moment balance", 0.3, 0.95, 160, thresholds=(("classifier", 0.2),))
    sets = FlightSets(rule)
    assert sets.threshold == 0.2  # the daemon scores the classifier alone, at its own calibrated threshold
    p = np.full(16, 0.01)
    p[1], p[5] = 0.5, 0.35  # {1} or {1, 2}: the network cannot tell whether the same-spin partner is hit too
    p /= p.sum()
    hyps = sets.add(p)
    assert [h for h, _ in hyps] == [(1,), (1, 2)]
    d = Decision(DecisionConfig(), 20.0, 100, use_stored_calibration=False)
    ann = []
    for j in range(1400):
        t = (j + 1) / 20.0
        d.step(t, StepInputs(True, 6500.0, 0.02, 0.05, 15.5, np.full(4, 6500.0)))
        if j >= 99:
            fp = np.array([0.999 if t > 42.5 else 0.01, 0.01, 0.01, 0.01])
            ann += d.window_evidence(t, WindowEvidence(fp, p, hypotheses=hyps if t > 42.5 else None))
    fault = [a for a in ann if a.level == "fault"]
    assert fault and fault[0].text == "PROP 1 or 1+2?"
    ev = fault[0].event()
    assert [h["faulty_propellers"] for h in ev["hypotheses"]] == [[1], [1, 2]]
    # a model without a classifier threshold gives no set; a new flight starts from nothing
    assert FlightSets(SetRule("classifier x moment balance", 0.3, 0.95, 160)).add(p) is None
    sets.reset()
    q = np.full(16, 0.001)
    q[0] = 1.0
    assert [h for h, _ in sets.add(q / q.sum())] == [()]
