"""propwatch adapt --healthy LOG... --vehicle V.yaml --out DIR [--json] [--labelled LOG[=ROTORS]...]

Calibrates the vehicle on its healthy logs, simulates and trains a classifier around the
calibrated vehicle (and, for comparison, around the nominal one), and writes into DIR: the
model (classifier.onnx), the calibrated vehicle (vehicle.yaml), the healthy baseline
(baseline.json), the manifest and the card. 'propwatch diagnose LOG --vehicle DIR' then
uses them. A --labelled log is scored with its truth when written LOG=3 or LOG=1+2
(faulty rotors, PX4 order) or LOG=healthy.

Exit code: 0 done; 2 bad input (a "healthy" log that is not, another vehicle type, a bad file).
"""

from __future__ import annotations

import argparse
import json
import sys

from monitor.errors import PropwatchError


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="propwatch adapt", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--healthy", nargs="+", required=True, metavar="LOG", help="healthy flights of this airframe")
    p.add_argument("--vehicle", required=True, help="nominal vehicle YAML")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--format", dest="fmt", default=None, help="log format or CSV mapping name (monitor/formats.yaml)")
    p.add_argument("--labelled", nargs="*", default=[], metavar="LOG[=ROTORS]", help="flights to score the gain on")
    p.add_argument("--mission", choices=("random", "crazypad"), default=None, help="simulated routes (default: by format)")
    p.add_argument("--flights-per-label", type=int, default=4, help="simulated training flights per label (default 4)")
    p.add_argument("--epochs", type=int, default=4, help="training epochs (default 4)")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated training set and the training (default 0)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from offline.adapt.pipeline import AdaptConfig, adapt_vehicle

    mission = args.mission or ("crazypad" if (args.fmt or "").startswith("crazypad") else "random")
    window = 60 if mission == "crazypad" else 100
    try:
        cfg = AdaptConfig(
            mission=mission, flights_per_label=args.flights_per_label, epochs=args.epochs, window=window, seed=args.seed
        )
        res = adapt_vehicle(args.healthy, args.vehicle, args.out, args.fmt, args.labelled, cfg, progress=sys.stderr.isatty())
    except PropwatchError as exc:
        print(f"propwatch adapt: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        json.dump(res, sys.stdout, indent=2, allow_nan=False)
        print()
    else:
        print(f"adapted model, vehicle, baseline and card in {res['out']}")
        inspect = res["calibration"].get("inspect_rotor")
        if inspect:
            print(f"  INSPECT ROTOR {inspect['rotor']}: {inspect['why']}")
        for kind, s in res["scores"].items():
            print(f"  {kind}: exact {s['exact']}/{s['scored']}, healthy false alarms {s['healthy_false_alarms']}/{s['healthy']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
