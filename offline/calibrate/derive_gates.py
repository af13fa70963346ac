"""Set the selection gates of ``offline.calibrate.fit`` on OUR simulator's nominal flights, to a stated false-naming rate.

    nice python -m offline.calibrate.derive_gates --pairs 40 --duration-s 40 --seed 11 --out out/gates.json

Each calibration gets two healthy flights of the nominal vehicle (``offline.calibrate.nominal_flights``: every
register entry drawn except the ones the term library fits), so any term named there is named wrongly. For every
pair the first selection round's numbers of every candidate are kept (held-out BIC gain, pooled RMS cut, whether
it is identifiable and consistent); a pair is wrongly named under thresholds (gain, cut) when some identifiable,
consistent candidate clears both ("in force": each candidate's own gate, ``fit.gain_threshold``, which grows with
the held-out length beyond 2 x 40 s flights). The held-out BIC threshold is the smallest on the grid that keeps the
wrongly named pairs at or below ``--target``, with a pooled-RMS floor at each value of ``--rms-floors`` (the floor is not
a gate in force: this shows what one would change); the figures are printed beside the gates in force. Never run on the evaluation-only simulator:
those flights measure the gates (``bench/evalsim_calibration.py``), they do not set them.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

BIC_GRID = (10.0, 15.0, 20.0, 25.0, 30.0, 40.0, 50.0, 60.0, 80.0, 100.0, 150.0, 200.0)


def first_round(tables, vehicle) -> dict:
    """The first round's verdict per candidate, as ``calibrate`` reports it."""
    from offline.calibrate.calibrate import calibrate_vehicle

    r = calibrate_vehicle(tables, vehicle)
    return {"cause": r.cause, "candidates": {n: c["verdict"] for n, c in r.candidates.items()}}


def wrongly_named(rows: list[dict], gain_min: float | None, cut_min_pct: float) -> list[str | None]:
    """Per pair: the term that thresholds (gain, cut) would name first, or None. ``gain_min`` None: each
    candidate's gain gate in force (``fit.gain_threshold``, as its verdict records it)."""
    out = []
    for row in rows:
        ok = {
            n: v["heldout_bic_gain"]
            for n, v in row["candidates"].items()
            if v["gates"]["identifiable"]["passed"]
            and v["gates"]["consistency"]["passed"]
            and v["heldout_bic_gain"] > (v["gates"]["heldout_bic_gain"]["threshold"] if gain_min is None else gain_min)
            and v["gates"]["heldout_bic_gain"]["pooled_rms_cut_pct"] >= cut_min_pct
        }
        out.append(max(ok, key=ok.get) if ok else None)
    return out


def consistency_figures(rows: list[dict]) -> dict:
    """What fitting a term does to the other signals on nominal flights: over every identifiable candidate of every
    pair, the signal whose held-out RMS rose by more than ``fit.MAX_SIGNAL_WORSENING`` with the largest paired
    mean-square rise. ``fit.WORSENING_SE`` is set at the largest such rise: the consistency gate vetoes only beyond
    what nominal flights show."""
    worst = [
        (
            v["gates"]["consistency"]["worst_rms_ratio"],
            v["gates"]["consistency"]["worst_se_rise"],
            n,
            v["gates"]["consistency"]["worst_signal"],
        )
        for r in rows
        for n, v in r["candidates"].items()
        if v["gates"]["identifiable"]["passed"] and v["gates"]["consistency"].get("worst_signal")
    ]
    if not worst:
        return {"candidates": 0}
    ratios = np.array([w[0] for w in worst])
    rises = np.array([w[1] for w in worst])
    top = max(worst, key=lambda w: w[1])
    return {
        "candidates": len(worst),
        "rms_ratio_max": float(ratios.max()),
        "rms_ratio_q95": float(np.quantile(ratios, 0.95)),
        "se_rise_max": float(rises.max()),
        "se_rise_q95": float(np.quantile(rises, 0.95)),
        "largest_rise": {"term": top[2], "signal": top[3], "rms_ratio": top[0], "se_rise": top[1]},
    }


def derive(rows: list[dict], target: float, rms_floors_pct: list[float]) -> dict:
    table = {}
    for floor in rms_floors_pct:
        rates = {g: sum(x is not None for x in wrongly_named(rows, g, floor)) for g in BIC_GRID}
        chosen = next((g for g in BIC_GRID if rates[g] <= target * len(rows)), None)
        table[f"{floor:g}"] = {"wrong_pairs_by_gain": rates, "smallest_gain_at_target": chosen}
    return table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m offline.calibrate.derive_gates", description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=40)
    ap.add_argument("--duration-s", type=float, default=40.0)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--target", type=float, default=0.025, help="largest share of wrongly named pairs (default 0.025)")
    ap.add_argument("--rms-floors", type=float, nargs="+", default=[0.0, 1.0, 2.0], help="pooled RMS cut floors, %%")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    from offline.calibrate.fit import GATE_HELDOUT_S, MAX_SIGNAL_WORSENING, MIN_DELTA_BIC, WORSENING_SE
    from offline.calibrate.nominal_flights import nominal_flights

    vehicle = load_vehicle(DEFAULT_VEHICLE)
    rows = []
    for p in range(a.pairs):
        tabs = nominal_flights(vehicle, 2, a.seed * 1000 + p, a.duration_s)
        row = {"pair": p, **first_round(tabs, vehicle)}
        rows.append(row)
        print(json.dumps({"pair": p, "cause": row["cause"]}), file=sys.stderr, flush=True)
    in_force = wrongly_named(rows, None, 0.0)
    thresholds = [v["gates"]["heldout_bic_gain"]["threshold"] for r in rows for v in r["candidates"].values()]
    out = {
        "config": vars(a) | {"out": str(a.out)},
        "gates_in_force": {
            "heldout_bic_gain": MIN_DELTA_BIC,
            "heldout_bic_gain_per_heldout_s": MIN_DELTA_BIC / GATE_HELDOUT_S,
            "heldout_bic_gain_in_force_range": [min(thresholds), max(thresholds)],
            "consistency_rms_ratio": MAX_SIGNAL_WORSENING,
            "consistency_se_rise": WORSENING_SE,
        },
        "wrong_pairs_in_force": sum(x is not None for x in in_force),
        "named_in_force": {n: in_force.count(n) for n in set(in_force) if n},
        "derived": derive(rows, a.target, a.rms_floors),
        "consistency_on_nominal": consistency_figures(rows),
        "largest_consistent_identifiable_gain_per_pair": [
            max(
                [
                    v["heldout_bic_gain"]
                    for v in r["candidates"].values()
                    if v["gates"]["identifiable"]["passed"] and v["gates"]["consistency"]["passed"]
                ]
                or [float("-inf")]
            )
            for r in rows
        ],
        "rows": rows,
    }
    text = json.dumps(out, indent=1, default=float)
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(text + "\n", encoding="utf-8")
    keys = ("gates_in_force", "wrong_pairs_in_force", "named_in_force", "derived", "consistency_on_nominal")
    print(json.dumps({k: out[k] for k in keys}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
