"""The calibrator and ``propwatch adapt`` on the evaluation-only simulator's ``hidden`` set.

    nice python -m bench.evalsim_hidden --out out/evalsim-hidden [--duration-s 40] [--adapt cg_offset weak_motor motor_lag]

The ``hidden`` set (``offline/evalsim``, RotorPy-based, never used for training) holds airframes
each with one hidden effect (CG offset, weak motor, motor lag, linear drag, ESC curve), each with
2 healthy flights and 4 single-propeller faults. Per airframe, measured:

1. the cause ``propwatch calibrate`` (``offline.calibrate.calibrate``) names from its 2 healthy flights;
2. localisation of its 4 faulty flights by the healthy-baseline rule (``offline.adapt.share_rule``: the rotor
   with the largest positive deviation beyond 3 spreads) with the airframe's own healthy baseline
   against the same rule with the nominal vehicle's (all shares equal);
3. with ``--adapt EFFECT...``: ``propwatch adapt`` on the 2 healthy flights (1 fits, 1 held out),
   the 4 faulty flights ``--labelled``: exact labels of the nominal and of the adapted model.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from monitor.logs import read_log  # noqa: E402
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402
from offline.adapt.share_rule import OUTLIER_SPREADS, HealthyBaseline, baseline_from_tables  # noqa: E402


def localised(base: HealthyBaseline, table, rotor: int) -> bool:
    dev = np.asarray(base.compare(table)["deviation_spreads"])
    return bool(int(np.argmax(dev)) + 1 == rotor and dev.max() > OUTLIER_SPREADS)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--duration-s", type=float, default=40.0)
    ap.add_argument("--adapt", nargs="*", default=[], metavar="EFFECT", help="airframes (by hidden effect) to adapt")
    ap.add_argument("--no-calibrate", action="store_true")
    args = ap.parse_args(argv)
    from offline.evalsim.sets import write_set

    setdir = args.out / "hidden"
    if not (setdir / "manifest.json").is_file():
        write_set("hidden", setdir, seed=0, duration_s=args.duration_s)
    manifest = json.loads((setdir / "manifest.json").read_text())
    veh = load_vehicle(DEFAULT_VEHICLE)
    by_af = defaultdict(list)
    for e in manifest["flights"]:
        by_af[e["airframe_id"]].append(e)
    results = {}
    for af, entries in sorted(by_af.items()):
        effect = entries[0]["nuisance"]
        healthy = [e for e in entries if not e["faulty_propellers"]]
        faulty = [e for e in entries if e["faulty_propellers"]]
        h_tabs = [read_log(setdir / e["file"], esc=veh.esc) for e in healthy]
        f_tabs = [read_log(setdir / e["file"], esc=veh.esc) for e in faulty]
        own = baseline_from_tables(h_tabs, [e["file"] for e in healthy])
        flat = HealthyBaseline(own.basis, (1.0,) * 4, (0.0,) * 4, own.noise_std, None, own.rate_hz, 0, (), own.motor_names)
        row = {
            "effect": effect,
            "baseline_rule_own": sum(localised(own, t, e["faulty_propellers"][0]) for t, e in zip(f_tabs, faulty)),
            "baseline_rule_nominal": sum(localised(flat, t, e["faulty_propellers"][0]) for t, e in zip(f_tabs, faulty)),
            "faulty": len(faulty),
        }
        if not args.no_calibrate:
            from offline.calibrate.calibrate import calibrate_vehicle

            row["calibrate_cause"] = calibrate_vehicle(h_tabs, veh).cause
        if effect in args.adapt:
            from offline.adapt.pipeline import AdaptConfig, adapt_vehicle

            cfg = AdaptConfig(mission="random", flights_per_label=2, epochs=3, duration_s=args.duration_s, vehicle_variants=2)
            labelled = [f"{setdir / e['file']}={e['faulty_propellers'][0]}" for e in faulty]
            res = adapt_vehicle([str(setdir / e["file"]) for e in healthy], DEFAULT_VEHICLE, args.out / af, None, labelled, cfg)
            row["adapt"] = res["scores"]
        results[af] = row
        print(json.dumps({af: row}), flush=True)
    (args.out / "evalsim-hidden.json").write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
