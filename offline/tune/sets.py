"""Split-conformal hypothesis sets for a classifier, calibrated on OUR simulator with randomised physics.

    propwatch tune sets --model models/classifier.onnx \\
        --data out/data-rncal/RNcal-varied.npz --data out/data-rnfall/RNfall-varied.npz \\
        --data out/data-rnrise/RNrise-varied.npz [--beyond out/data-rnsevere/RNsevere-varied.npz ...] \\
        [--sign-check TSup-varied.npz TSdown-varied.npz] [--check out/data-rrcal/RRcal-varied.npz] [--coverage 0.95]

(`make card` runs it with every region it builds.)

Each ``--data`` set is a *region*: flights the classifier never trained on, every physics term drawn from the
assumption register, some with one range moved (``propwatch dataset --assumption``; e.g. the damaged blade's
torque per thrust falling, -30..0 %, or rising, 0..+30 %), and ``--beyond`` regions past the register's ranges
(``make card``: hover losses of 12-25 %): the register is a statement of ignorance that may itself be wrong, and a
rule must not fall apart just outside it. For every flight the three candidate scores of
``monitor.decision.hypotheses`` are computed (the classifier's mean label probability, that times the moment balance's
likelihood, the balance alone), each under every sparsity prior rho of ``SPARSITY_GRID``; the two with the
classifier also under every classifier weight tau of ``CLASSIFIER_WEIGHT_GRID`` (the network's split within each
yaw class, the sets only the unmeasured yaw torque separates, as p**tau: the network learned the register's own
distribution of that torque, the balance states and marginalises its prior; ``monitor.decision.hypotheses.YAW_CLASS``). A
candidate's threshold is the smallest of its regions' own split-conformal thresholds (the score the truth reaches
in all but ``1 - coverage`` of that region's flights), so the coverage holds in each region, not only on average
over the register: whichever way the unmeasured torque goes. The rule chosen (``choose``) passes the torque-sign
check (``--sign-check``: two sets alike but for the sign of that torque change; single-propeller accuracy may move
by 2 points at most), then is one whose single-propeller accuracy is never below the ω²-share baseline on any
region (the issue's floor; where none is, the least shortfall), then the smallest worst-region set size, then the
weakest prior; it is written as ``<model>.sets.json`` beside the model, with a manifest.
``--check`` data sets (e.g. an unmeasured airframe) are only measured. The evaluation-only simulator is never
read here.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.decision.effectiveness import Evidence, HypothesisBank, Priors, RotorGeometry
from monitor.decision.hypotheses import SCORES, flight_score, hypothesis_set, rule_path
from monitor.diagnose.physics import airframe_log_bayes_factor
from monitor.features import compute_features, sliding_windows
from monitor.labels import LABEL_TABLE
from monitor.model import Classifier
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.dataset.records import FaultDataset, load_dataset
from offline.manifest import make_manifest, write_manifest
from offline.tune.noise import WARMUP_STEPS, flight_balances

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


def physics_log_likelihoods(ds: FaultDataset, vehicle, *priors: Priors) -> np.ndarray:
    """(F, 16) the moment balance's marginal log-likelihood of each set, per flight; with several ``priors``
    (k, F, 16), one per priors, from the same balances (computed once; the priors share their noise model)."""
    each = priors or (Priors(),)
    geometry = RotorGeometry.from_vehicle(vehicle)
    banks = [HypothesisBank(p, geometry) for p in each]
    out = [[] for _ in each]
    for z, h, std in flight_balances(ds, geometry):
        for o, p, bank in zip(out, each, banks, strict=True):
            ev = Evidence()
            ev.add(z, h, std, p)
            o.append(bank.posterior(ev).log_likelihood)
    res = np.asarray(out)
    return res if len(priors) > 1 else res[0]


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
    return set_metrics([hypothesis_set(s, threshold) for s in scores], truth)


def set_metrics(sets: list[list[dict]], truth: np.ndarray) -> dict:
    """Coverage, size and accuracy of per-flight hypothesis sets (``hypothesis_set``'s form) against the truth."""
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


SPARSITY_GRID = (1.0, 0.5, 0.3, 0.2, 0.15, 0.1, 0.07, 0.05, 0.03)
CLASSIFIER_WEIGHT_GRID = (1.0, 0.5, 0.25, 0.1)  # tau of the scores with the classifier in them
BALANCE = "moment balance"


@dataclass(frozen=True)
class Region:
    """One calibration set: flights of our simulator with one part of the register's ranges (e.g. the torque
    change falling, or rising), its truth, the per-flight inputs of every score and the ω²-share verdicts."""

    name: str
    truth: np.ndarray  # (F,) label index 0..15
    label_probability: np.ndarray  # (F, 16) the classifier's flight-mean
    log_likelihood: np.ndarray  # (F, 16) the moment balance's
    share_rotor: np.ndarray  # (F,) the ω²-share baseline's rotor 1..4
    log_likelihood_unmeasured: np.ndarray | None = None  # (F, 16) the balance with an unmeasured airframe
    airframe_log_bayes_factor: np.ndarray | None = None  # (F,) the airframe check's statistic
    manifest: dict | None = None  # the data set's manifest, as it was read (written beside the rule)

    def unmeasured(self, flagged_above: float) -> Region:
        """The flights of this region the airframe check flags, scored as an unmeasured airframe."""
        keep = self.airframe_log_bayes_factor > flagged_above
        return Region(
            name=self.name,
            truth=self.truth[keep],
            label_probability=self.label_probability[keep],
            log_likelihood=self.log_likelihood_unmeasured[keep],
            share_rotor=self.share_rotor[keep],
        )


def region_of(path: Path, clf: Classifier, vehicle) -> Region:
    return region_from_dataset(load_dataset(path), path.stem, clf, vehicle)


def region_from_dataset(ds: FaultDataset, name: str, clf: Classifier, vehicle) -> Region:
    """A region's per-flight inputs of every score (classifier, moment balance, airframe check, ω²-share)."""
    ds.check_model(clf.info.metadata["vehicle"]["name"], clf.info.sample_rate_hz, clf.info.features)
    base, check = Priors(), Priors().for_airframe_check()
    ll, ll_u, check_n, check_u = physics_log_likelihoods(
        ds, vehicle, base, base.with_unmeasured_airframe(), check, check.with_unmeasured_airframe()
    )
    return Region(
        name=name,
        truth=truth_labels(ds),
        label_probability=classifier_probabilities(ds, clf),
        log_likelihood=ll,
        share_rotor=share_rotors(ds),
        log_likelihood_unmeasured=ll_u,
        # the airframe check's statistic per flight, as monitor.diagnose.physics computes it for a log
        airframe_log_bayes_factor=np.array([airframe_log_bayes_factor(a, b) for a, b in zip(check_n, check_u, strict=True)]),
        manifest=ds.manifest,
    )


def share_rotors(ds: FaultDataset) -> np.ndarray:
    """(F,) the ω²-share baseline's rotor (offline/share_baseline.py) per flight, after the first 5 s."""
    rpm = ds.signals["motor_rpm"][:, WARMUP_STEPS:, :].astype(np.float64)
    w2 = np.square(rpm).mean(axis=1)
    return np.argmax(w2 / w2.mean(axis=1, keepdims=True), axis=1) + 1


def region_scores(r: Region, score: str, sparsity_prior: float, classifier_weight: float = 1.0) -> np.ndarray:
    return np.array(
        [
            flight_score(p, ll, score, sparsity_prior, classifier_weight)
            for p, ll in zip(r.label_probability, r.log_likelihood, strict=True)
        ]
    )


def share_singles(r: Region) -> float | None:
    single = [i for i, t in enumerate(r.truth) if len(LABEL_TABLE[t + 1]) == 1]
    if not single:
        return None
    return float(np.mean([LABEL_TABLE[r.truth[i] + 1] == (int(r.share_rotor[i]),) for i in single]))


def candidate(regions: list[Region], score: str, sparsity_prior: float, coverage: float, classifier_weight: float = 1.0) -> dict:
    """One (score, rho, tau): the threshold that covers every region (the smallest of their own thresholds), and
    what it gives on each region."""
    sc = {r.name: region_scores(r, score, sparsity_prior, classifier_weight) for r in regions}
    own = {r.name: conformal_threshold(sc[r.name][np.arange(len(r.truth)), r.truth], coverage) for r in regions}
    thr = min(own.values())
    per = {r.name: {"threshold_alone": own[r.name], **measure(sc[r.name], r.truth, thr)} for r in regions}
    shortfall = [share_singles(r) - per[r.name]["single_exact"] for r in regions if per[r.name]["single_exact"] is not None]
    beats_share = all(x <= 0 for x in shortfall)
    return {
        "score": score,
        "sparsity_prior": sparsity_prior,
        "classifier_weight": classifier_weight,
        "threshold": thr,
        "regions": per,
        "worst_set_size": max(m["mean_set_size"] for m in per.values()),
        "singles_never_below_share": beats_share,
        "worst_singles_shortfall": max([0.0, *shortfall]),  # the most any region's singles fall below the share
    }


SIGN_CHECK_MAX_MOVE = 0.02  # single-propeller accuracy may move by at most 2 points when the torque flips


def torque_sign_move(up: Region, down: Region, score: str, sparsity_prior: float, classifier_weight: float) -> float:
    """How far single-propeller accuracy (the most probable set) moves between flights whose damaged blades'
    torque per thrust rises and flights where it falls, everything else alike (the issue's torque-sign check)."""

    def singles(r: Region) -> float:  # the most probable set is first whatever the threshold
        return measure(region_scores(r, score, sparsity_prior, classifier_weight), r.truth, 1.0)["single_exact"]

    return abs(singles(up) - singles(down))


def choose(cands: list[dict]) -> dict:
    """A candidate that passes the torque-sign check where one was measured (``torque_sign_move`` <= 2 points; if
    none passes, the check is not applied); of those, one whose singles are never below the ω²-share baseline on
    any region (none qualifying: those whose singles fall least below it on their worst region,
    ``worst_singles_shortfall``); among those the smallest worst-region set size, then the weakest sparsity prior
    (largest rho), then the largest classifier weight. Without shortfalls on record (older candidate lists), the
    strongest prior tried."""
    signed = [c for c in cands if c.get("torque_sign_move", 0.0) <= SIGN_CHECK_MAX_MOVE + 1e-9]
    cands = signed or cands
    ok = [c for c in cands if c["singles_never_below_share"]]
    if not ok and all("worst_singles_shortfall" in c for c in cands):
        least = min(c["worst_singles_shortfall"] for c in cands)
        ok = [c for c in cands if c["worst_singles_shortfall"] <= least + 1e-12]
    ok = ok or [c for c in cands if c["sparsity_prior"] == min(x["sparsity_prior"] for x in cands)]
    return min(
        ok,
        key=lambda c: (
            round(c["worst_set_size"], 9),
            -c["sparsity_prior"],
            -c.get("classifier_weight", 1.0),
            SCORES.index(c["score"]),
        ),
    )


AIRFRAME_CHECK_QUANTILE = 0.98  # flights of an airframe as its file says flagged at most this rarely, per region


def airframe_check(
    nominal: list[Region], unmeasured: list[Region], score: str, rho: float, coverage: float, log, tau: float = 1.0
) -> dict:
    """The airframe check's threshold (the log Bayes factor that at most 2 % of each nominal region's flights
    exceed) and the conformal threshold of ``score`` under an unmeasured airframe, covering the flights the
    check flags in each of ``unmeasured``'s regions (drawn airframes, scored with the widened balance)."""
    bf_max = max(float(np.quantile(r.airframe_log_bayes_factor, AIRFRAME_CHECK_QUANTILE)) for r in nominal)
    flagged_regions = [r.unmeasured(bf_max) for r in unmeasured]
    c = candidate(flagged_regions, score, rho, coverage, tau)
    flagged = {r.name: float(np.mean(r.airframe_log_bayes_factor > bf_max)) for r in [*nominal, *unmeasured]}
    for name, f in flagged.items():
        log(f"airframe check: {name} flagged {100 * f:.1f} % (log Bayes factor > {bf_max:.2f})")
    for name, m in c["regions"].items():
        log(f"unmeasured airframe on {name}: " + fmt(m))
    return {
        "log_bayes_factor_max": bf_max,
        "quantile": AIRFRAME_CHECK_QUANTILE,
        "unmeasured_threshold": c["threshold"],
        "unmeasured_calibration_flights": int(sum(len(r.truth) for r in flagged_regions)),
        "flagged": flagged,
        "unmeasured_regions": c["regions"],
    }


def measure_with_check(r: Region, score: str, rho: float, threshold: float, check: dict, tau: float = 1.0) -> dict:
    """``measure`` as diagnose answers: flights the check flags get the unmeasured airframe's scores and threshold."""
    flag = r.airframe_log_bayes_factor > check["log_bayes_factor_max"]
    nominal = region_scores(r, score, rho, tau)
    wide = region_scores(dataclasses.replace(r, log_likelihood=r.log_likelihood_unmeasured), score, rho, tau)
    sets = [
        hypothesis_set(wide[i], check["unmeasured_threshold"]) if flag[i] else hypothesis_set(nominal[i], threshold)
        for i in range(len(r.truth))
    ]
    m = set_metrics(sets, r.truth)
    first = [hs[0]["faulty_propellers"] for hs in sets]
    m["sure_and_wrong"] = float(
        np.mean([len(hs) == 1 and f != list(LABEL_TABLE[t + 1]) for hs, f, t in zip(sets, first, r.truth)])
    )
    return {"flights": m.pop("flights"), "flagged": float(np.mean(flag)), **m}


def tune_sets(
    model: Path,
    data: list[Path],
    checks: list[Path],
    coverage: float,
    log=print,
    unmeasured: list[Path] = (),
    sparsity_grid: tuple[float, ...] = SPARSITY_GRID,
    classifier_weights: tuple[float, ...] = CLASSIFIER_WEIGHT_GRID,
    sign_check: tuple[Path, ...] = (),
    beyond: list[Path] = (),
) -> dict:
    clf = Classifier(model)
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    register = [region_of(p, clf, vehicle) for p in data]
    # beyond the register: they shape the set rule (coverage, singles, sizes) but not the airframe check, whose
    # premise is damage as the register says on an airframe as its file says
    regions = [*register, *(region_of(p, clf, vehicle) for p in beyond)]
    signs = [region_of(p, clf, vehicle) for p in sign_check]  # (rising, falling) or none
    for r in regions:
        s = share_singles(r)
        log(f"{r.name}: {len(r.truth)} flights, ω²-share singles {'-' if s is None else f'{100 * s:.1f} %'}")
    cands = [
        candidate(regions, s, rho, coverage, tau)
        for rho in sparsity_grid
        for s in SCORES
        for tau in (classifier_weights if s != BALANCE else (1.0,))
    ]
    if signs:
        for c in cands:
            c["torque_sign_move"] = torque_sign_move(*signs, c["score"], c["sparsity_prior"], c["classifier_weight"])
    for c in cands:
        log(
            f"{c['score']:30s} rho {c['sparsity_prior']:<5g} tau {c['classifier_weight']:<4g} threshold {c['threshold']:.5f} "
            f"worst size {c['worst_set_size']:.2f} singles >= share: {'yes' if c['singles_never_below_share'] else 'no'}"
            + (f"  torque-sign move {100 * c['torque_sign_move']:.1f}" if "torque_sign_move" in c else "")
            + "  exact / singles % by region: "
            + "  ".join(_pct(m["exact"]) + "/" + _pct(m["single_exact"]) for m in c["regions"].values())
        )
    best = choose(cands)
    for name, m in best["regions"].items():
        log(f"chosen on {name}: " + fmt(m))
    rho, tau = best["sparsity_prior"], best["classifier_weight"]
    # every score at the chosen prior and weight: the daemon words its alerts with the classifier's own threshold
    measured = {
        c["score"]: c
        for c in cands
        if c["sparsity_prior"] == rho and c["classifier_weight"] == (1.0 if c["score"] == BALANCE else tau)
    }
    checked = {}
    for path in checks:
        other = region_of(path, clf, vehicle)
        m = measure(region_scores(other, best["score"], rho, tau), other.truth, best["threshold"])
        checked[path.name] = {"manifest": other.manifest.get("config"), **m}
        log(f"check {path.name}  {best['score']:30s} threshold {best['threshold']:.5f}  " + fmt(m))
    check = None
    if unmeasured:
        drawn = [region_of(p, clf, vehicle) for p in unmeasured]
        check = airframe_check(register, drawn, best["score"], rho, coverage, log, tau)
        check["as_diagnose_runs_it"] = {}
        for r in [*regions, *drawn]:
            m = measure_with_check(r, best["score"], rho, best["threshold"], check, tau)
            check["as_diagnose_runs_it"][r.name] = m
            log(f"with the airframe check on {r.name}: " + fmt(m))
    return {
        "airframe_check": check,
        "rule": {
            "score": best["score"],
            "threshold": best["threshold"],
            "coverage": coverage,
            "calibration_flights": int(sum(len(r.truth) for r in regions)),
            "sparsity_prior": rho,
            "classifier_weight": tau,
            "selection": "torque-sign check passed (single-propeller accuracy moves <= 2 points between the sign "
            "check's rising and falling flights), then singles never below the ω²-share baseline on any region (else "
            "the least shortfall), then the smallest worst-region mean set size, then the largest rho, then the "
            "largest tau; threshold: the smallest region threshold (each region covered)",
            "torque_sign_move": best.get("torque_sign_move"),
        },
        "torque_sign_check": [
            {"path": str(p), "manifest": r.manifest.get("config")} for p, r in zip(sign_check, signs, strict=True)
        ],
        "candidates": measured,
        "all_candidates": [
            {
                k: c[k]
                for k in (
                    "score",
                    "sparsity_prior",
                    "classifier_weight",
                    "threshold",
                    "worst_set_size",
                    "singles_never_below_share",
                    "worst_singles_shortfall",
                    "torque_sign_move",
                )
                if k in c
            }
            for c in cands
        ],
        "calibration_data": [{"path": str(p), "manifest": r.manifest} for p, r in zip([*data, *beyond], regions, strict=True)],
        "beyond_register": [str(p) for p in beyond],
        "checks": checked,
    }


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f}"


