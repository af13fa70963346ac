"""The verdict as a hypothesis set: conformal threshold, set, fused score, alert text, rule file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from monitor.decision.hypotheses import flight_score, hypothesis_set, load_rule, rule_path
from monitor.errors import ModelError
from monitor.labels import LABEL_TABLE
from offline.tune.sets import conformal_threshold, measure


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


def test_classifier_weight_lets_the_balance_outvote_a_network_sure_of_what_only_yaw_separates():
    # the network is sure of {3} + the CCW pair {1, 2} (label 12), the balance mildly prefers {3} (label 4): as the
    # network is, it wins; at tau = 0.25 its 0.999 : 0.001 (6.9 nats) counts as 1.7 nats, below the balance's 3
    p = np.full(16, 1e-6)
    p[11], p[3] = 0.999, 0.001
    p /= p.sum()
    ll = np.zeros(16)
    ll[3], ll[11] = 3.0, 0.0
    fused = "classifier x moment balance"
    assert np.argmax(flight_score(p, ll, fused)) == 11
    assert np.argmax(flight_score(p, ll, fused, classifier_weight=0.25)) == 3
    # tau weighs only the split inside a yaw class: sure of {4} (label 5) against {3} (label 4), a different class
    # (roll and pitch tell them apart), the network still outvotes the balance's 3 nats
    q = np.full(16, 1e-6)
    q[4], q[3] = 0.999, 0.001
    q /= q.sum()
    assert np.argmax(flight_score(q, ll, fused, classifier_weight=0.25)) == 4
    # the classifier alone: its split inside the class flattened (0.999 : 0.001 -> about 5.6 : 1), the class kept
    alone = flight_score(p, None, "classifier", classifier_weight=0.25)
    assert alone[11] / alone[3] == pytest.approx(999.0**0.25, rel=1e-3)
    assert alone[11] + alone[3] == pytest.approx(p[11] + p[3], rel=1e-9)  # exactly the class the network gave
    q = np.full(16, 0.5 / 14)
    q[0], q[5] = 0.25, 0.25  # healthy and 1+2 (one class of four) at 0.25 each: the class keeps its 0.5 + 2/28
    flat = flight_score(q, None, "classifier", classifier_weight=0.25)
    assert flat[[0, 5, 10, 15]].sum() == pytest.approx(q[[0, 5, 10, 15]].sum(), rel=1e-9)
    # the balance alone knows nothing of the classifier
    assert np.allclose(flight_score(p, ll, "moment balance", classifier_weight=0.25), flight_score(p, ll, "moment balance"))
    # a tau of 1 is the plain product
    assert np.allclose(flight_score(p, ll, fused, classifier_weight=1.0), flight_score(p, ll, fused))


def test_yaw_classes_join_exactly_the_sets_a_same_spin_pair_apart():
    from monitor.decision.hypotheses import YAW_CLASS

    classes = {}
    for k, c in enumerate(YAW_CLASS):
        classes.setdefault(int(c), set()).add(LABEL_TABLE[k + 1])
    got = sorted(sorted(v) for v in classes.values())
    want = [
        [()] + [(1, 2), (1, 2, 3, 4), (3, 4)],
        [(1,), (1, 3, 4)],
        [(1, 3)],
        [(1, 4)],
        [(2,), (2, 3, 4)],
        [(2, 3)],
        [(2, 4)],
        [(3,), (1, 2, 3)],
        [(4,), (1, 2, 4)],
    ]
    assert got == sorted(sorted(v) for v in want)


def test_the_daemon_words_a_yaw_class_split_with_the_rules_weight():
    from monitor.decision.hypotheses import FlightSets, SetRule

    p = np.full(16, 1e-6)
    p[14], p[2] = 0.95, 0.05  # label 15 = {2, 3, 4}, label 3 = {2}: one yaw class, split by the network alone
    p /= p.sum()
    sure = FlightSets(SetRule("classifier", 0.1, 0.95, 160, thresholds=(("classifier", 0.1),)), horizon=1)
    assert [s for s, _ in sure.add(p)] == [(2, 3, 4)]
    weighed = FlightSets(
        SetRule("classifier", 0.1, 0.95, 160, thresholds=(("classifier", 0.1),), classifier_weight=0.25), horizon=1
    )
    assert [s for s, _ in weighed.add(p)] == [(2, 3, 4), (2,)]  # worded `PROP 2+3+4 or 2?`, not one answer


def test_rule_file_carries_its_classifier_weight_and_refuses_an_impossible_one(tmp_path):
    model = tmp_path / "classifier.onnx"
    rule = {"rule": {"score": "classifier x moment balance", "threshold": 0.01, "coverage": 0.95, "calibration_flights": 9}}
    rule_path(model).write_text(json.dumps(rule))
    assert load_rule(model).classifier_weight == 1.0  # an older file: the network as it is
    for bad, ok in ((0.25, True), (0.0, False), (1.5, False)):
        rule["rule"]["classifier_weight"] = bad
        rule_path(model).write_text(json.dumps(rule))
        if ok:
            assert load_rule(model).classifier_weight == bad
        else:
            with pytest.raises(ModelError, match="classifier_weight"):
                load_rule(model)


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
    from monitor.decision.config import DecisionConfig
    from monitor.decision.hypotheses import FlightSets, SetRule
    from monitor.decision.regime import StepInputs
    from monitor.decision.rule import Decision, WindowEvidence

    rule = SetRule("classifier x moment balance", 0.3, 0.95, 160, thresholds=(("classifier", 0.2),))
    sets = FlightSets(rule)
    assert sets.threshold == 0.2  # the daemon scores the classifier alone, at its own calibrated threshold
    p = np.full(16, 0.01)
    p[1], p[5] = 0.5, 0.35  # {1} or {1, 2}: the network cannot tell whether the same-spin partner is hit too
    p /= p.sum()
    hyps = sets.add(p)
    assert [h for h, _ in hyps] == [(1,), (1, 2)]
    # the network's evidence alone: it may raise FAULT only when the configuration lets it (fault_evidence "all")
    d = Decision(DecisionConfig(fault_evidence="all"), 20.0, 100, use_stored_calibration=False)
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


def _fly_with_a_network_set(label_p, network_p, share_rotor: int | None, seed: int = 0) -> list:
    """80 s at 20 Hz through the shipped rule (analytic thresholds). From 40 s: rotor ``share_rotor``'s omega^2
    share rises by 10 % (None: the shares stay put), the network's P(faulty) per propeller is ``network_p`` (0.01
    before), and its recent set (a classifier-only conformal rule) is worded from ``label_p``. The announcements."""
    from monitor.decision.config import DecisionConfig
    from monitor.decision.hypotheses import FlightSets, SetRule
    from monitor.decision.regime import StepInputs
    from monitor.decision.rule import Decision, WindowEvidence

    sets = FlightSets(SetRule("classifier", 0.3, 0.95, 160, thresholds=(("classifier", 0.3),)))
    d = Decision(DecisionConfig(), 20.0, 100, use_stored_calibration=False)
    rng = np.random.default_rng(seed)
    ann = []
    for j in range(1600):
        t = (j + 1) / 20.0
        w2 = np.ones(4)
        if share_rotor is not None and t >= 40.0:
            w2 = w2 + 0.10 * (np.eye(4)[share_rotor - 1] - 0.25)
        rpm = 6500.0 * np.sqrt(w2 * (1.0 + 0.01 * rng.standard_normal(4)))
        d.step(t, StepInputs(True, float(rpm.mean()), 0.02, 0.05, 15.5, rpm))
        if j >= 99:
            after = t >= 40.0
            fp = np.asarray(network_p, dtype=np.float64) if after else np.full(4, 0.01)
            ann += d.window_evidence(t, WindowEvidence(fp, label_p, hypotheses=sets.add(label_p) if after else None))
    return ann


def _labels(weights: dict[int, float]) -> np.ndarray:
    """A 16-label probability vector: ``{9: 1.0}`` puts weight 1 on label 9, the rest 0.001 (normalised)."""
    p = np.full(16, 0.001)
    for label, v in weights.items():
        p[label - 1] = v
    return p / p.sum()


def test_a_fault_raised_by_physics_is_worded_by_physics_not_by_the_networks_set():
    # The default (fault_evidence "physics"): rotor 2's omega^2 share rises by 10 % (a thrust loss) while the network,
    # confidently wrong on an airframe it never saw, words the flight {2, 3}. The FAULT, raised by the shares, says
    # PROP 2 (the shares' rotor); the network's set stays in the event's hypotheses. The shares reach suspect first
    # (44.1 s), so the NOTICE is theirs too; after the FAULT the network raises no NOTICE on rotor 3.
    ann = _fly_with_a_network_set(_labels({9: 1.0}), [0.01, 0.999, 0.999, 0.01], share_rotor=2)  # label 9 = {2, 3}
    fault = [a for a in ann if a.level == "fault"]
    assert fault and fault[0].propellers == (2,) and fault[0].text.startswith("PROP 2 FAULT"), [a.text for a in ann]
    assert [h["faulty_propellers"] for h in fault[0].event()["hypotheses"]] == [[2, 3]]
    notices = [a for a in ann if a.level == "suspect"]
    assert [a.text for a in notices] == ["PROP 2 SUSPECT"] and notices[0].t_s < fault[0].t_s
    assert [h["faulty_propellers"] for h in notices[0].event()["hypotheses"]] == [[2, 3]]


def test_sparsity_prior_names_the_single_rotor_where_physics_cannot_split_it_from_a_triple():
    # {1} (label 2) and {1, 3, 4} (label 14) differ only through the unmeasured torque change: equal evidence.
    p = np.full(16, 0.01)
    p[1], p[13] = 0.3, 0.4  # the classifier leans to the triple, as one trained on rising torque does
    p /= p.sum()
    assert np.argmax(flight_score(p, None, "classifier")) == 13
    s = flight_score(p, None, "classifier", sparsity_prior=0.1)
    assert np.argmax(s) == 1 and s.sum() == pytest.approx(1.0)
    # the weights are rho**k: healthy x1, the single x0.1, the triple x0.001, exactly
    assert s[1] / s[13] == pytest.approx((0.3 / 0.4) * 100.0)
    assert s[0] / s[1] == pytest.approx((0.01 / 0.3) * 10.0)
    # evidence that separates them still wins: a triple the data clearly says stays the verdict
    q = np.full(16, 1e-5)
    q[13], q[1] = 0.99, 1e-4
    assert np.argmax(flight_score(q / q.sum(), None, "classifier", sparsity_prior=0.1)) == 13


def test_rule_file_carries_its_sparsity_prior_and_refuses_an_impossible_one(tmp_path):
    model = tmp_path / "classifier.onnx"
    rule = {"rule": {"score": "classifier", "threshold": 0.2, "coverage": 0.95, "calibration_flights": 160}}
    rule_path(model).write_text(json.dumps(rule))
    assert load_rule(model).sparsity_prior == 1.0  # an older file: no prior
    rule["rule"]["sparsity_prior"] = 0.1
    rule_path(model).write_text(json.dumps(rule))
    assert load_rule(model).sparsity_prior == 0.1
    rule["rule"]["sparsity_prior"] = 0.0
    rule_path(model).write_text(json.dumps(rule))
    with pytest.raises(ModelError, match="sparsity_prior"):
        load_rule(model)


def _region(name, rng, n, sharp, share_right):
    from offline.tune.sets import Region

    p, truth = _flights(rng, n, sharp)
    singles = np.array([len(LABEL_TABLE[t + 1]) == 1 for t in truth])
    share = np.where(
        singles & (rng.random(n) < share_right), [LABEL_TABLE[t + 1][0] if s else 1 for t, s in zip(truth, singles)], 0
    )
    return Region(name, truth, p, np.zeros((n, 16)), share)


def test_region_threshold_covers_every_region_not_only_their_mean():
    from offline.tune.sets import candidate

    rng = np.random.default_rng(5)
    easy, hard = _region("easy", rng, 400, 6.0, 0.5), _region("hard", rng, 400, 1.0, 0.5)
    c = candidate([easy, hard], "classifier", 1.0, 0.9)
    assert c["threshold"] == min(c["regions"][r]["threshold_alone"] for r in ("easy", "hard"))
    assert c["regions"]["hard"]["truth_in_set"] >= 0.9 and c["regions"]["easy"]["truth_in_set"] >= 0.9
    # pooled, the easy region's flights would carry a threshold that leaves the hard one under-covered
    pooled = np.concatenate([easy.label_probability, hard.label_probability])
    truth = np.concatenate([easy.truth, hard.truth])
    thr = conformal_threshold(pooled[np.arange(800), truth], 0.9)
    assert measure(hard.label_probability, hard.truth, thr)["truth_in_set"] < 0.9


def test_choose_takes_the_smallest_sets_whose_singles_match_the_share_baseline_then_the_weakest_prior():
    from offline.tune.sets import choose

    def c(score, rho, size, ok, tau=1.0):
        return {
            "score": score,
            "sparsity_prior": rho,
            "worst_set_size": size,
            "singles_never_below_share": ok,
            "classifier_weight": tau,
        }

    cands = [c("classifier", 1.0, 2.0, False), c("classifier", 0.3, 2.5, True), c("moment balance", 0.3, 2.2, True)]
    best = choose(cands)
    assert (best["score"], best["sparsity_prior"]) == ("moment balance", 0.3)  # the smaller sets of the two that qualify
    cands.append(c("classifier", 0.1, 1.5, True))
    assert choose(cands)["sparsity_prior"] == 0.1  # smaller sets still, and singles as good as the share's
    cands.append(c("classifier", 1.0, 1.5, True))
    assert choose(cands)["sparsity_prior"] == 1.0  # equal sets: the weaker prior
    fused = [c("classifier x moment balance", 0.1, 3.0, True, tau) for tau in (0.25, 1.0, 0.5)]
    assert choose(fused)["classifier_weight"] == 1.0  # equal sets and prior: the network as it is
    none_ok = [c("classifier", 1.0, 2.0, False), c("classifier", 0.1, 3.0, False)]
    assert choose(none_ok)["sparsity_prior"] == 0.1  # nothing qualifies, no shortfall known: the strongest prior tried
    # nothing qualifies: the prior whose singles fall least below the share (then the weakest such prior), not the
    # strongest, which may cost far wider sets for no gain in singles
    short = [
        {**c("classifier x moment balance", r, size, False), "worst_singles_shortfall": f}
        for r, size, f in ((1.0, 2.7, 0.15), (0.3, 3.4, 0.05), (0.1, 4.7, 0.05), (0.03, 6.8, 0.08))
    ]
    assert choose(short)["sparsity_prior"] == 0.3


def test_choose_keeps_only_rules_passing_the_torque_sign_check_when_any_does():
    from offline.tune.sets import choose

    def c(rho, size, move):
        return {
            "score": "classifier x moment balance",
            "sparsity_prior": rho,
            "worst_set_size": size,
            "singles_never_below_share": True,
            "classifier_weight": 1.0,
            "torque_sign_move": move,
        }

    # the smallest sets move 5 points when the torque flips: not chosen while a rule within 2 points exists
    assert choose([c(0.3, 2.0, 0.05), c(0.1, 2.5, 0.015), c(0.05, 3.0, 0.0)])["sparsity_prior"] == 0.1
    # none passes: the check cannot choose, the rest of the order does
    assert choose([c(0.3, 2.0, 0.05), c(0.1, 2.5, 0.03)])["sparsity_prior"] == 0.3


def test_torque_sign_move_is_the_change_of_single_propeller_accuracy_between_the_two_sets():
    from offline.tune.sets import Region, torque_sign_move

    truth = np.array([1, 2, 3, 4, 0, 5])  # four singles ({1}..{4}), healthy, a pair
    right = np.full((6, 16), 1e-3)
    right[np.arange(6), truth] = 1.0
    wrong = right.copy()
    wrong[0], wrong[1] = wrong[1].copy(), wrong[0].copy()  # two singles swapped: 50 % of singles right
    up = Region("up", truth, right / right.sum(1, keepdims=True), np.zeros((6, 16)), np.zeros(6, int))
    down = Region("down", truth, wrong / wrong.sum(1, keepdims=True), np.zeros((6, 16)), np.zeros(6, int))
    assert torque_sign_move(up, down, "classifier", 1.0, 1.0) == pytest.approx(0.5)
    assert torque_sign_move(up, up, "classifier", 1.0, 1.0) == 0.0


def test_conformal_cli_refuses_a_sparsity_prior_outside_0_1_before_reading_anything(tmp_path, capsys):
    from offline.tune.sets import main

    for bad in ("0", "1.5", "-0.1"):
        with pytest.raises(SystemExit) as exc:
            main(["--data", str(tmp_path / "missing.npz"), "--sparsity-prior", bad, "--dry-run"])
        assert exc.value.code == 2 and "--sparsity-prior must be in (0, 1]" in capsys.readouterr().err
        with pytest.raises(SystemExit) as exc:
            main(["--data", str(tmp_path / "missing.npz"), "--classifier-weight", bad, "--dry-run"])
        assert exc.value.code == 2 and "--classifier-weight must be in (0, 1]" in capsys.readouterr().err


def test_flight_sets_word_an_onset_from_the_recent_windows_not_the_healthy_minutes_before():
    from monitor.decision.hypotheses import FlightSets, SetRule

    rule = SetRule("classifier", 0.05, 0.95, 160, thresholds=(("classifier", 0.05),))
    healthy, prop2 = np.full(16, 0.001), np.full(16, 0.001)
    healthy[0], prop2[2] = 1.0, 1.0  # label 1 = healthy, label 3 = {2}
    healthy, prop2 = healthy / healthy.sum(), prop2 / prop2.sum()
    recent, since_takeoff = FlightSets(rule, horizon=20), FlightSets(rule, horizon=10_000)
    for p in [healthy] * 600 + [prop2] * 20:  # 30 s healthy, then one second of windows that see propeller 2
        r, s = recent.add(p), since_takeoff.add(p)
    assert r[0][0] == (2,)
    assert s[0][0] == ()  # what the daemon said before: the onset drowned in the flight's healthy half minute
    with pytest.raises(ValueError):
        FlightSets(rule, horizon=0)


def test_deferred_flight_sets_are_the_sets_add_gives_whenever_they_are_read():
    """The daemon defers each window's set until an alert reads it: read later (after more windows, a reset),
    it is still the set of its own window, and it reads as the tuple ``add`` returns."""
    from monitor.decision.hypotheses import FlightSets, RecentSet, SetRule

    rule = SetRule("classifier", 0.05, 0.95, 160, sparsity_prior=0.7)
    eager, lazy = FlightSets(rule, horizon=5), FlightSets(rule, horizon=5)
    rng = np.random.default_rng(4)
    want, got = [], []
    for k in range(60):
        p = rng.dirichlet(np.full(16, 0.3))
        if k == 30:
            eager.reset(), lazy.reset()
        want.append(eager.add(p))
        got.append(lazy.add_deferred(p))
    for w, g in zip(want, got):
        assert isinstance(g, RecentSet) and bool(g) and len(g) == len(w) >= 1
        assert tuple(g) == w and g == w and g[0] == w[0]
        assert sorted(g, key=lambda x: -x[1]) == sorted(w, key=lambda x: -x[1])
    bad = np.full(16, np.nan)
    assert lazy.add_deferred(bad) is None and eager.add(bad) is None
    assert FlightSets(SetRule("classifier x moment balance", 0.3, 0.95, 160)).add_deferred(np.full(16, 1 / 16)) is None


def test_a_suspect_raised_by_physics_is_worded_by_physics_too():
    # Rotor 2's omega^2 share rises by 10 % while the network's P stays low (it raises nothing) but its recent set
    # says {2, 3}. The NOTICE, raised by the shares alone, names rotor 2 as the FAULT does: the network words only
    # what its own statistics raised (before, the daemon's NOTICE read "PROP 2+3 SUSPECT", naming a healthy rotor).
    ann = _fly_with_a_network_set(_labels({9: 1.0}), np.full(4, 0.01), share_rotor=2)  # label 9 = {2, 3}
    # (and the network's P of 0.01 for rotor 2 is not quoted on the FAULT: it disagrees)
    assert [(a.level, a.text) for a in ann][:2] == [("suspect", "PROP 2 SUSPECT"), ("fault", "PROP 2 FAULT")], ann
    assert all(a.propellers == (2,) for a in ann)
    # A NOTICE the network raised (its P for rotor 1 at 0.999, the shares quiet) is worded by its set: {1} or {1, 2}.
    q = np.full(16, 0.01)
    q[1], q[5] = 0.5, 0.35
    ann = _fly_with_a_network_set(q / q.sum(), [0.999, 0.01, 0.01, 0.01], share_rotor=None, seed=1)
    assert [(a.level, a.text) for a in ann] == [("suspect", "PROP 1 or 1+2?")], ann
