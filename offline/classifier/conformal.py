"""Split-conformal hypothesis sets for a classifier, calibrated on OUR simulator with randomised physics.

    python -m offline.classifier.conformal --model models/classifier.onnx \\
        --data out/data-rncal/RNcal-varied.npz [--check out/data-rrcal/RRcal-varied.npz] [--coverage 0.95]

For every calibration flight (flights the classifier never trained on, every physics term drawn from the
assumption register) the three candidate scores of ``monitor.hypotheses`` are computed: the classifier's mean
label probability, that times the moment balance's likelihood, and the balance's likelihood alone. For each, the conformal threshold is
the score the truth reaches in all but ``1 - coverage`` of the flights (the ceil((n+1)·coverage)-th
smallest nonconformity 1 - score(truth)). The candidate with the smaller mean set size on the calibration
flights is written as the rule (``<model>.sets.json`` beside the model, with a manifest). ``--check``
data sets (e.g. an unmeasured airframe) are only measured, with the chosen threshold. The evaluation-only
simulator is never read here.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from monitor.effectiveness import Evidence, HypothesisBank, Priors, RotorGeometry
from monitor.features import compute_features, sliding_windows
from monitor.hypotheses import SCORES, flight_score, hypothesis_set, rule_path
from monitor.labels import LABEL_TABLE
from monitor.model import Classifier
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.dataset.records import FaultDataset, load_dataset
from offline.manifest import make_manifest, write_manifest
from offline.physics_calibration import WARMUP_STEPS, flight_balances

_LABEL_OF = {frozenset(v): k for k, v in LABEL_TABLE.items()}


def truth_labels(ds: FaultDataset) -> np.ndarray:
    """(F,) label index 0..15 of each flight."""
    return np.array([_LABEL_OF[frozenset(i + 1 for i in range(4) if c[i])] - 1 for c in ds.conditions])


def classifier_probabilities(ds: FaultDataset, clf: Classifier, hop: int = 10) -> np.ndarray:
    """(F, 16) mean label probability over each flight's windows after the first 5 s."""
    feats = compute_features(ds.signals, clf.info.features)
    out = []
    for f in range(ds.n_flights):
        w = sliding_windows(feats[f, WARMUP_STEPS:], clf.info.window, hop)
        labels, _ = clf.predict(np.ascontiguousarray(w))
        out.append(labels.mean(axis=0))
    return np.asarray(out)


def physics_log_likelihoods(ds: FaultDataset, vehicle, priors: Priors | None = None) -> np.ndarray:
    """(F, 16) the moment balance's marginal log-likelihood of each set, per flight."""
    priors = priors or Priors()
    geometry = RotorGeometry.from_vehicle(vehicle)
    bank = HypothesisBank(priors, geometry)
    out = []
    for z, h, std in flight_balances(ds, geometry):
        ev = Evidence()
        ev.add(z, h, std, priors)
        out.append(bank.posterior(ev).log_likelihood)
    return np.asarray(out)


def conformal_threshold(truth_scores: np.ndarray, coverage: float) -> float:
    """The score threshold whose sets hold the truth in >= ``coverage`` of exchangeable new flights."""
    n = len(truth_scores)
    k = math.ceil((n + 1) * coverage)
    if k > n:
        raise ValueError(
            f"{n} calibration flights cannot support coverage {coverage}: need >= {math.ceil(coverage / (1 - coverage))}"
        )
    nonconformity = np.sort(1.0 - np.asarray(truth_scores))
    return float(1.0 - nonconformity[k - 1])


def measure(scores: np.ndarray, truth: np.ndarray, threshold: float) -> dict:
    sets = [hypothesis_set(s, threshold) for s in scores]
    members = [[_LABEL_OF[frozenset(h["faulty_propellers"])] - 1 for h in hs] for hs in sets]
    single = [i for i, t in enumerate(truth) if len(LABEL_TABLE[t + 1]) == 1]
    return {
        "flights": len(truth),
        "truth_in_set": float(np.mean([t in m for t, m in zip(truth, members)])),
        "mean_set_size": float(np.mean([len(m) for m in members])),
        "exact": float(np.mean([m[0] == t for t, m in zip(truth, members)])),
        "single_exact": float(np.mean([members[i][0] == truth[i] for i in single])) if single else None,
        "sure_and_right": float(np.mean([m == [t] for t, m in zip(truth, members)])),
    }


def scores_of(ds: FaultDataset, clf: Classifier, vehicle) -> dict[str, np.ndarray]:
    p = classifier_probabilities(ds, clf)
    ll = physics_log_likelihoods(ds, vehicle)
    return {s: np.array([flight_score(p[f], ll[f], s) for f in range(ds.n_flights)]) for s in SCORES}


def calibrate(model: Path, data: Path, checks: list[Path], coverage: float, log=print) -> dict:
    clf = Classifier(model)
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    ds = load_dataset(data)
    ds.check_model(clf.info.metadata["vehicle"]["name"], clf.info.sample_rate_hz, clf.info.features)
    truth = truth_labels(ds)
    scores = scores_of(ds, clf, vehicle)
    measured = {}
    for s, sc in scores.items():
        thr = conformal_threshold(sc[np.arange(len(truth)), truth], coverage)
        measured[s] = {"threshold": thr, **measure(sc, truth, thr)}
        log(f"{data.name}  {s:30s} threshold {thr:.4f}  " + fmt(measured[s]))
    best = min(SCORES, key=lambda s: (measured[s]["mean_set_size"], SCORES.index(s)))
    thr = measured[best]["threshold"]
    checked = {}
    for path in checks:
        other = load_dataset(path)
        t = truth_labels(other)
        sc = scores_of(other, clf, vehicle)[best]
        checked[path.name] = {"manifest": other.manifest.get("config"), **measure(sc, t, thr)}
        log(f"{path.name}  {best:30s} threshold {thr:.4f}  " + fmt(checked[path.name]))
    return {
        "rule": {"score": best, "threshold": thr, "coverage": coverage, "calibration_flights": len(truth)},
        "candidates": measured,
        "calibration_data": {"path": str(data), "manifest": ds.manifest},
        "checks": checked,
    }


def fmt(m: dict) -> str:
    s = m["single_exact"]
    return (
        f"truth in set {100 * m['truth_in_set']:5.1f} %  size {m['mean_set_size']:.2f}  exact {100 * m['exact']:5.1f} %"
        f"  singles {'-' if s is None else f'{100 * s:5.1f} %'}  one-member-and-right {100 * m['sure_and_right']:5.1f} %"
        f"  ({m['flights']} flights)"
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m offline.classifier.conformal", description=__doc__.splitlines()[0])
    p.add_argument("--model", type=Path, default=Path("models/classifier.onnx"), help="classifier ONNX")
    p.add_argument("--data", type=Path, required=True, help="calibration data set (.npz, randomised physics, unseen)")
    p.add_argument("--check", type=Path, action="append", default=[], help="data sets only measured (repeatable)")
    p.add_argument("--coverage", type=float, default=0.95, help="target coverage (default 0.95)")
    p.add_argument("--dry-run", action="store_true", help="print the figures, write nothing")
    a = p.parse_args(argv)
    res = calibrate(a.model, a.data, a.check, a.coverage)
    if a.dry_run:
        return 0
    manifest = make_manifest("hypothesis-set-rule", {"model": str(a.model), "coverage": a.coverage}, None, **res)
    out = write_manifest(rule_path(a.model), manifest)
    print(f"wrote {out}: score '{res['rule']['score']}', threshold {res['rule']['threshold']:.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
