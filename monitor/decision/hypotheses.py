"""The verdict as a small set of propeller-set hypotheses with a stated coverage.

A flight's score over the 16 propeller sets is the classifier's mean label probability over its windows,
that times the moment balance's likelihood of each set (``monitor.decision.effectiveness``), or that likelihood
alone, renormalised: the calibration picks one of the three on our own data.
Split conformal prediction turns that score into a set: on flights of our own simulator with randomised
physics that the classifier never saw, the threshold is the score the truth reached in all but
``1 - coverage`` of them (``propwatch tune sets``, ``offline.tune.sets``, fits it and writes ``<model>.sets.json`` beside
the model). Every set scoring at least the threshold is a hypothesis; the most probable one is always in.
A sparsity prior ``rho`` multiplies a set of k damaged propellers by ``rho**k`` (k = 0 for healthy): where
physics cannot split two sets (a single rotor and that rotor with the opposite same-spin pair differ only
through the unmeasured torque change), the sparser one is named, and both stay in the set. ``rho`` is chosen
on our own stress sets by ``offline.tune.sets`` (the weakest prior whose singles never fall below
the ω²-share baseline on any torque region); 1 is no prior (older rule files).
One member: the verdict is that set. More: physics could not tell them apart, and the output says so
(the daemon words it as `monitor.decision.rule.statustext` does: ``PROP 1 or 1+2?``).

The coverage holds for flights like the calibration flights (whole flights of that simulator, the
airframe as its file says); it is a statement about that population, not a promise on any one log.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.errors import ModelError
from monitor.labels import LABEL_TABLE, N_LABELS

SCORES = ("classifier", "classifier x moment balance", "moment balance")


@dataclass(frozen=True)
class SetRule:
    score: str  # one of SCORES
    threshold: float  # a set is a hypothesis when its score >= threshold
    coverage: float  # target fraction of calibration flights whose truth is in the set
    calibration_flights: int
    source: str = ""
    # Every candidate score's own calibrated threshold (the JSON's "candidates"), e.g. the classifier alone,
    # which the daemon scores in flight where the moment balance of whole flights is not at hand.
    thresholds: tuple[tuple[str, float], ...] = ()
    sparsity_prior: float = 1.0  # rho: a set of k damaged propellers is weighted rho**k before normalising
    # tau: the classifier's split within each yaw class (sets that only the unmeasured yaw torque separates,
    # YAW_CLASS) enters every score it is in as p**tau (1: as it is, older files). Below 1 that certainty, learned
    # from the register's own torque distribution, counts for less (against the balance, which states and
    # marginalises its prior, where there is one); the network's probability of the class stays at full weight.
    classifier_weight: float = 1.0
    # The airframe check: a flight whose moment balance favours an unmeasured airframe over the vehicle file's
    # by more than this log Bayes factor (monitor.diagnose.physics) is scored with the balance under an
    # unmeasured airframe, at the threshold calibrated on such airframes. None: no check (older files).
    airframe_log_bayes_factor_max: float | None = None
    unmeasured_threshold: float | None = None
    unmeasured_calibration_flights: int = 0

    def threshold_for(self, score: str) -> float | None:
        """The calibrated threshold of ``score``; None when the calibration did not measure it."""
        if score == self.score:
            return self.threshold
        return dict(self.thresholds).get(score)

    def __post_init__(self) -> None:
        if self.score not in SCORES:
            raise ModelError(f"{self.source}: score must be one of {SCORES}, got {self.score!r}")
        if not (0.0 < self.threshold <= 1.0 and 0.0 < self.coverage < 1.0):
            raise ModelError(f"{self.source}: threshold must be in (0, 1] and coverage in (0, 1)")
        if self.unmeasured_threshold is not None and not (0.0 < self.unmeasured_threshold <= 1.0):
            raise ModelError(f"{self.source}: airframe_check.unmeasured_threshold must be in (0, 1]")
        if self.airframe_log_bayes_factor_max is not None and not np.isfinite(self.airframe_log_bayes_factor_max):
            raise ModelError(f"{self.source}: airframe_check.log_bayes_factor_max must be finite")
        if not (0.0 < self.sparsity_prior <= 1.0):
            raise ModelError(f"{self.source}: sparsity_prior must be in (0, 1], got {self.sparsity_prior}")
        if not (0.0 < self.classifier_weight <= 1.0):
            raise ModelError(f"{self.source}: classifier_weight must be in (0, 1], got {self.classifier_weight}")


def rule_path(model_path: str | Path) -> Path:
    """Where the set rule of ``model_path`` lives: ``classifier.onnx`` -> ``classifier.sets.json``."""
    p = Path(model_path)
    return p.with_name(p.stem + ".sets.json")


def load_rule(model_path: str | Path) -> SetRule | None:
    """The set rule beside ``model_path``, None when the model has none (an older or adapted model).

    Parsed once per file content (diagnose calls this for every log of a fleet ingest)."""
    path = rule_path(model_path)
    if not path.is_file():
        return None
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ModelError(f"{path}: not a set rule ({exc})") from exc
    return _parse_rule(path, data)


@functools.lru_cache(maxsize=8)
def _parse_rule(path: Path, data: bytes) -> SetRule:
    try:
        d = json.loads(data.decode("utf-8"))
        r = d["rule"]
        return SetRule(
            score=str(r["score"]),
            threshold=float(r["threshold"]),
            coverage=float(r["coverage"]),
            calibration_flights=int(r["calibration_flights"]),
            source=str(path),
            thresholds=tuple((str(k), float(v["threshold"])) for k, v in (d.get("candidates") or {}).items()),
            sparsity_prior=float(r.get("sparsity_prior", 1.0)),
            classifier_weight=float(r.get("classifier_weight", 1.0)),
            **_airframe_check(d.get("airframe_check")),
        )
    except (ValueError, KeyError, TypeError) as exc:
        raise ModelError(f"{path}: not a set rule ({exc})") from exc


_SET_SIZE = np.array([len(LABEL_TABLE[k]) for k in range(1, N_LABELS + 1)], dtype=np.float64)
SAME_SPIN_PAIRS = (frozenset((1, 2)), frozenset((3, 4)))  # PX4 quad-X: 1 and 2 spin CCW, 3 and 4 CW


def _yaw_classes() -> np.ndarray:
    """(16,) class index of each label (label order): two sets share a class when one is the other plus a same-spin
    pair it does not touch. Roll and pitch balance cannot tell them apart (the pair's two thrusts stay equal); only
    the yaw balance can, and that moves with the unmeasured torque per thrust of a damaged blade. A set's class is
    the set without the same-spin pairs it holds whole: {healthy, 1+2, 3+4, all four}, {1, 1+3+4}, {2, 2+3+4},
    {3, 1+2+3}, {4, 1+2+4}, and each cross pair alone."""

    def core(k: int) -> frozenset:
        s = frozenset(LABEL_TABLE[k])
        for pair in SAME_SPIN_PAIRS:
            if pair <= s:
                s = s - pair
        return s

    cores = [core(k) for k in range(1, N_LABELS + 1)]
    first = {c: i for i, c in reversed(list(enumerate(cores)))}  # each class numbered by its first label
    _, idx = np.unique([first[c] for c in cores], return_inverse=True)
    return idx


YAW_CLASS = _yaw_classes()


def _airframe_check(block: dict | None) -> dict:
    if not block:
        return {}
    return {
        "airframe_log_bayes_factor_max": float(block["log_bayes_factor_max"]),
        "unmeasured_threshold": float(block["unmeasured_threshold"]),
        "unmeasured_calibration_flights": int(block["unmeasured_calibration_flights"]),
    }


def flight_score(
    label_probability: np.ndarray,
    physics_log_likelihood: np.ndarray | None,
    score: str,
    sparsity_prior: float = 1.0,
    classifier_weight: float = 1.0,
) -> np.ndarray:
    """(16,) score of each propeller set (label order), summing to 1.

    ``label_probability``: the classifier's mean probability per label over the flight's windows.
    ``physics_log_likelihood``: the moment balance's marginal log-likelihood per set, or None when the log
    gave no usable balance (then the classifier's probability alone is the score, whatever ``score`` says).
    ``sparsity_prior``: rho, each set weighted rho**(its number of damaged propellers).
    ``classifier_weight``: tau, wherever the classifier's probability enters (the classifier alone, or times the
    balance) its split WITHIN each yaw class (``YAW_CLASS``: sets only the unmeasured yaw torque separates) enters as
    p**tau; its probability of the class itself (which rotors roll and pitch say, healthy or not) stays at full
    weight. Alone, the split is flattened toward equal (the sparsity prior then orders the class's members).
    """
    p = np.asarray(label_probability, dtype=np.float64)
    if p.shape != (N_LABELS,) or not np.all(np.isfinite(p)):
        raise ValueError(f"label_probability must be {N_LABELS} finite values")
    if score != "classifier" and physics_log_likelihood is not None:
        ll = np.asarray(physics_log_likelihood, dtype=np.float64)
        logp = ll - ll.max()
        if score == "classifier x moment balance":
            logp = logp + _classifier_log_weight(p, float(classifier_weight))
        p = np.exp(logp - logp.max())
    elif classifier_weight != 1.0:  # the classifier alone, or no balance to fuse
        logp = _classifier_log_weight(p, float(classifier_weight))
        p = np.exp(logp - logp.max())
    if sparsity_prior != 1.0:
        p = p * np.power(float(sparsity_prior), _SET_SIZE)
    return p / p.sum()


def _classifier_log_weight(p: np.ndarray, tau: float) -> np.ndarray:
    """(16,) log of the classifier's weight of each set: its yaw class's probability, shared among the class's sets
    in proportion to P(set | class)**tau (so each class keeps exactly the probability the classifier gave it)."""
    q = np.maximum(p, 1e-12)
    per_class = np.bincount(YAW_CLASS, weights=q)
    tempered = np.power(q / per_class[YAW_CLASS], tau)
    return np.log(per_class[YAW_CLASS]) + np.log(tempered / np.bincount(YAW_CLASS, weights=tempered)[YAW_CLASS])


def hypothesis_set(scores: np.ndarray, threshold: float) -> list[dict]:
    """Every set scoring >= ``threshold`` (the best one always), most probable first, as JSON-ready dicts."""
    order = np.argsort(-scores, kind="stable")
    keep = [int(k) for k in order if scores[k] >= threshold] or [int(order[0])]
    return [{"faulty_propellers": list(LABEL_TABLE[k + 1]), "probability": round(float(scores[k]), 4)} for k in keep]


class FlightSets:
    """The daemon's running set: the classifier's mean label probability over the last ``horizon`` windows (the
    daemon: the last second, each window itself spanning 5 s), against the classifier-alone threshold. Recent,
    not since take-off: a fault that begins mid-flight must word its alert from the windows that see it, not
    from the healthy minutes before (measured: since take-off, a propeller-2 onset 7 s old was worded
    ``PROP 1+2 or 1+2+3+4?``). Calibrated on whole-flight means, so over one second its coverage is only
    approximate; it words alerts, it does not raise them."""

    def __init__(self, rule: SetRule, horizon: int = 20):
        if horizon < 1:
            raise ValueError("horizon must be >= 1 window")
        self.threshold = rule.threshold_for("classifier")
        self.sparsity_prior = rule.sparsity_prior
        self.classifier_weight = rule.classifier_weight
        self._ring = np.zeros((int(horizon), N_LABELS))
        self.reset()

    def reset(self) -> None:
        self._ring[:] = 0.0
        self._head, self._n = 0, 0

    def add(self, label_probability: np.ndarray) -> tuple[tuple[tuple[int, ...], float], ...] | None:
        """Add one window; the set over the recent windows as ((propellers), probability) pairs, None without a
        threshold."""
        deferred = self.add_deferred(label_probability)
        return None if deferred is None else tuple(deferred)

    def add_deferred(self, label_probability: np.ndarray) -> RecentSet | None:
        """``add``, with the set worked out only when something reads it (an alert's wording, 20 windows a
        second that are mostly never read). The recent windows are copied now, so it is the set ``add`` gives."""
        p = np.asarray(label_probability, dtype=np.float64)
        if self.threshold is None or p.shape != (N_LABELS,) or not np.isfinite(p).all():
            return None
        self._ring[self._head] = p
        self._head = (self._head + 1) % len(self._ring)
        self._n = min(self._n + 1, len(self._ring))
        return RecentSet(self._ring.copy(), self._n, self.threshold, self.sparsity_prior, self.classifier_weight)


class RecentSet(Sequence):
    """The hypothesis set of one ``FlightSets`` state, computed on first read; reads as the tuple ``add`` returns
    (((propellers), probability), ...), never empty (the most probable set is always in)."""

    __slots__ = ("_ring", "_n", "_threshold", "_rho", "_tau", "_pairs")

    def __init__(self, ring: np.ndarray, n: int, threshold: float, sparsity_prior: float, classifier_weight: float = 1.0):
        self._ring, self._n, self._threshold, self._rho = ring, n, threshold, sparsity_prior  # ring: a copy, as it was
        self._tau = classifier_weight
        self._pairs: tuple[tuple[tuple[int, ...], float], ...] | None = None

    def _value(self) -> tuple[tuple[tuple[int, ...], float], ...]:
        if self._pairs is None:
            mean = self._ring.sum(axis=0) / self._n  # empty rows are zeros
            hyps = hypothesis_set(flight_score(mean, None, "classifier", self._rho, self._tau), self._threshold)
            self._pairs = tuple((tuple(h["faulty_propellers"]), h["probability"]) for h in hyps)
        return self._pairs

    def __bool__(self) -> bool:
        return True  # hypothesis_set always keeps the best set

    def __len__(self) -> int:
        return len(self._value())

    def __getitem__(self, i):
        return self._value()[i]

    def __iter__(self):
        return iter(self._value())

    def __eq__(self, other) -> bool:
        return tuple(self) == (tuple(other) if isinstance(other, RecentSet) else other)

    __hash__ = None  # type: ignore[assignment]  # mutable cache, compared by value

    def __repr__(self) -> str:
        return f"RecentSet({self._value()!r})"
