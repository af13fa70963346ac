"""Measure the vehicle-memory constants (``monitor/memory/thresholds.py``) on our own simulator's fleet.

    python -m offline.vehicles.calibrate --fleet DIR

DIR: ``offline.vehicles.ours.write_fleet(DIR, 288, seed=1)`` (24 airframes). Never the evaluation-only simulator.
- PRIOR_COV: covariance of healthy later flights' deviations from their vehicle's 3 references, over (1 + 1/3)
  (a new flight against a mean of 3: the flight-to-flight covariance of one flight's intercept);
- SUSPECT_STATISTIC: the 95th percentile of the healthy later flights' fault statistic judged with that prior;
- SET_STATISTIC: the 99th percentile, over damaged singles past the healthy 99th percentile, of the best
  hypothesis's statistic minus the true one's (at least 2);
- FAULT_STATISTIC: at least the healthy 99th percentile (a false FAULT on at most 1 % of a vehicle's healthy
  flights), raised in steps of 0.5 as far as it costs no exactly named single of >= 6 % on this fleet: the margin
  against false alarms that exact naming does not pay for.
- SCAN_FAULT_STATISTIC / SCAN_SUSPECT_STATISTIC: the healthy later flights' 99th / 95th percentile of the largest
  statistic of a flight's ends (``monitor.memory.through_time.scan``, each log read again for its marks), never
  below the fault / suspect level above.
Prints the constants to paste, beside the ones in use.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from unittest import mock

import numpy as np

from monitor.memory import thresholds as th
from monitor.memory.judge import judge, statistic_of
from monitor.memory.normal import normal_of
from monitor.memory.through_time import scan, thin
from offline.vehicles.evaluate import CLAIM, REFERENCES, later_flights, load_fleet


def calibrate_memory_thresholds(fleet: Path) -> dict:
    by = load_fleet(fleet, marks=True)
    dev = []
    for refs, f in later_flights(by):
        if not f["faulty"]:
            dev.append(normal_of([r["summary"] for r in refs]).deviation(f["summary"]))
    prior = np.cov(np.array(dev).T) / (1.0 + 1.0 / REFERENCES)
    with mock.patch.object(th, "PRIOR_COV", tuple(map(tuple, prior))):
        normals = [(f, normal_of([r["summary"] for r in refs])) for refs, f in later_flights(by)]
        judged = [(f, judge(n, f["summary"])) for f, n in normals]
        looks = [scan(n, f["summary"], thin(f["marks"], f["summary"])) for f, n in normals if not f["faulty"]]
    healthy = [v["fault_statistic"] for f, v in judged if not f["faulty"]]
    scan_max = [0.0 if b is None else b[1]["fault_statistic"] for b in looks]
    fault99 = float(np.quantile(healthy, 0.99))
    singles = [(f, v) for f, v in judged if len(f["faulty"]) == 1]
    gaps = [v["fault_statistic"] - statistic_of(v, f["faulty"]) for f, v in singles if v["fault_statistic"] >= fault99]
    set_stat = float(max(2.0, np.quantile(gaps, 0.99))) if gaps else 2.0

    def exact(t: float) -> int:
        """Singles >= 6 % named exactly with fault level t: past it, and no other hypothesis within set_stat."""
        n = 0
        for f, v in singles:
            top, st = v["fault_statistic"], [h["statistic"] for h in v["statistics"]]
            if f["loss"] >= CLAIM and top >= t and statistic_of(v, f["faulty"]) == top:
                n += sum(top - x <= set_stat for x in st) == 1
        return n

    sweep = [(float(t), exact(t)) for t in np.arange(np.ceil(fault99 * 2) / 2, 3 * fault99, 0.5)]
    best = max(n for _, n in sweep)
    fault = max(t for t, n in sweep if n == best)
    suspect = float(np.quantile(healthy, 0.95))
    return {
        "scan_fault": max(fault, float(np.quantile(scan_max, 0.99))),
        "scan_suspect": max(suspect, float(np.quantile(scan_max, 0.95))),
        "scan_max": float(max(scan_max)),
        "prior_cov": prior.tolist(),
        "fault": fault,
        "fault_99th_percentile": fault99,
        "suspect": suspect,
        "set": set_stat,
        "sweep": sweep,
        "healthy_flights": len(healthy),
        "healthy_past_fault": sum(h >= fault for h in healthy),
        "damaged_past_fault": len(gaps),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m offline.vehicles.calibrate", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--fleet", required=True, type=Path)
    args = p.parse_args(argv)
    c = calibrate_memory_thresholds(args.fleet)
    print(f"{c['healthy_flights']} healthy later flights, {c['damaged_past_fault']} damaged singles past the fault level")
    print("PRIOR_COV = (\n" + "".join(f"    ({', '.join(f'{x:.3e}' for x in row)}),\n" for row in c["prior_cov"]) + ")")
    print("fault level -> singles >= 6 % named exactly: " + ", ".join(f"{t:g}: {n}" for t, n in c["sweep"]))
    print(
        f"FAULT_STATISTIC = {c['fault']:.1f}  (in use {th.FAULT_STATISTIC}; healthy 99th percentile {c['fault_99th_percentile']:.1f}; "
        f"{c['healthy_past_fault']} of {c['healthy_flights']} healthy flights past it)"
    )
    print(f"SUSPECT_STATISTIC = {c['suspect']:.1f}  (in use {th.SUSPECT_STATISTIC})")
    print(f"SET_STATISTIC = {c['set']:.1f}  (in use {th.SET_STATISTIC})")
    print(
        f"SCAN_FAULT_STATISTIC = {c['scan_fault']:.1f}  (in use {th.SCAN_FAULT_STATISTIC}; largest healthy {c['scan_max']:.1f})"
    )
    print(f"SCAN_SUSPECT_STATISTIC = {c['scan_suspect']:.1f}  (in use {th.SCAN_SUSPECT_STATISTIC})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
