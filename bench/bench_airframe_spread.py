"""How localisation falls as the airframe leaves its file, on OUR simulator.

Randomised flights of our simulator, every term drawn from the assumption register, with the airframe's own terms
(``offline.sim.assumptions.AIRFRAME_TERMS``: CG offset, motor spread, arm and ESC errors, healthy torque spread) drawn
over the register's ranges scaled by 0 (the airframe as its file says, as the shipped model was trained and its sets
calibrated), 1/4, 1/2 and 1 (an airframe nobody measured). Each model (``--model NAME=PATH``, default the shipped one)
is scored as ``propwatch diagnose`` answers: its conformal rule with the airframe check
(``offline.tune.sets.measure_with_check``), beside the ω²-share baseline's singles.
The evaluation-only simulator's counterpart is evalsim ``shift_quarter`` / ``shift_half`` (bench_generalisation.py).

Run: ``python -m bench.bench_airframe_spread [--flights-per-label 10] [--seed 8]`` (about 4 min on 2 cores).
"""

from __future__ import annotations

import argparse
import sys

from bench.bench_localise import add_model_option, model_paths
from monitor.decision.hypotheses import load_rule  # noqa: E402
from monitor.model import Classifier  # noqa: E402
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402
from offline.dataset.generate import DatasetSpec, generate  # noqa: E402
from offline.sim.assumptions import scaled_airframe  # noqa: E402
from offline.tune.sets import measure_with_check, region_from_dataset, share_singles  # noqa: E402

SCALES = (0.0, 0.25, 0.5, 1.0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights-per-label", type=int, default=10, help="flights per label and scale (default 10)")
    ap.add_argument("--seed", type=int, default=8, help="data set seed, the same for every scale (default 8)")
    ap.add_argument("--duration-s", type=float, default=80.0, help="flight length (default 80 s)")
    add_model_option(ap)
    args = ap.parse_args(argv)
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    models = {name: Classifier(path) for name, path in model_paths(args.model).items()}
    print(
        "| airframe spread (x register) | system | truth in set / size | exact | singles | sure and wrong | flagged | ω²-share singles |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for scale in SCALES:
        spec = DatasetSpec(
            name=f"airframe-x{scale:g}",
            fault="varied",
            waypoints=("random",),
            payload_kg=(0.0, 0.6),
            flights_per_label=args.flights_per_label,
            duration_s=args.duration_s,
            propellers="quadratic",
            physics="randomised",
            airframe="drawn",
            seed=args.seed,
        )
        ds = generate(spec, vehicle, log=lambda *_: None, register=scaled_airframe(scale))
        for name, clf in models.items():
            rule = load_rule(clf.path)
            if rule is None:
                print(f"| x{scale:g} | {name} | no conformal rule beside the model: skipped | | | | | |")
                continue
            r = region_from_dataset(ds, spec.name, clf, vehicle)
            check = {
                "log_bayes_factor_max": rule.airframe_log_bayes_factor_max,
                "unmeasured_threshold": rule.unmeasured_threshold,
            }
            m = measure_with_check(r, rule.score, rule.sparsity_prior, rule.threshold, check)
            share = share_singles(r)
            print(
                f"| x{scale:g} | {name} | {100 * m['truth_in_set']:.1f} % / {m['mean_set_size']:.2f} | {100 * m['exact']:.1f} % | "
                f"{100 * m['single_exact']:.1f} % | {100 * m['sure_and_wrong']:.1f} % | {100 * m['flagged']:.1f} % | "
                f"{100 * share:.1f} % |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
