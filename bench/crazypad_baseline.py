"""The healthy-baseline rule of ``propwatch adapt`` on every real CrazyPAD motor log, per condition.

    nice python -m bench.crazypad_baseline [--root ../shared/data/crazypad] [--json out.json]

Per airframe (E8, E9), the baseline (``offline.adapt.share_rule``) is built from its healthy logs with an
even number (the CrazyPAD split of ``offline/crazypad/data.py``); every other motor log is
compared with it. A flight is *flagged at M3* when Bitcraze M3 (PX4 rotor 2) is the rotor with
the largest positive deviation and it exceeds 3 spreads; *flagged* when any rotor exceeds 3
spreads. No model, no training: the physics evidence alone, and what it can and cannot tell.
About 40 s.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from bench import REPO
from monitor.vehicle import load_vehicle  # noqa: E402
from offline.adapt.share_rule import OUTLIER_SPREADS, baseline_from_tables  # noqa: E402
from offline.crazypad.data import AIRFRAMES, DEFAULT_ROOT  # noqa: E402
from offline.crazypad.experiment import GROUP_ORDER  # noqa: E402
from offline.crazypad.real import read_motor_flights  # noqa: E402
from offline.crazypad.vehicle import PROJECT_INDEX_OF_BITCRAZE  # noqa: E402

M3 = PROJECT_INDEX_OF_BITCRAZE["M3"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=DEFAULT_ROOT)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    vehicle = load_vehicle(REPO / "models" / "crazyflie.yaml")
    flights, tables = read_motor_flights(vehicle, args.root)
    rows = []
    for af in AIRFRAMES:
        cal = [f for f in flights if f.airframe == af and f.role == "calibration"]
        base = baseline_from_tables([tables[f.file] for f in cal], [f.file for f in cal])
        for f in flights:
            if f.airframe != af or f.role == "calibration":
                continue
            c = base.compare(tables[f.file])
            dev = np.asarray(c["deviation_spreads"])
            rows.append(
                {
                    "file": f.file,
                    "airframe": af,
                    "group": f.group,
                    "deviation_spreads": dev.tolist(),
                    "flagged": bool(np.any(np.abs(dev) > OUTLIER_SPREADS)),
                    "flagged_M3": bool(int(np.argmax(dev)) == M3 and dev[M3] > OUTLIER_SPREADS),
                }
            )
    by = defaultdict(list)
    for r in rows:
        by[r["group"]].append(r)
    print(f"{'condition':22s} {'flights':>7s} {'flagged':>8s} {'flagged at M3':>14s}   per airframe (flagged at M3)")
    table = {}
    for g in [g for g in GROUP_ORDER if g in by]:
        rs = by[g]
        per = {af: [r for r in rs if r["airframe"] == af] for af in AIRFRAMES}
        table[g] = {
            "flights": len(rs),
            "flagged": sum(r["flagged"] for r in rs),
            "flagged_M3": sum(r["flagged_M3"] for r in rs),
            "per_airframe": {af: f"{sum(r['flagged_M3'] for r in v)}/{len(v)}" for af, v in per.items() if v},
        }
        t = table[g]
        print(
            f"{g:22s} {t['flights']:7d} {t['flagged']:8d} {t['flagged_M3']:14d}   "
            + "  ".join(f"{k} {v}" for k, v in t["per_airframe"].items())
        )
    if args.json:
        args.json.write_text(json.dumps({"table": table, "flights": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