def fmt(m: dict) -> str:
    s = m["single_exact"]
    return (
        f"truth in set {100 * m['truth_in_set']:5.1f} %  size {m['mean_set_size']:.2f}  exact {100 * m['exact']:5.1f} %"
        f"  singles {'-' if s is None else f'{100 * s:5.1f} %'}  one-member-and-right {100 * m['sure_and_right']:5.1f} %"
        f"  ({m['flights']} flights)"
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="propwatch tune sets", description=__doc__.splitlines()[0])
    p.add_argument("--model", type=Path, default=Path("models/classifier.onnx"), help="classifier ONNX")
    p.add_argument(
        "--data",
        type=Path,
        action="append",
        required=True,
        help="calibration data set (.npz, randomised physics, unseen); repeat for regions of the register "
        "(e.g. torque falling / rising): the rule must cover each",
    )
    p.add_argument(
        "--beyond",
        type=Path,
        action="append",
        default=[],
        help="a region with a range moved past the register's (e.g. hover losses of 12-25 %%): calibrated "
        "like --data, but not used for the airframe check's threshold (repeatable)",
    )
    p.add_argument("--check", type=Path, action="append", default=[], help="data sets only measured (repeatable)")
    p.add_argument(
        "--unmeasured",
        type=Path,
        action="append",
        default=[],
        help="regions of drawn airframes (propwatch dataset --airframe drawn): calibrate the airframe check and "
        "the sets of a flight it flags (repeatable)",
    )
    p.add_argument(
        "--sign-check",
        type=Path,
        nargs=2,
        metavar=("RISING", "FALLING"),
        default=(),
        help="two data sets alike but for the damaged blades' torque per thrust (rising, falling): only rules whose "
        "single-propeller accuracy moves <= 2 points between them are chosen (the torque-sign check)",
    )
    p.add_argument("--coverage", type=float, default=0.95, help="target coverage (default 0.95)")
    p.add_argument("--dry-run", action="store_true", help="print the figures, write nothing")
    p.add_argument(
        "--sparsity-prior",
        type=float,
        default=None,
        help="fix rho instead of choosing it from the grid (to compare models at one prior; the selection rule still "
        "picks the score)",
    )
    p.add_argument(
        "--classifier-weight",
        type=float,
        default=None,
        help="fix tau, the weight of the classifier's split inside a yaw class, instead of choosing it from the grid",
    )
    a = p.parse_args(argv)
    if a.sparsity_prior is not None and not 0.0 < a.sparsity_prior <= 1.0:
        p.error(f"--sparsity-prior must be in (0, 1], got {a.sparsity_prior}")
    if a.classifier_weight is not None and not 0.0 < a.classifier_weight <= 1.0:
        p.error(f"--classifier-weight must be in (0, 1], got {a.classifier_weight}")
    grid = SPARSITY_GRID if a.sparsity_prior is None else (a.sparsity_prior,)
    weights = CLASSIFIER_WEIGHT_GRID if a.classifier_weight is None else (a.classifier_weight,)
    res = tune_sets(
        a.model,
        a.data,
        a.check,
        a.coverage,
        unmeasured=a.unmeasured,
        sparsity_grid=grid,
        classifier_weights=weights,
        sign_check=tuple(a.sign_check),
        beyond=a.beyond,
    )
    if a.dry_run:
        return 0
    manifest = make_manifest("hypothesis-set-rule", {"model": str(a.model), "coverage": a.coverage}, None, **res)
    out = write_manifest(rule_path(a.model), manifest)
    print(f"wrote {out}: score '{res['rule']['score']}', threshold {res['rule']['threshold']:.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
