"""Vehicle memory on the real CrazyPAD flights: each airframe's healthy flights as its history, every other log judged.

    nice python -m bench.crazypad_memory [--root ../shared/data/crazypad] [--json out.json]

Per airframe (E8, E9) the vehicle baseline (``monitor.memory``) is learnt from its healthy calibration logs (even log
numbers, ``offline/crazypad/data.py``; a calibration log the others call faulty is reported and kept, as the raw
comparison needs a history); every other motor log of that airframe is judged against it with the thresholds of
``monitor/memory/thresholds.py`` (measured on our simulator, untouched here). Truth in PX4 rotor order (Bitcraze M3 is
PX4 rotor 2). A flight is *named exactly* when the verdict is confident and its propellers are the damaged ones;
*wrong* when confident and not (masses and strings damage no propeller: any confident propeller there is wrong);
*flagged* when any propeller is in the verdict or its set. Rows: the raw judgement, and with the airframe marked
``cg_damage_separable: false`` (offline/crazypad/README.md), as ``propwatch adapt`` writes it for CrazyPAD.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

from bench import REPO
from monitor.diagnose.memory_adapter import as_imbalance
from monitor.memory.learn import HealthyOutlierError, learn_baseline
from monitor.memory.summary import accumulate
from monitor.memory.through_time import judge_through_time
from monitor.vehicle import load_vehicle
from offline.crazypad.data import AIRFRAMES, DEFAULT_ROOT
from offline.crazypad.experiment import GROUP_ORDER
from offline.crazypad.real import read_motor_flights
from offline.crazypad.vehicle import PROJECT_INDEX_OF_BITCRAZE


def truth_px4(flight) -> list[int]:
    """Damaged propellers in PX4 order: cuts and tape only (a mass or a string damages no propeller)."""
    if flight.fault_kind not in ("propeller_cut", "tape_on_propeller"):
        return []
    return sorted(PROJECT_INDEX_OF_BITCRAZE[f"M{i + 1}"] + 1 for i, bad in enumerate(flight.faulty) if bad)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=DEFAULT_ROOT)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    vehicle = load_vehicle(REPO / "models" / "crazyflie.yaml")
    flights, tables = read_motor_flights(vehicle, args.root)
    rows, notes = [], []
    for af in AIRFRAMES:
        cal = [f for f in flights if f.airframe == af and f.role == "calibration"]
        try:
            base = learn_baseline([tables[f.file] for f in cal], [f.file for f in cal], vehicle_id=af)
        except HealthyOutlierError as exc:
            notes.append(f"{af}: {exc}")
            base = learn_baseline([tables[f.file] for f in cal], [f.file for f in cal], vehicle_id=af, check_healthy=False)
        normal = base.normal()
        for f in flights:
            if f.airframe != af or f.role == "calibration":
                continue
            acc = accumulate(tables[f.file])  # judged through time, as diagnose --baseline judges a log
            v = judge_through_time(normal, acc.summary, acc.marks)
            rows.append(
                {
                    "file": f.file,
                    "airframe": af,
                    "group": f.group,
                    "truth": truth_px4(f),
                    "raw": v,
                    "cg": as_imbalance(v) if v["faulty_propellers"] else v,
                }
            )
    by = defaultdict(list)
    for r in rows:
        by[r["group"]].append(r)
    table = {}
    print(f"{len(rows)} CrazyPAD motor logs judged against their airframe's {len(cal)} healthy calibration logs")
    for n in notes:
        print("note:", n)
    print(f"{'condition':22s} {'flights':>7s} | raw: exact wrong flagged | CG/damage alike: exact wrong flagged")
    for g in [g for g in GROUP_ORDER if g in by] + sorted(set(by) - set(GROUP_ORDER)):
        rs = by[g]
        cells = {}
        for key in ("raw", "cg"):
            cells[key] = {
                "exact": sum(
                    r[key]["confidence"] == "confident" and r[key]["faulty_propellers"] == r["truth"] and bool(r["truth"])
                    for r in rs
                ),
                "wrong": sum(r[key]["confidence"] == "confident" and r[key]["faulty_propellers"] != r["truth"] for r in rs),
                "flagged": sum(bool(r[key]["faulty_propellers"] or r[key].get("suspect_propellers")) for r in rs),
            }
        table[g] = {"flights": len(rs), **cells}
        c, d = cells["raw"], cells["cg"]
        print(
            f"{g:22s} {len(rs):7d} | {c['exact']:5d} {c['wrong']:5d} {c['flagged']:7d} | {d['exact']:5d} {d['wrong']:5d} {d['flagged']:7d}"
        )
    if args.json:
        args.json.write_text(json.dumps({"table": table, "notes": notes, "flights": rows}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
