"""Calibrate the decision's thresholds on healthy flights: the exceedance-rate tail of its CUSUM.

``propwatch tune alerts`` (``make tune-alerts``, ``main`` here) simulates the healthy calibration flights, writes
the thresholds, then scores them on independent flights with ``propwatch evaluate alerts`` (``offline.alerts.evaluate``).

Each healthy flight is replayed through ``monitor.decision.rule.Decision`` itself
(regime holds and discounts included) with its trace on; the traced updates
are then re-run against a grid of thresholds, restarting the statistic at
each crossing (a renewal: after an alarm the monitor starts again), which
gives the crossing rate per healthy flight-hour for every threshold. A line
through ln(rate) against h on the grid points with at least ``MIN_EVENTS``
crossings gives ``rate(h) = exp(a - b h)``; the decision solves it for the
configured rates. Only the tail is fitted: grid points crossed at most
``TAIL_MAX_RATE_PER_H`` times per hour (the body of the distribution, where
every manoeuvre crosses, says nothing about the rare excursions that make
false alarms). Points beyond the data are an extrapolation of that tail, and
healthy flights show rarer, larger excursions than an exponential tail
predicts (a 5-s gust bump, a network flipping mid-flight): so the file also
keeps each statistic's highest renewal value over all calibration flights
(``h_max_healthy``), and a rate below what the calibration hours can resolve
(< 1 per calibration flight-time) never gets a threshold that one of those
flights crossed. The file says from how many hours and crossings it was drawn.

A point fit of a thin tail is fragile: 5 and 10 calibration hours of the same simulator put the physics fault
threshold at 7.24 and 6.54 nat-s, and the lower one gave 17 false FAULTs in 10 h of the evaluation-only
simulator where the higher gave none (models/decision-evaluation.md). So the file also keeps a
bootstrap over *flights* (a flight's excursions are not independent of each other; flights are): each draw
resamples the calibration flights with replacement and fits the tail again (``BOOTSTRAP_DRAWS``, seeded by the
calibration seed, so the file is reproducible). The decision takes, for each rate, the ``CONFIDENCE`` quantile of
the draws' thresholds: a threshold that meets the rate in 95 % of the calibration sets these flights could have
been, not in half of them. A draw with no tail to fit counts as an infinite threshold.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np

from monitor.decision.config import DecisionConfig
from monitor.decision.rule import Decision
from monitor.decision.thresholds import STATISTICS, Thresholds, file_sha256, pair_statistic, physics_statistic
from offline.alerts.flights import AlertFlight, FlightSet
from offline.alerts.rules import replay_decision
from offline.manifest import make_manifest
from offline.sim.assumptions import REGISTER

MIN_EVENTS = 3
TAIL_MAX_RATE_PER_H = 10.0  # fit the tail: grid points crossed at most this often (100x the fault target)
BOOTSTRAP_DRAWS = 200  # flight resamples of the tail (the 95 % quantile of 200 draws: the 190th)
CONFIDENCE = 0.95  # the quantile of the draws' thresholds the decision takes (monitor/decision/thresholds.py)
H_GRID = np.geomspace(0.05, 500.0, 100)


def _factor(scale, statistic: str) -> float:
    """A trace's ("scale", factor) applies to every statistic; ("scale", {statistic: factor}) to those named."""
    return float(scale.get(statistic, 1.0)) if isinstance(scale, dict) else float(scale)


def flight_peaks(traces: list[list], statistic: str) -> np.ndarray:
    """(n_flights,) the highest value the statistic reaches (any propeller) on each trace."""
    peaks = np.zeros(len(traces))
    for k, trace in enumerate(traces):
        s = np.zeros(4)
        for op, v in trace:
            if op == "scale":
                s *= _factor(v, statistic)
            elif statistic in v:
                s = np.maximum(0.0, s + v[statistic])
                peaks[k] = max(peaks[k], float(s.max()))
    return peaks


