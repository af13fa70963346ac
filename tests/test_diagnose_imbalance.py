"""``diagnose --vehicle DIR``: where the airframe's baseline says a CG offset and a damaged propeller look alike,
a fault verdict becomes an ambiguous imbalance: "imbalance near ...: CG offset or damage" in text; in JSON no
propeller in ``faulty_propellers``, the rotors in ``imbalance_rotors``, both causes in ``hypotheses``, and why in
``baseline.cg_damage_separable``."""

from __future__ import annotations

import json
import re
import shutil

import pytest
from test_diagnose_fixtures import build_model, run_diagnose, write_tlog

from monitor.baseline import BASELINE_FILE, HealthyBaseline
from monitor.vehicle import DEFAULT_VEHICLE


def _folder(tmp_path, separable):
    """A `propwatch adapt`-shaped folder: vehicle.yaml, classifier.onnx (the fixture model), baseline.json."""
    d = tmp_path / f"adapted-{separable}"
    d.mkdir()
    shutil.copy(DEFAULT_VEHICLE, d / "vehicle.yaml")
    build_model(d / "classifier.onnx")
    HealthyBaseline(
        "omega2", (1.0,) * 4, (0.01,) * 4, (0.05,) * 4, None, 20.0, 2, ("a", "b"), ("1", "2", "3", "4"), separable, "a test"
    ).save(d / BASELINE_FILE)
    return d


@pytest.fixture(scope="module")
def faulty3(tmp_path_factory):
    return write_tlog(tmp_path_factory.mktemp("imb") / "f3.tlog", duration_s=12.0, faulty=3, seed=3)


def test_not_separable_words_a_one_rotor_verdict_as_an_imbalance(tmp_path, faulty3):
    d = _folder(tmp_path, False)
    code, text = run_diagnose([faulty3, "--vehicle", d])
    assert code == 3  # ambiguous: not a confident verdict
    assert "Imbalance near propeller 3 (front-left): a shifted load or battery, or a damaged propeller." in text, text
    assert "3 front-left INSPECT" in text and "REPLACE" not in text, text
    assert "why not sure: On this airframe's healthy flights a mass off centre and a damaged propeller" in text, text
    # The baseline's own words follow its deviations (shares alone never tell a CG offset from damage).
    assert re.search(r"healthy baseline \(spreads\): [-+\d., ]+ -> imbalance near 3: CG offset or damage", text), text
    code, out = run_diagnose([faulty3, "--vehicle", d, "--json"])
    res = json.loads(out)
    v = res["verdict"]
    assert code == 3 and v["faulty_propellers"] == [] and v["label"] == 1 and v["confidence"] == "ambiguous"
    assert v["imbalance_rotors"] == [3] and v["imbalance_names"] == ["3"]
    assert [h["faulty_propellers"] for h in res["hypotheses"]] == [[3], []]
    assert res["hypothesis_rule"] is None
    assert not any(p["faulty"] for p in res["propellers"]) and [p["suspect"] for p in res["propellers"]] == [
        False,
        False,
        True,
        False,
    ]
    assert res["baseline"]["cg_damage_separable"] is False


@pytest.mark.parametrize("separable", [None, True])
def test_unmeasured_or_separable_names_the_fault(tmp_path, faulty3, separable):
    d = _folder(tmp_path, separable)
    code, text = run_diagnose([faulty3, "--vehicle", d])
    assert code == 0 and "Propeller 3 (front-left) is damaged: replace it." in text and "3 front-left REPLACE" in text, text
    assert "Imbalance" not in text, text
    res = json.loads(run_diagnose([faulty3, "--vehicle", d, "--json"])[1])
    assert res["verdict"]["faulty_propellers"] == [3]
    assert ("cg_damage_separable" in res["baseline"]) == (separable is not None)


def test_old_baselines_without_the_key_still_load(tmp_path):
    d = _folder(tmp_path, False)
    raw = json.loads((d / BASELINE_FILE).read_text())
    del raw["cg_damage_separable"], raw["cg_damage_evidence"]
    b = HealthyBaseline.from_dict(raw)
    assert b.cg_damage_separable is None and b.imbalance_wording("M3") is None
    assert HealthyBaseline.load(d / BASELINE_FILE).imbalance_wording("M3 (PX4 rotor 2)") == (
        "imbalance near M3 (PX4 rotor 2): CG offset or damage"
    )
