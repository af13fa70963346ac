"""The CrazyPAD experiment as one ``propwatch adapt`` call per airframe, plus its real-data scoring.

    nice python -m bench.crazypad_adapt --out out/crazypad-adapt [--flights-per-label 10] [--epochs 6]

Per airframe: ``adapt`` on its healthy motor logs (even numbers calibrate, odd are held out and
scored), every fault and mass log of that airframe given as ``--labelled`` with the paper's truth
(cut or taped rotors are faults; masses are not: their truth is healthy). Prints, per condition,
exact-label accuracy and "called a propeller fault" for the nominal and the adapted model.
Minutes per airframe at the defaults; the figures printed are what was measured on this run.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

from bench import REPO
from offline.adapt.pipeline import AdaptConfig, adapt_vehicle  # noqa: E402
from offline.crazypad.data import AIRFRAMES, DEFAULT_ROOT, load_manifest, select  # noqa: E402
from offline.crazypad.experiment import GROUP_ORDER  # noqa: E402
from offline.crazypad.vehicle import PROJECT_INDEX_OF_BITCRAZE  # noqa: E402


def truth_spec(f) -> str:
    if f.fault_kind not in ("propeller_cut", "tape_on_propeller"):
        return "healthy"
    rotors = [PROJECT_INDEX_OF_BITCRAZE[f"M{k + 1}"] + 1 for k, bad in enumerate(f.faulty) if bad]
    return "+".join(map(str, sorted(rotors)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=DEFAULT_ROOT)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--flights-per-label", type=int, default=10)
    ap.add_argument("--epochs", type=int, default=6)
    ap.add_argument("--airframes", nargs="+", default=list(AIRFRAMES))
    args = ap.parse_args(argv)
    flights = select(load_manifest(args.root))
    cfg = AdaptConfig(mission="crazypad", flights_per_label=args.flights_per_label, epochs=args.epochs, window=60)
    group_of = {str(args.root / f.file): f.group for f in flights}
    rows = defaultdict(lambda: defaultdict(list))
    for af in args.airframes:
        healthy = [str(args.root / f.file) for f in flights if f.airframe == af and f.fault_kind == "healthy"]
        healthy.sort()
        labelled = [f"{args.root / f.file}={truth_spec(f)}" for f in flights if f.airframe == af and f.fault_kind != "healthy"]
        res = adapt_vehicle(healthy, REPO / "models" / "crazyflie.yaml", args.out / af, "crazypad", labelled, cfg, progress=True)
        manifest = json.loads(Path(res["manifest"]).read_text())
        for kind in ("nominal", "adapted"):
            for r in manifest["scores"][kind]["logs"]:
                rows[kind][group_of[r["log"]]].append(r)
    print(f"{'condition':22s} {'n':>3s}  exact nominal/adapted   called a propeller fault nominal/adapted")
    table = {}
    for g in [g for g in GROUP_ORDER if g in rows["adapted"]]:
        t = {}
        for kind in ("nominal", "adapted"):
            rs = rows[kind][g]
            t[kind] = {
                "n": len(rs),
                "exact": sum(bool(r["correct"]) for r in rs),
                "called_fault": sum(r["label"] not in (1, None) for r in rs),
            }
        table[g] = t
        n, a = t["nominal"], t["adapted"]
        print(
            f"{g:22s} {a['n']:3d}  {n['exact']:3d} / {a['exact']:3d}             {n['called_fault']:3d} / {a['called_fault']:3d}"
        )
    (args.out / "crazypad-adapt.json").write_text(json.dumps(table, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