def peak_value(traces: list[list], statistic: str) -> float:
    """The highest value the statistic reaches (any propeller) over all traces."""
    return float(flight_peaks(traces, statistic).max(initial=0.0))


def flight_crossing_counts(traces: list[list], h_grid: np.ndarray, statistic: str) -> np.ndarray:
    """(n_flights, len(h_grid)) crossings of each threshold (any propeller, renewal after each) on each trace."""
    counts = np.zeros((len(traces), len(h_grid)), dtype=np.int64)
    for k, trace in enumerate(traces):
        s = np.zeros((len(h_grid), 4))
        for op, v in trace:
            if op == "scale":
                s *= _factor(v, statistic)
                continue
            if statistic not in v:
                continue
            s = np.maximum(0.0, s + v[statistic][None, :])
            hit = (s >= h_grid[:, None]).any(axis=1)
            counts[k] += hit
            s[hit] = 0.0
    return counts


def crossing_counts(traces: list[list], h_grid: np.ndarray, statistic: str) -> np.ndarray:
    """Crossings of each threshold (any propeller, renewal after each) over all traces."""
    return flight_crossing_counts(traces, h_grid, statistic).sum(axis=0)


def fit_tail(h_grid: np.ndarray, counts: np.ndarray, hours: float) -> tuple[float, float, list]:
    """Least squares ln(rate) = a - b h over the tail: points with >= MIN_EVENTS crossings and a rate <= the tail's."""
    ok = (counts >= MIN_EVENTS) & (counts / hours <= TAIL_MAX_RATE_PER_H)
    if ok.sum() < 3:
        raise ValueError(f"too few threshold crossings to fit a tail ({int(ok.sum())} usable points): fly more hours")
    x, y = h_grid[ok], np.log(counts[ok] / hours)
    # var(ln c) ~ 1 / c (Poisson): weigh each point by sqrt(c), so the thin end of the tail does not steer the line
    slope, intercept = np.polyfit(x, y, 1, w=np.sqrt(counts[ok]))
    if slope >= 0:
        raise ValueError("crossing rate does not fall with the threshold: no tail to fit")
    points = [[round(float(h), 3), int(c), round(float(c / hours), 4)] for h, c in zip(h_grid, counts)]
    return float(intercept), float(-slope), points


def bootstrap_tails(
    per_flight: np.ndarray, flight_hours: np.ndarray, h_grid: np.ndarray, draws: int, rng: np.random.Generator
) -> tuple[list[list[float]], int]:
    """The tail fitted again on ``draws`` resamples of the flights (with replacement): ([[a, b], ...], failed),
    ``failed`` the draws with no tail to fit (fewer usable points, or a rate that does not fall)."""
    n = len(per_flight)
    fits, failed = [], 0
    for _ in range(draws):
        idx = rng.integers(0, n, n)
        try:
            a, b, _ = fit_tail(h_grid, per_flight[idx].sum(axis=0), float(flight_hours[idx].sum()))
        except ValueError:
            failed += 1
            continue
        fits.append([round(a, 6), round(b, 6)])
    return fits, failed


def tune_alerts(healthy: list[AlertFlight], model_path: str | Path, cfg: DecisionConfig, provenance: dict, seed: int = 0) -> dict:
    traces = []
    never = {k: np.inf for k in STATISTICS}
    for f in healthy:
        d = Decision(cfg, f.rate_hz, f.window, use_stored_calibration=False)
        d.thresholds = Thresholds(never, never, "calibration run")
        d.trace = []
        replay_decision(f, d)
        d.trace.append(("scale", 0.0))
        traces.append(d.trace)
    return fit_traces(traces, np.array([f.hours for f in healthy]), model_path, cfg, provenance, seed)


