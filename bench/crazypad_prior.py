"""Vehicle memory's flight-to-flight prior measured on real flights: CrazyPAD, one airframe left out.

    nice python -m bench.crazypad_prior [--root ../shared/data/crazypad] [--json out.json]

The prior (``monitor/memory/thresholds.py: PRIOR_COV``) is the covariance of a healthy flight's share intercept about
its vehicle's normal. Shipped, it is measured on our simulator's fleet. Here it is measured on the real healthy
CrazyPAD flights of one airframe (each flight against the normal of the others, over 1 + 1/(m - 1), as
``offline.vehicles.calibrate`` does against 3 references) and used on the other, left out:

- learning: all the left-out airframe's healthy flights offered as its history; accepted where none is FAULTY
  against the others (``monitor.memory.learn.outliers``);
- refusing: each cut-propeller (and tape) flight of that airframe offered as healthy beside them; refused where
  ``outliers`` names it.

Printed beside the same two figures with the simulator's prior. The fault level and set thresholds stay those of
``monitor/memory/thresholds.py``; nothing here is tuned or shipped.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bench import REPO
from monitor.memory import thresholds as th
from monitor.memory.learn import outliers
from monitor.memory.normal import FlightStack
from monitor.memory.summary import summarize
from monitor.vehicle import load_vehicle
from offline.crazypad.data import AIRFRAMES, DEFAULT_ROOT
from offline.crazypad.experiment import GROUP_ORDER
from offline.crazypad.real import read_motor_flights

DAMAGE_KINDS = ("propeller_cut", "tape_on_propeller")


def measured_prior(summaries) -> np.ndarray:
    """(4, 4) covariance of each healthy flight's intercept about the normal of the others, over 1 + 1/(m - 1)."""
    stack = FlightStack.of(summaries)
    m = len(summaries)
    dev = []
    for i, s in enumerate(summaries):
        keep = np.ones(m, dtype=bool)
        keep[i] = False
        dev.append(stack.normal(keep).deviation(s))
    return np.cov(np.array(dev).T) / (1.0 + 1.0 / (m - 1))


def left_out(healthy, damaged, prior) -> dict:
    """Learning the healthy flights, and each damaged one (``(group, summary)``) offered beside them, under
    ``prior``: how many of each group are refused."""
    set_aside = [i for i, _ in outliers(healthy, prior)]
    groups: dict[str, list[int]] = {}
    for group, s in damaged:
        found = [i for i, _ in outliers([*healthy, s], prior)]
        groups.setdefault(group, []).append(int(len(healthy) in found))
    return {
        "healthy": len(healthy),
        "healthy_set_aside": len(set_aside),
        "damaged": {g: {"flights": len(v), "refused": sum(v)} for g, v in groups.items()},
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=DEFAULT_ROOT)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    vehicle = load_vehicle(REPO / "models" / "crazyflie.yaml")
    flights, tables = read_motor_flights(vehicle, args.root)
    summary = {k: summarize(t) for k, t in tables.items()}
    healthy = {af: [summary[f.file] for f in flights if f.airframe == af and f.fault_kind == "healthy"] for af in AIRFRAMES}
    damaged = {
        af: [(f.group, summary[f.file]) for f in flights if f.airframe == af and f.fault_kind in DAMAGE_KINDS] for af in AIRFRAMES
    }
    rows = []
    for out in AIRFRAMES:
        (source,) = [af for af in AIRFRAMES if af != out]
        prior = measured_prior(healthy[source])
        for name, cov in ((f"CrazyPAD {source}", prior), ("our simulator (shipped)", np.asarray(th.PRIOR_COV))):
            rows.append(
                {
                    "left_out": out,
                    "prior": name,
                    "prior_sd": np.sqrt(np.diag(cov)).tolist(),
                    **left_out(healthy[out], damaged[out], cov),
                }
            )
    groups = [g for g in GROUP_ORDER if any(g in r["damaged"] for r in rows)]
    print("left out | prior from              | per-rotor sd of the prior   | healthy set aside | refused: " + ", ".join(groups))
    for r in rows:
        sd = " ".join(f"{x:.4f}" for x in r["prior_sd"])
        refused = ", ".join(
            f"{r['damaged'][g]['refused']}/{r['damaged'][g]['flights']}" if g in r["damaged"] else "-" for g in groups
        )
        print(f"{r['left_out']:8} | {r['prior']:23} | {sd} | {r['healthy_set_aside']} of {r['healthy']}            | {refused}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
