"""Which unmeasured assumption breaks a classifier: score it on randomised data with one group varied at a time.

    .venv/bin/python -m bench.bench_assumptions [--model models/classifier.onnx] [--flights-per-label 2]
        [--duration-s 30] [--by group|entry] [--seed 7]

For each group of ``offline/sim/assumptions.py`` (or each entry, ``--by entry``)
a randomised data set is simulated with that group drawn over its range and
every other entry held at its fixed-simulator value (``nominal``); then
"all nominal" and "all drawn". Prints window accuracy (hop 10), single-propeller
accuracy (labels 2-5) and healthy accuracy (label 1). Drag and wind are separate
entries: wind acts only through drag, so "wind" alone with nominal (zero) drag
changes nothing. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path


def collapsed(register, keep: set[str], by: str):
    from offline.sim.assumptions import AssumptionRegister

    def kept(a) -> bool:
        return not a.modelled or (a.group if by == "group" else a.name) in keep

    return AssumptionRegister(
        tuple(
            a if kept(a) else dataclasses.replace(a, low=a.nominal, high=a.nominal, distribution="uniform")
            for a in register.assumptions
        )
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", type=Path, default=Path("models/classifier.onnx"))
    ap.add_argument("--flights-per-label", type=int, default=2)
    ap.add_argument("--duration-s", type=float, default=30.0)
    ap.add_argument("--by", choices=("group", "entry"), default="group")
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args(argv)

    from monitor.model import Classifier
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
    from offline.classifier.evaluate import evaluate_dataset
    from offline.dataset.generate import DatasetSpec, generate
    from offline.sim.assumptions import REGISTER

    vehicle = load_vehicle(DEFAULT_VEHICLE)
    clf = Classifier(args.model)
    names = sorted({(a.group if args.by == "group" else a.name) for a in REGISTER.assumptions if a.modelled})
    spec = DatasetSpec(
        "RR",
        fault="varied",
        waypoints=("random",),
        payload_kg=(0.0, 0.6),
        flights_per_label=args.flights_per_label,
        duration_s=args.duration_s,
        propellers="quadratic",
        physics="randomised",
        seed=args.seed,
    )
    print(f"{args.model}: {16 * args.flights_per_label} flights of {args.duration_s:.0f} s per row, seed {args.seed}")
    for label, keep in [("all nominal", set())] + [(f"only {n}", {n}) for n in names] + [("all drawn", set(names))]:
        t0 = time.process_time()
        ds = generate(spec, vehicle, log=lambda *_: None, register=collapsed(REGISTER, keep, args.by))
        r = evaluate_dataset(clf.predict, ds, clf.info.features, clf.info.window, 10)
        c = r.confusion
        single = sum(c[k, k] for k in range(1, 5)) / max(int(c[1:5].sum()), 1)
        healthy = c[0, 0] / max(int(c[0].sum()), 1)
        print(
            f"{label:48s} exact {100 * r.accuracy:6.2f} %  single-propeller {100 * single:6.2f} %  "
            f"healthy {100 * healthy:6.2f} %  ({time.process_time() - t0:.0f} s cpu)",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
