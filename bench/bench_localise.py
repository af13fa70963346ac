"""Localisation on our own simulator's paper sets: physics (moment balance) beside the CNN and the ω²-share baseline.

For each of the paper's sets A, B, C (Table 4.2) and each fault kind, one 80 s flight per label is
simulated (offline.dataset, LSTM propellers as the shipped classifier was trained on) and every flight
gets three verdicts:
- ``physics``: the most probable propeller set of the moment-balance hypothesis bank
  (monitor.decision.effectiveness, nominal priors, no airframe baseline), its 95 % credible set and size;
- each classifier given with ``--model NAME=PATH`` (default: the shipped one) as ``propwatch diagnose`` runs it
  (``monitor.diagnose.engine.diagnose_table`` after the first 5 s, with the vehicle for the moment balance): the
  verdict's set, which is the conformal set's most probable member when the model has a rule beside it;
- ``share``: the ω²-share baseline (the rotor with the largest flight-mean share of ω²; always one rotor).
Run: ``python -m bench.bench_localise [--flights-per-label 1] [--duration-s 80] [--model NAME=PATH ...] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from monitor.decision.effectiveness import HYPOTHESES, Evidence, HypothesisBank, Priors, RotorGeometry, credible_set
from monitor.diagnose.engine import diagnose_table
from monitor.flight import FlightTable
from monitor.model import Classifier
from monitor.vehicle import DEFAULT_VEHICLE, REPO_ROOT, load_vehicle
from offline.dataset.generate import PRESETS, DatasetSpec, generate
from offline.tune.noise import WARMUP_STEPS, flight_balances
from offline.tune.sets import share_rotors


def physics_verdicts(ds, bank: HypothesisBank, geometry: RotorGeometry, priors: Priors):
    out = []
    for z, h, std in flight_balances(ds, geometry):  # non-overlapping 5 s windows after the first 5 s
        ev = Evidence()
        ev.add(z, h, std, priors)
        v = bank.posterior(ev)
        out.append((HYPOTHESES[v.best], [HYPOTHESES[k] for k in credible_set(v, 0.95)], v.fault_probability()))
    return out


def share_verdicts(ds):
    return [(int(r),) for r in share_rotors(ds)]


def flight_table(ds, f: int) -> FlightTable:
    """Flight ``f`` of a data set as a log reader would give it, from the end of the first 5 s (airborne)."""
    sig = {k: np.asarray(v[f, WARMUP_STEPS:], dtype=np.float64) for k, v in ds.signals.items()}
    n = len(sig["roll_rad"])
    step_us = round(1e6 / ds.sample_rate_hz)
    return FlightTable(
        timestamp_us=(np.arange(n, dtype=np.int64) + WARMUP_STEPS) * step_us,
        motor_cmd=np.full((n, 4), np.nan),
        battery_v=np.full(n, np.nan),
        airborne=np.ones(n, dtype=bool),
        rate_hz=ds.sample_rate_hz,
        source=f"{ds.name}[{f}]",
        **sig,
    )


def system_verdicts(ds, clf: Classifier, vehicle, hop: int = 10, flights=None):
    """The verdict ``propwatch diagnose`` gives each flight (its propeller set); ``flights``: only these (others None)."""
    out = [None] * ds.n_flights
    for f in range(ds.n_flights) if flights is None else flights:
        d = diagnose_table(flight_table(ds, f), clf, hop=hop, vehicle=vehicle)
        out[f] = tuple(d.verdict["faulty_propellers"]) if d.verdict else None
    return out


def add_model_option(ap: argparse.ArgumentParser) -> None:
    """``--model NAME=PATH``, repeatable, read by ``model_paths``."""
    ap.add_argument("--model", action="append", help="NAME=PATH of a classifier to score (repeatable; default the shipped one)")


def model_paths(specs: list[str] | None) -> dict[str, Path]:
    """``--model NAME=PATH`` options as {name: path}; none given: the shipped model as "shipped CNN"."""
    if not specs:
        return {"shipped CNN": REPO_ROOT / "models" / "classifier.onnx"}
    out = {}
    for spec in specs:
        name, sep, path = spec.partition("=")
        if not sep or not name or not path:
            raise SystemExit(f"--model {spec!r}: expected NAME=PATH")
        out[name] = Path(path)
    return out


def score(truth, pred):
    truth = [tuple(t) for t in truth]
    single = [i for i, t in enumerate(truth) if len(t) == 1]
    acc = np.mean([p == t for p, t in zip(pred, truth)])
    acc1 = np.mean([pred[i] == truth[i] for i in single]) if single else float("nan")
    return float(acc), float(acc1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights-per-label", type=int, default=1, help="flights per label and set (default 1)")
    ap.add_argument("--duration-s", type=float, default=80.0, help="flight length (paper: 80 s)")
    ap.add_argument("--json", help="write the table as JSON here")
    ap.add_argument("--seed", type=int, default=101, help="data set seed (not the training seeds)")
    add_model_option(ap)
    args = ap.parse_args(argv)
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    geometry, priors = RotorGeometry.from_vehicle(vehicle), Priors()
    bank = HypothesisBank(priors, geometry)
    models = {name: Classifier(path) for name, path in model_paths(args.model).items()}
    rows = []
    for name in ("A", "B", "C"):
        for fault in ("bent", "cracked"):
            t0 = time.perf_counter()
            spec = DatasetSpec(
                name=f"{name}-{fault}",
                fault=fault,
                flights_per_label=args.flights_per_label,
                duration_s=args.duration_s,
                seed=args.seed,
                **PRESETS[name],
            )
            ds = generate(spec, vehicle, log=lambda *_: None)
            truth = [tuple(i + 1 for i in range(4) if c[i]) for c in ds.conditions]
            phys = physics_verdicts(ds, bank, geometry, priors)
            row = {"set": spec.name, "flights": ds.n_flights, "physics": score(truth, [p[0] for p in phys])}
            row["models"] = {label: score(truth, system_verdicts(ds, clf, vehicle)) for label, clf in models.items()}
            row["share"] = score(truth, share_verdicts(ds))
            row["physics_set_coverage"] = float(np.mean([t in p[1] for t, p in zip(truth, phys)]))
            row["physics_set_size"] = float(np.mean([len(p[1]) for p in phys]))
            healthy = [p[2] for t, p in zip(truth, phys) if not t]
            row["physics_healthy_p_faulty_max"] = float(np.max(np.mean(healthy, axis=0))) if healthy else float("nan")
            row["seconds"] = round(time.perf_counter() - t0, 1)
            rows.append(row)
            print(
                f"{spec.name:10s} n={row['flights']:3d}  exact all/single  physics {100 * row['physics'][0]:5.1f}/{100 * row['physics'][1]:5.1f}"
                + "".join(f"  {n} {100 * a:5.1f}/{100 * a1:5.1f}" for n, (a, a1) in row["models"].items())
                + f"  share -/{100 * row['share'][1]:5.1f}"
                f"  | physics set cover {100 * row['physics_set_coverage']:5.1f} % size {row['physics_set_size']:.2f}"
                f"  healthy max mean P(faulty) {row['physics_healthy_p_faulty_max']:.2f}  ({row['seconds']} s)",
                flush=True,
            )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
