"""Per-flight alert listing for the decision rule: which flight alarms, when, on which
statistic and propeller, and in which regime.

    python -m bench.alerts_flights --set ours-healthy --flights 24 --seed 200
    python -m bench.alerts_flights --set evalsim-healthy --flights 23 --seed 200   # understanding only

Flights are classified once and cached (``--cache``, pickles of ``AlertFlight`` lists), so the rule can be
re-run on them in seconds. evalsim is evaluation-only: read its listing to understand failure modes, never
to choose a threshold or a setting.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from monitor.decision.config import DecisionConfig
from monitor.decision.rule import Decision, WindowEvidence
from monitor.decision.thresholds import STATISTICS, load_calibration
from monitor.model import Classifier
from monitor.vehicle import REPO_ROOT, load_vehicle


def load_flights(set_name: str, n: int, seed: int, cache: Path, model: str, physics: str = "randomised", pickup: float = 0.25):
    """The set through the same cache as ``propwatch evaluate alerts --cache``."""
    from monitor.decision.thresholds import file_sha256
    from offline.alerts.evaluate import cached, evalsim_cached, set_key
    from offline.alerts.flights import FlightSet, simulate_set

    sha = file_sha256(model)
    log = lambda m: print(m, file=sys.stderr)  # noqa: E731
    sim, kind = set_name.split("-", 1)
    if sim == "evalsim":
        return evalsim_cached(str(cache), kind, n, seed, Classifier(model), sha, log)
    fs = FlightSet(
        kind, n, seed=seed, physics=physics, pickup_fraction=pickup if kind == "healthy" and physics == "randomised" else 0.0
    )
    vehicle = load_vehicle(REPO_ROOT / "models" / "vehicle.yaml")
    return cached(str(cache), set_key(fs, sha), lambda: simulate_set(vehicle, fs, Classifier(model), log=log))


def replay_listing(f, d: Decision) -> list[dict]:
    """Every announcement with the statistic that crossed, and the regime events around it."""
    rows, events = [], []
    w = f.window
    steps = f.steps()
    for j in range(len(f.mean_rpm)):
        t = (j + 1) / f.rate_hz
        before = dict(d.regime.counts)
        d.step(t, steps.inputs(j))
        for k, v in d.regime.counts.items():
            if v > before[k]:
                events.append((round(t, 1), k))
        k = j - w + 1
        if k >= 0:
            for a in d.window_evidence(t, WindowEvidence(f.fault_probability[k])):
                th = d.thresholds.fault if a.level == "fault" else d.thresholds.suspect
                crossed = sorted({s for s in STATISTICS for i in a.propellers if d.S[s][i - 1] >= th[s]})
                rows.append(
                    {
                        "t_s": round(t, 1),
                        "level": a.level,
                        "propellers": a.propellers,
                        "statistics": crossed,
                        "regime_events_before": events[-3:],
                        "share_baseline": None if d.share.baseline is None else np.round(d.share.baseline, 4).tolist(),
                    }
                )
    return rows


def share_spread(flights) -> dict:
    """Yaw-free omega^2 share (mean over SHARE_AVERAGE_S) and the yaw balance y = (s1 + s2 - s3 - s4) / 2 (mean
    over YAW_AVERAGE_S) minus the flight's first 10 s: pooled std and tails of each; and the largest rise of one
    rotor's yaw-free share over YAW_AVERAGE_S (what words a yaw-balance alert: monitor.decision.rotor_share.YAW_FREE_RISE)."""
    from monitor.decision.rotor_share import _Y, _YAW_FREE, BASELINE_S, SHARE_AVERAGE_S, YAW_AVERAGE_S

    devs, ydevs, rises = [], [], []
    for f in flights:
        w2 = f.motor_rpm**2
        sh = w2 / w2.mean(axis=1, keepdims=True)
        c = np.cumsum(np.vstack([np.zeros((1, 4)), sh]), axis=0)
        n = int(round(SHARE_AVERAGE_S * f.rate_hz))
        m = (c[n:] - c[:-n]) / n
        x = m @ _YAW_FREE.T
        n0 = int(BASELINE_S * f.rate_hz)
        devs.append(x[n0:] - x[:n0].mean(axis=0))
        ny = int(round(YAW_AVERAGE_S * f.rate_hz))
        y = ((c[ny:] - c[:-ny]) / ny) @ _Y  # the decision's yaw balance: mean over YAW_AVERAGE_S
        ydevs.append(y[n0:] - (m[:n0] @ _Y).mean())
        x10 = ((c[ny:] - c[:-ny]) / ny) @ _YAW_FREE.T
        rises.append((x10[n0:] - x[:n0].mean(axis=0)).max(axis=1))

    def spread(devs):
        d = np.abs(np.concatenate(devs))
        return {
            "std": round(float(np.sqrt(np.mean(d**2))), 4),
            "quantiles_abs": {q: round(float(np.quantile(d, q)), 4) for q in (0.5, 0.9, 0.99, 0.999)},
            "per_flight_max_abs_p50_p90_max": np.round(
                np.quantile([x.max() for x in (np.abs(v) for v in devs)], [0.5, 0.9, 1.0]), 4
            ).tolist(),
        }

    r = np.concatenate(rises)
    rise = {q: round(float(np.quantile(r, q)), 4) for q in (0.5, 0.9, 0.99, 0.999)}
    return {"flights": len(flights), **spread(devs), "yaw_balance": spread(ydevs), "largest_yaw_free_rise_10s": rise}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument(
        "--set", default="ours-healthy", help="ours-healthy | ours-single | ours-pair | evalsim-healthy | evalsim-onset"
    )
    p.add_argument("--flights", type=int, default=24)
    p.add_argument("--seed", type=int, default=200)
    p.add_argument("--physics", default="randomised", help="ours only: randomised (register) | fixed (old FlightSet)")
    p.add_argument("--model", default=str(REPO_ROOT / "models" / "classifier.onnx"))
    p.add_argument("--calibration", default="", help="decision calibration file (default: the shipped one)")
    p.add_argument("--cache", default="out/alerts-cache")
    p.add_argument("--share-spread", action="store_true", help="only print the healthy spread of the omega^2 share")
    p.add_argument("--pickup-fraction", type=float, default=0.25, help="ours, randomised: flights with a payload step")
    args = p.parse_args(argv)
    flights = load_flights(args.set, args.flights, args.seed, Path(args.cache), args.model, args.physics, args.pickup_fraction)
    if args.share_spread:
        print(share_spread(flights))
        return 0
    cal = load_calibration(args.calibration or None)
    cfg = DecisionConfig()
    n_alarm = 0
    for f in flights:
        d = Decision(cfg, f.rate_hz, f.window, calibration=cal, use_stored_calibration=False)
        rows = replay_listing(f, d)
        faults = [r for r in rows if r["level"] == "fault"]
        n_alarm += bool(faults)
        peak = {k: np.round(v, 2).tolist() for k, v in d.peak.items()}
        print(f"{f.name} truth={f.truth} onset={f.onset_s:.1f} regime={d.regime.counts} peak={peak}")
        for r in rows:
            print("   ", r)
    hours = sum(f.hours for f in flights)
    print(f"{len(flights)} flights, {hours:.3f} h, {n_alarm} with a fault alert; thresholds {d.thresholds.as_dict()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
