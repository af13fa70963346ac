"""Onboard figures: false alarms per healthy flight-hour and detection time after an in-flight fault onset.

Flights are simulated with shifted conditions (random routes and payloads),
the classifier runs on every window (hop 1, as the daemon does at 20 Hz) and
the consecutive-window rule (``offline.classifier.consecutive``, the comparison
beside the daemon's sequential rule) is replayed on the flight's clock, with its
defaults and the trade-offs in ``RULES``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.labels import LABEL_MASKS
from monitor.vehicle import VehicleConfig
from offline.classifier.consecutive import ConsecutiveConfig, replay_consecutive
from offline.classifier.evaluate import Predictor
from offline.classifier.windows import gather, window_index
from offline.dataset.generate import DatasetSpec, from_log, routes, simulate_flights
from offline.dataset.onset import SwitchedPropellers
from offline.dataset.records import FaultDataset

DEFAULT_RULE = ConsecutiveConfig()  # the card's headline figures
# Other rules to show the trade-off: a hair trigger (3 windows) and a longer run of hot windows (3 s at 20 Hz).
RULES = {
    "default": DEFAULT_RULE,
    "hair trigger": ConsecutiveConfig(threshold=0.8, consecutive=3),
    "3 s": ConsecutiveConfig(threshold=0.9, consecutive=60),
}


@dataclass(frozen=True)
class ShiftFlights:
    """How the evaluation flights are drawn (all shifted away from the paper's route A)."""

    n_flights: int = 32
    duration_s: float = 80.0
    payload_kg: tuple[float, float] = (0.0, 0.6)
    fault: str = "mixed"
    propellers: str = "quadratic"
    onset_s: tuple[float, float] = (30.0, 50.0)  # uniform per flight (detection runs)
    seed: int = 1000


def simulate_onset(vehicle: VehicleConfig, cfg: ShiftFlights, healthy: bool) -> FaultDataset:
    """Flights on random routes: all healthy, or healthy until a per-flight onset then a random non-empty fault set."""
    rng = np.random.default_rng([cfg.seed, 1 if healthy else 2])
    n = cfg.n_flights
    if healthy:
        cond = np.zeros((n, 4), np.int8)
    else:
        masks = LABEL_MASKS[1 + rng.integers(0, 15, n)] > 0  # labels 2..16
        kinds = rng.integers(1, 3, (n, 4)) if cfg.fault == "mixed" else np.full((n, 4), 1 if cfg.fault == "bent" else 2)
        cond = (masks * kinds).astype(np.int8)
    payload = rng.uniform(*cfg.payload_kg, n)
    spec = DatasetSpec(
        "onset", fault=cfg.fault, waypoints=("random",), duration_s=cfg.duration_s, propellers=cfg.propellers, seed=cfg.seed
    )
    wps, names = routes(spec, n, seed=cfg.seed + (0 if healthy else 1))
    onset_s = np.full(n, np.inf) if healthy else rng.uniform(*cfg.onset_s, n)
    from offline.propellers import build_propellers

    seed = cfg.seed + (0 if healthy else 1)
    props = None
    if not healthy:
        before = build_propellers(vehicle, np.zeros_like(cond), kind=cfg.propellers, rng_seed=seed)
        after = build_propellers(vehicle, cond, kind=cfg.propellers, rng_seed=seed + 1)
        props = SwitchedPropellers(before, after, onset_s)
    log = simulate_flights(vehicle, wps, cond, payload, spec, seed, propellers=props)
    rate = log.log_rate_hz
    onset_step = np.where(np.isfinite(onset_s), np.ceil(onset_s * rate) - 1, log.n_samples).astype(np.int64)
    return from_log(
        log,
        "healthy" if healthy else "onset",
        vehicle,
        cond,
        payload,
        names,
        {"kind": "onset-flights", "config": cfg.__dict__},
        onset_step,
    )


def flight_fault_probabilities(predict: Predictor, ds: FaultDataset, features, window: int) -> list[np.ndarray]:
    """Per flight, (N, 4) fault probabilities of every window (hop 1); window k ends at step k + window - 1."""
    feats = ds.features(features)
    out = []
    for b in range(ds.n_flights):
        idx = window_index(feats, window, 1, np.array([b]))
        probs = []
        for i in range(0, len(idx), 2048):
            probs.append(predict(gather(feats, idx[i : i + 2048], window))[1])
        out.append(np.concatenate(probs))
    return out


def false_alarms_per_hour(
    predict: Predictor,
    healthy: FaultDataset,
    features,
    window: int,
    config: ConsecutiveConfig = DEFAULT_RULE,
    probs: list[np.ndarray] | None = None,
) -> dict:
    if probs is None:
        probs = flight_fault_probabilities(predict, healthy, features, window)
    alarms = sum(len(replay_consecutive(p, healthy.sample_rate_hz, window, config)) for p in probs)
    classified_s = sum(len(p) for p in probs) / healthy.sample_rate_hz
    hot_windows = float(np.mean(np.concatenate(probs) >= config.threshold))
    return {
        "alarms": alarms,
        "classified_hours": classified_s / 3600.0,
        "alarms_per_hour": alarms / (classified_s / 3600.0),
        "windows_over_threshold": hot_windows,
        "flights": healthy.n_flights,
    }


def detection_times(
    predict: Predictor,
    onset: FaultDataset,
    features,
    window: int,
    config: ConsecutiveConfig = DEFAULT_RULE,
    probs: list[np.ndarray] | None = None,
) -> dict:
    """Seconds from fault onset to the first alert, and to the first alert naming only truly faulty propellers."""
    if probs is None:
        probs = flight_fault_probabilities(predict, onset, features, window)
    rate = onset.sample_rate_hz
    first, correct, early = [], [], 0
    for b, p in enumerate(probs):
        t_on = (onset.onset_step[b] + 1) / rate  # time of the first faulty log sample
        truth = {i + 1 for i in np.flatnonzero(onset.fault_mask[b])}
        alerts = replay_consecutive(p, rate, window, config)
        early += sum(1 for t, _ in alerts if t < t_on)
        after = [(t - t_on, props) for t, props in alerts if t >= t_on]
        first.append(after[0][0] if after else np.inf)
        ok = [dt for dt, props in after if set(props) <= truth]
        correct.append(ok[0] if ok else np.inf)
    first, correct = np.array(first), np.array(correct)

    def summary(x: np.ndarray) -> dict:
        hit = np.isfinite(x)
        return {
            "detected": float(hit.mean()),
            "median_s": float(np.median(x[hit])) if hit.any() else None,
            "p90_s": float(np.percentile(x[hit], 90)) if hit.any() else None,
        }

    return {
        "flights": onset.n_flights,
        "first_alert": summary(first),
        "first_correct_alert": summary(correct),
        "alerts_before_onset": early,
    }


def rule_sweep(
    predict: Predictor, healthy: FaultDataset, onset: FaultDataset, features, window: int, rules: dict[str, ConsecutiveConfig]
) -> dict[str, dict]:
    """False alarms and detection for several alert rules on the same classifier outputs (classified once)."""
    ph = flight_fault_probabilities(predict, healthy, features, window)
    po = flight_fault_probabilities(predict, onset, features, window)
    return {
        name: {
            "rule": {"threshold": r.threshold, "consecutive": r.consecutive, "refractory_s": r.refractory_s},
            "false_alarms": false_alarms_per_hour(predict, healthy, features, window, r, ph),
            "detection": detection_times(predict, onset, features, window, r, po),
        }
        for name, r in rules.items()
    }