def fit_traces(
    traces: list[list], flight_hours: np.ndarray, model_path: str | Path, cfg: DecisionConfig, provenance: dict, seed: int
) -> dict:
    """The calibration file's content from the healthy flights' traces (``calibrate``)."""
    hours = float(np.sum(flight_hours))
    h_grid = H_GRID
    rng = np.random.default_rng([seed, 13])  # the bootstrap's own stream: the same file for the same flights
    fits, points = {}, {}
    for stat in STATISTICS:
        per_flight = flight_crossing_counts(traces, h_grid, stat)
        counts = per_flight.sum(axis=0)
        points[stat] = [[round(float(h), 3), int(c)] for h, c in zip(h_grid, counts)]
        try:
            a, b, _ = fit_tail(h_grid, counts, hours)
            # A tail that still crosses at the top of the grid more often than the rates we serve is no tail.
            if counts[-1] / hours > cfg.false_alarms_per_hour:
                raise ValueError(f"{counts[-1]} crossings of h={h_grid[-1]:.0f} in {hours:.2f} h: not an exponential tail")
            boot, failed = bootstrap_tails(per_flight, np.asarray(flight_hours, float), h_grid, BOOTSTRAP_DRAWS, rng)
            fits[stat] = {
                "a": a,
                "b": b,
                "h_max_healthy": round(peak_value(traces, stat), 4),
                "bootstrap_ab": boot,
                "bootstrap_failed": failed,
            }
        except ValueError as exc:
            fits[stat] = None
            points[stat + "_disabled_because"] = str(exc)
    return {
        "fits": fits,
        "form": "crossings per healthy flight-hour = exp(a - b * h), h in nat-seconds; null = statistic disabled",
        "confidence": CONFIDENCE,
        "model_sha256": file_sha256(model_path),
        "provenance": {
            **provenance,
            "flights": len(traces),
            "flight_hours": round(hours, 3),
            "min_events_per_point": MIN_EVENTS,
            "tail_max_rate_per_h": TAIL_MAX_RATE_PER_H,
            "bootstrap": {"draws": BOOTSTRAP_DRAWS, "over": "flights, with replacement", "seed": [seed, 13]},
            "physics_statistic": physics_statistic(cfg),
            "pair_statistic": pair_statistic(cfg),
            "points_h_crossings": points,
        },
    }


def write_calibration(cal: dict, path: str | Path, config: dict, seed: int) -> Path:
    path = Path(path)
    cal = {**cal, "manifest": make_manifest("decision-calibration", config, seed)}
    tmp = path.with_name(path.name + ".tmp")
    text = json.dumps(cal, indent=1)
    text = re.sub(r"\[\n\s+(\S+),\n\s+(\S+)\n\s+\]", r"[\1, \2]", text)  # an (a, b) draw on one line
    tmp.write_text(text + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def main(argv: list[str] | None = None) -> int:
    """``propwatch tune alerts``: the options of ``propwatch evaluate alerts``; calibrate, then evaluate."""
    from monitor.model import Classifier
    from monitor.vehicle import load_vehicle
    from offline.alerts.evaluate import evaluate, flown_flight_count, our_flights, parse_args

    args = parse_args(["--calibrate", *(sys.argv[1:] if argv is None else argv)])
    clf = Classifier(args.model)
    vehicle = load_vehicle(args.vehicle)
    fs = FlightSet(
        "healthy",
        n_flights=flown_flight_count(args.calibration_hours),
        seed=args.calibration_seed,
        pickup_fraction=args.pickup_fraction if args.physics == "randomised" else 0.0,
        physics=args.physics,
    )
    healthy = our_flights(args, vehicle, clf, fs)
    prov = {"flight_set": fs.__dict__, "simulator": "offline.sim (ours)"}
    cal = tune_alerts(healthy, args.model, DecisionConfig(), prov, seed=args.calibration_seed)
    config = {"flight_set": fs.__dict__}
    if args.physics == "randomised":
        config["assumptions"] = REGISTER.to_mapping()
    path = write_calibration(cal, args.calibration_out, config, args.calibration_seed)
    ab = {k: None if v is None else (round(v["a"], 4), round(v["b"], 4)) for k, v in cal["fits"].items()}
    print(f"calibration: {path} (a, b) {ab}", file=sys.stderr)
    return evaluate(args)
