"""offline.tune.sets.tune_sets end to end, on small data sets of our simulator and the shipped model:
regions beyond the register shape the set rule but not the airframe check, the torque-sign check is applied, and
the rule written is the one ``choose`` picks from the candidates it records."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.vehicle import DEFAULT_VEHICLE, REPO_ROOT, load_vehicle

MODEL = REPO_ROOT / "models" / "classifier.onnx"
TORQUE = "*torque_per_thrust_change*"


def _write(tmp_path, name, seed, airframe="nominal", torque=None, flights_per_label=2):
    import fnmatch

    from offline.dataset.generate import DatasetSpec, generate
    from offline.dataset.records import save_dataset
    from offline.sim.assumptions import REGISTER, nominal_airframe

    register = nominal_airframe() if airframe == "nominal" else REGISTER
    if torque is not None:
        for n in fnmatch.filter(register.names, TORQUE):
            register = register.with_range(n, *torque)
    spec = DatasetSpec(
        name,
        fault="varied",
        waypoints=("random",),
        flights_per_label=flights_per_label,
        duration_s=20.0,
        propellers="quadratic",
        physics="randomised",
        seed=seed,
    )
    ds = generate(spec, load_vehicle(DEFAULT_VEHICLE), log=lambda *_: None, register=register)
    return save_dataset(tmp_path / f"{name}.npz", ds)


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    from offline.tune.sets import tune_sets

    tmp = tmp_path_factory.mktemp("conformal")
    paths = {
        "register": _write(tmp, "reg", 1),
        "beyond": _write(tmp, "beyond", 2, torque=(-0.25, -0.10)),
        "up": _write(tmp, "up", 3, torque=(0.02, 0.10)),
        "down": _write(tmp, "down", 3, torque=(-0.10, -0.02)),
        "drawn": _write(tmp, "drawn", 4, airframe="drawn", flights_per_label=3),
    }
    res = tune_sets(
        MODEL,
        [paths["register"]],
        [],
        0.9,  # a small test: 0.9 needs 9 flights per region, 0.95 needs 19
        log=lambda *_: None,
        unmeasured=[paths["drawn"]],
        sparsity_grid=(1.0, 0.1),
        classifier_weights=(1.0, 0.5),
        sign_check=(paths["up"], paths["down"]),
        beyond=[paths["beyond"]],
    )
    return res, paths


def test_the_rule_written_is_the_one_choose_picks_from_every_candidate_it_records(calibrated):
    from offline.tune.sets import choose

    res, _ = calibrated
    rule, cands = res["rule"], res["all_candidates"]
    # two priors x (classifier at two weights, balance, fused at two weights)
    assert len(cands) == 2 * 5 and all("torque_sign_move" in c for c in cands)
    # the classifier's own threshold (the daemon's wording) is the one at the chosen prior and weight
    own = res["candidates"]["classifier"]
    assert (own["sparsity_prior"], own["classifier_weight"]) == (rule["sparsity_prior"], rule["classifier_weight"])
    best = choose([dict(c) for c in cands])
    assert (rule["score"], rule["sparsity_prior"], rule["classifier_weight"]) == (
        best["score"],
        best["sparsity_prior"],
        best["classifier_weight"],
    )
    assert rule["torque_sign_move"] == best["torque_sign_move"]
    if any(c["torque_sign_move"] <= 0.02 for c in cands):
        assert rule["torque_sign_move"] <= 0.02


def test_beyond_register_regions_count_for_the_rule_not_for_the_airframe_check(calibrated):
    from monitor.model import Classifier
    from offline.tune.sets import AIRFRAME_CHECK_QUANTILE, region_of

    res, paths = calibrated
    assert res["beyond_register"] == [str(paths["beyond"])]
    assert res["rule"]["calibration_flights"] == 2 * 32  # the register's region and the one beyond it
    regions = res["airframe_check"]["as_diagnose_runs_it"]
    assert {"reg", "beyond", "drawn"} <= set(regions)
    clf, vehicle = Classifier(MODEL), load_vehicle(DEFAULT_VEHICLE)
    reg = region_of(paths["register"], clf, vehicle)
    # the check's threshold is the register region's own quantile: the region beyond it does not move it
    assert res["airframe_check"]["log_bayes_factor_max"] == pytest.approx(
        float(np.quantile(reg.airframe_log_bayes_factor, AIRFRAME_CHECK_QUANTILE))
    )
    assert set(res["airframe_check"]["flagged"]) == {"reg", "drawn"}


def test_a_rule_file_with_a_weight_is_what_diagnose_reads(calibrated, tmp_path):
    import json

    from monitor.decision.hypotheses import load_rule, rule_path

    res, _ = calibrated
    model = tmp_path / "m.onnx"
    rule_path(model).write_text(json.dumps({"rule": res["rule"], "candidates": res["candidates"]}))
    got = load_rule(model)
    assert (got.score, got.classifier_weight, got.sparsity_prior) == (
        res["rule"]["score"],
        res["rule"]["classifier_weight"],
        res["rule"]["sparsity_prior"],
    )
    assert got.threshold_for(got.score) == res["rule"]["threshold"]
