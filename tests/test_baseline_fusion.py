"""``diagnose LOG --vehicle DIR``: the verdict fuses the classifier with the airframe's healthy baseline (issue 14)."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest
from test_diagnose_fixtures import build_model, run_diagnose, write_tlog
from test_diagnose_json_schema import documented, key_paths

from monitor.baseline import BASELINE_FILE, HealthyBaseline, baseline_from_tables, fuse
from monitor.labels import LABEL_TABLE, label_from_mask
from monitor.vehicle import DEFAULT_VEHICLE, REPO_ROOT


def _probs(**by_label) -> np.ndarray:
    p = np.full(16, 0.0)
    for k, v in by_label.items():
        p[int(k[1:]) - 1] = v
    return p


def label_of(*rotors) -> int:
    return label_from_mask([i + 1 in rotors for i in range(4)])


def test_fuse_rule_by_hand():
    healthy_says = _probs(l1=0.7, l3=0.3)
    # One rotor beyond 3 spreads: that rotor, whatever the classifier said.
    f = fuse([0.5, 5.0, -1.0, -2.0], healthy_says, 1, True)
    assert (f["label"], f["faulty_propellers"], f["confidence"]) == (label_of(2), [2], "confident")
    # Exactly 3 spreads is not beyond; far *below* the share is not a damaged propeller's signature alone.
    f = fuse([3.0, -4.0, 0.0, 0.0], _probs(l2=0.6, l1=0.4), 2, False)
    assert (f["label"], f["confidence"]) == (1, "confident") and "healthy" in f["rule"]
    # No rotor beyond: a confident classifier still stands.
    assert fuse([0.0, 0.0, 0.0, 0.0], _probs(l5=0.95), 5, True)["faulty_propellers"] == [4]
    # Two rotors beyond: the classifier picks among {2}, {4}, {2, 4}; confident only with >= 0.9 of their mass.
    pair = label_of(2, 4)
    f = fuse([0.0, 4.0, 0.0, 6.0], _probs(l1=0.5, **{f"l{pair}": 0.475, f"l{label_of(4)}": 0.025}), 1, False)
    assert (f["label"], f["confidence"]) == (pair, "confident")  # 0.475 / 0.5 = 0.95
    f = fuse([0.0, 4.0, 0.0, 6.0], _probs(**{f"l{pair}": 0.3, f"l{label_of(4)}": 0.5, f"l{label_of(2)}": 0.2}), 1, False)
    assert (f["label"], f["confidence"]) == (label_of(4), "ambiguous")
    assert set(LABEL_TABLE[f["label"]]) <= {2, 4}
    with pytest.raises(ValueError, match="4 deviations and 16"):
        fuse([0.0] * 3, healthy_says, 1, True)


@pytest.fixture(scope="module")
def healthy_log(tmp_path_factory):
    return write_tlog(tmp_path_factory.mktemp("fuse") / "healthy.tlog", duration_s=12.0, faulty=None, seed=5)


def test_baseline_names_a_rotor_the_classifier_calls_healthy(tmp_path, healthy_log):
    """An airframe whose healthy flights load rotor 1 lightly: this flight's equal shares put rotor 1 far above
    its healthy share, and the fused verdict names it where the classifier alone says healthy."""
    d = tmp_path / "adapted"
    d.mkdir()
    shutil.copy(DEFAULT_VEHICLE, d / "vehicle.yaml")
    build_model(d / "classifier.onnx")
    code, out = run_diagnose([healthy_log, "--model", d / "classifier.onnx", "--json"])
    alone = json.loads(out)["verdict"]
    assert alone["label"] == 1  # the classifier alone: healthy
    # This flight's own shares, measured through the same code the CLI uses.
    light = HealthyBaseline("omega2", (1.0,) * 4, (0.0,) * 4, (0.05,) * 4, None, 20.0, 3, ("a",), ("1", "2", "3", "4"))
    light.save(d / BASELINE_FILE)
    seen = json.loads(run_diagnose([healthy_log, "--vehicle", d, "--json"])[1])["baseline"]["shares"]
    # Healthy shares 0.1 lower on rotor 1 (the others raised to keep the mean at 1): rotor 1 now sits
    # (s1 - (s1 - 0.1)) / 0.02 = 5 spreads above it, the others (0.1/3)/0.02 = 1.7 below.
    mean = np.asarray(seen) + np.array([-0.1, 0.1 / 3, 0.1 / 3, 0.1 / 3])
    for separable in (None, False):
        HealthyBaseline(
            "omega2", tuple(mean), (0.0,) * 4, (0.05,) * 4, None, 20.0, 3, ("a",), ("1", "2", "3", "4"), separable, "test"
        ).save(d / BASELINE_FILE)
        code, out = run_diagnose([healthy_log, "--vehicle", d, "--json"])
        res = json.loads(out)
        assert res["baseline"]["deviation_spreads"] == pytest.approx([5.0, -5 / 3, -5 / 3, -5 / 3], abs=0.01)
        assert res["baseline"]["fusion"]["classifier_label"] == 1 and res["baseline"]["fusion"]["spreads_required"] == 3.0
        undocumented = key_paths(res) - set(documented())
        assert not undocumented, f"undocumented keys: {sorted(undocumented)}"
        text = run_diagnose([healthy_log, "--vehicle", d])[1]
        assert "verdict from the baseline and the classifier (label 1 alone): baseline: PX4 rotor(s) [1]" in text, text
        if separable is None:  # nobody measured CG offset against damage: the rotor is named
            assert res["verdict"]["faulty_propellers"] == [1] and res["verdict"]["confidence"] == "confident" and code == 0
            assert [p["faulty"] for p in res["propellers"]] == [True, False, False, False]
            assert "Propeller 1 (front-right) is damaged: replace it." in text, text
        else:  # measured alike: an imbalance near rotor 1, no propeller called faulty
            assert res["verdict"]["faulty_propellers"] == [] and res["verdict"]["imbalance_rotors"] == [1] and code == 3
            assert not any(p["faulty"] for p in res["propellers"])
            assert "Imbalance near propeller 1 (front-right): a shifted load or battery, or a damaged propeller." in text, text
            assert "REPLACE" not in text, text


CRAZYPAD = REPO_ROOT.parent / "shared" / "data" / "crazypad"
E8 = CRAZYPAD / "motor" / "normal_flight"


@pytest.mark.realdata
@pytest.mark.skipif(not E8.is_dir(), reason=f"CrazyPAD data not found at {CRAZYPAD}")
def test_real_crazypad_flights_baseline_corrects_the_classifier(tmp_path):
    """E8's baseline from its even-numbered healthy logs, the shipped Crazyflie classifier: a 3 mm cut on M3 that the
    classifier alone calls a pair, and a held-out healthy flight it calls faulty, both set right by the baseline."""
    from monitor.logs import read_log
    from monitor.vehicle import load_vehicle

    crazyflie = REPO_ROOT / "models" / "crazyflie.yaml"
    esc = load_vehicle(crazyflie).esc
    cal = [E8 / f"E8_log0{i}.csv.gz" for i in (0, 2, 4, 6)]
    base = baseline_from_tables([read_log(p, fmt="crazypad", esc=esc) for p in cal], [p.name for p in cal])
    d = tmp_path / "E8"
    d.mkdir()
    shutil.copy(crazyflie, d / "vehicle.yaml")
    shutil.copy(REPO_ROOT / "models" / "crazyflie-classifier.onnx", d / "classifier.onnx")
    base.save(d / BASELINE_FILE)
    cut = CRAZYPAD / "motor" / "cut_propeller_M3_3mm" / "E8_log02.csv.gz"
    res = json.loads(run_diagnose([cut, "--format", "crazypad", "--vehicle", d, "--json"])[1])
    assert res["baseline"]["fusion"]["classifier_label"] != label_of(2)  # the classifier alone: not M3 alone
    assert res["verdict"]["faulty_propellers"] == [2] and res["verdict"]["faulty_names"] == ["M3"]
    # The shipped CrazyPAD finding (cg_damage_separable false): the same flight is an imbalance near M3, not a fault.
    from offline.crazypad.evidence import CG_DAMAGE_EVIDENCE, CG_DAMAGE_SEPARABLE

    replace(base, cg_damage_separable=CG_DAMAGE_SEPARABLE, cg_damage_evidence=CG_DAMAGE_EVIDENCE).save(d / BASELINE_FILE)
    res = json.loads(run_diagnose([cut, "--format", "crazypad", "--vehicle", d, "--json"])[1])
    assert res["verdict"]["faulty_propellers"] == [] and res["verdict"]["imbalance_names"] == ["M3"]
    assert [h["faulty_propellers"] for h in res["hypotheses"]] == [[2], []]
    base.save(d / BASELINE_FILE)
    healthy = E8 / "E8_log05.csv.gz"
    res = json.loads(run_diagnose([healthy, "--format", "crazypad", "--vehicle", d, "--json"])[1])
    assert res["baseline"]["fusion"]["classifier_label"] != 1  # the classifier alone: a false alarm
    assert res["verdict"]["label"] == 1 and res["verdict"]["faulty_propellers"] == []


def test_student_t_spreads_by_hand():
    """A new flight against the mean and std of n healthy flights: t_{n-1} at the Gaussian 3-sigma tail, times
    sqrt(1 + 1/n). By hand for n = 4: t_3.isf(0.0013499) = 9.2189 (tables), times sqrt(1.25) = 10.307."""
    from monitor.baseline import T_ISF_3SIGMA, t_spreads_required

    assert t_spreads_required(1) is None
    assert t_spreads_required(4) == pytest.approx(9.2189 * np.sqrt(1.25), rel=1e-6)
    assert t_spreads_required(31) == pytest.approx(3.2703 * np.sqrt(1 + 1 / 31), rel=1e-6)
    # Many flights: back toward the Gaussian 3 (first-order expansion past the table, continuous at its end).
    assert 3.0 < t_spreads_required(1000) < 3.02
    assert abs(t_spreads_required(32) - t_spreads_required(31)) < 0.05
    stats = pytest.importorskip("scipy.stats")
    tail = stats.norm.sf(3.0)
    assert T_ISF_3SIGMA == pytest.approx([stats.t.isf(tail, df) for df in range(1, 31)], abs=1e-4)


def test_compare_reports_the_t_rule_beside_the_3_spread_rule(healthy_log):
    """Rotor 1 at 5 spreads above a 4-flight baseline: beyond 3 spreads, not beyond the t rule's 10.31."""
    from monitor.baseline import flight_shares
    from monitor.logs import read_log

    table = read_log(healthy_log)
    seen, basis = flight_shares(table)
    mean = seen + np.array([-0.1, 0.1 / 3, 0.1 / 3, 0.1 / 3])
    b = HealthyBaseline(basis, tuple(mean), (0.0,) * 4, (0.05,) * 4, None, 20.0, 4, ("a",), ("1", "2", "3", "4"))
    res = b.compare(table)
    assert res["rotors_beyond_3_spreads"] == [1]
    assert res["t_spreads_required"] == pytest.approx(10.31) and res["rotors_beyond_t_spreads"] == []
    one = HealthyBaseline(basis, tuple(mean), (0.0,) * 4, (0.05,) * 4, None, 20.0, 1, ("a",), ("1", "2", "3", "4"))
    assert one.compare(table)["t_spreads_required"] is None and one.compare(table)["rotors_beyond_t_spreads"] is None
