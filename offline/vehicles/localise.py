"""Localisation on quirky airframes, three ways: the vehicle's own baseline, with the calibrated vehicle, the nominal.

    python -m offline.vehicles.localise --fleet DIR [--nominal] [--cache out/localise/cal] [--json OUT.json]

DIR is a same-airframe fleet (``offline.evalsim`` set ``vehicles`` or ``offline.vehicles.ours``; see
``offline.vehicles.evaluate``). Each later flight is judged by ``monitor.memory.judge.judge`` (unchanged) against:

- (a) ``baseline``: the vehicle's normal from its 3 healthy references (today's vehicle memory);
- (b) ``baseline + calibrated``: that normal with its intercept pulled towards the hover shares of the vehicle
  ``propwatch calibrate`` fits on the same 3 references (``offline.vehicles.calibrated``: the prediction weighs as
  many flights as the population prior, 3); beside it a control: the same weight given to the baseline's own mean
  (a prediction carrying no new information), which shows what (b) owes to the weight alone;
- (c) ``nominal vehicle``: no history, the nominal vehicle's hover shares with the population covariance; with
  ``--nominal`` also today's nominal ``propwatch diagnose`` (no baseline), as ``offline.vehicles.evaluate`` runs it;
- (d) ``calibrated alone``: no history, the calibrated vehicle's hover shares with the population covariance,
  calibrated on the first 2 references (before a baseline of 3 exists) and on all 3; beside it the vehicle's normal
  from those 2 references alone (the judgement runs on 2, ``propwatch baseline learn`` asks for 3).

Columns: "exact & confident" (confident and exactly the damaged propeller; on healthy flights confident healthy),
"in set" (the damaged propeller among the verdict's propellers: named, in a hypothesis or suspect), "confident
wrong" (confident and anything else, a healthy call on a damaged flight included), "FAULTY on healthy" (a healthy
flight marked FAULTY: confident with a propeller, as ``offline.vehicles.evaluate`` counts it), "named on healthy" (a
healthy flight given a propeller at any confidence: ambiguous past the fault level, or today's diagnose's uncertain
verdicts). Calibrations are cached (``--cache``; about 20-30 s each).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from monitor.memory.judge import judge
from monitor.memory.normal import normal_of
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.vehicles.calibrated import PREDICTION_FLIGHTS, calibrated_vehicle, hover_shares, prior_normal, pulled_normal
from offline.vehicles.evaluate import CLAIM, REFERENCES, load_fleet

DEFAULT_CACHE = Path("out/localise/cal")
RULES = (
    "(a) baseline (3 references)",
    "(b) baseline + calibrated vehicle",
    "(b) control: baseline + its own mean as the prediction",
    "(c) nominal vehicle, no history",
    "(a) baseline of 2 references (learn needs 3)",
    "(d) calibrated on 2 references, no history",
    "(d) calibrated on 3 references, no history",
)
NOMINAL_DIAGNOSE = "(c) nominal diagnose (today, no baseline)"


def verdict_set(v: dict) -> list[int]:
    """Every propeller a verdict points at: named, in any hypothesis, or suspect."""
    out = set(v.get("faulty_propellers") or []) | set(v.get("suspect_propellers") or [])
    for h in v.get("hypotheses") or []:
        out |= set(h.get("faulty_propellers") or [])
    return sorted(out)


def brief(v: dict) -> dict:
    return {
        "faulty_propellers": list(v["faulty_propellers"]),
        "confidence": v["confidence"],
        "set": verdict_set(v),
        "fault_statistic": v.get("fault_statistic"),
    }


def airframe_predictions(refs: list[dict], nominal, cache: Path | None) -> dict:
    """Hover shares of the nominal vehicle and of the vehicles calibrated on the first 2 and on all 3 references."""
    out = {"nominal": hover_shares(nominal, nominal.esc)}
    for n in (2, REFERENCES):
        vehicle, result = calibrated_vehicle([r["file"] for r in refs[:n]], nominal, cache)
        out[f"calibrated_{n}"] = hover_shares(vehicle, nominal.esc)
        out[f"named_{n}"] = result["named"]
    return out


def score(by: dict[str, list[dict]], nominal, cache: Path | None, k: float = PREDICTION_FLIGHTS) -> tuple[list[dict], dict]:
    """Every later flight's verdict under each rule (a prediction weighs ``k`` flights); each airframe's shares."""
    rows, airframes = [], {}
    for af, flights in by.items():
        refs = [f for f in flights if f["reference"]][:REFERENCES]
        pred = airframe_predictions(refs, nominal, cache)
        own = normal_of([r["summary"] for r in refs])
        own_2 = normal_of([r["summary"] for r in refs[:2]])
        airframes[af] = {
            "own_intercept": own.intercept.tolist(),
            **{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in pred.items()},
        }
        pulled = pulled_normal(own, pred[f"calibrated_{REFERENCES}"], k)
        control = pulled_normal(own, own.intercept, k)  # the same weight, no new information: what (b) owes to it
        for f in flights:
            if f["reference"]:
                continue
            s = f["summary"]
            normals = (own, pulled, control, prior_normal(pred["nominal"], s, k), own_2, prior_normal(pred["calibrated_2"], s, k),
                       prior_normal(pred[f"calibrated_{REFERENCES}"], s, k))  # fmt: skip
            rows.append(
                {"name": f["name"], "file": f["file"], "airframe": af, "faulty": f["faulty"], "loss": f["loss"],
                 "verdicts": {rule: brief(judge(n, s)) for rule, n in zip(RULES, normals)}}
            )  # fmt: skip
    return rows, airframes


def groups(rows: list[dict]) -> dict[str, list[dict]]:
    return {
        f"singles >= {100 * CLAIM:.0f} %": [r for r in rows if len(r["faulty"]) == 1 and r["loss"] >= CLAIM],
        f"singles 3-{100 * CLAIM:.0f} %": [r for r in rows if len(r["faulty"]) == 1 and r["loss"] < CLAIM],
        "healthy later": [r for r in rows if not r["faulty"]],
    }


def cell(sel: list[dict], rule: str) -> dict:
    out = {
        "flights": len(sel),
        "exact_confident": 0,
        "in_set": 0,
        "confident_wrong": 0,
        "faulty_on_healthy": 0,
        "named_on_healthy": 0,
    }
    for r in sel:
        v = r["verdicts"][rule]
        exact = sorted(v["faulty_propellers"]) == sorted(r["faulty"])
        confident = v["confidence"] == "confident"
        out["exact_confident"] += confident and exact
        out["confident_wrong"] += confident and not exact
        out["in_set"] += bool(r["faulty"]) and set(r["faulty"]) <= set(v["set"])
        out["faulty_on_healthy"] += not r["faulty"] and bool(v["faulty_propellers"]) and confident
        out["named_on_healthy"] += not r["faulty"] and bool(v["faulty_propellers"])
    return out


def table(rows: list[dict]) -> dict:
    have = rows[0]["verdicts"] if rows else {}
    rules = [r for r in (*RULES[:4], NOMINAL_DIAGNOSE, *RULES[4:]) if r in have]
    return {g: {rule: cell(sel, rule) for rule in rules} for g, sel in groups(rows).items()}


def format_table(res: dict, title: str) -> str:
    lines = [
        f"| {title}: flights | rule | n | exact & confident | in set | confident wrong | FAULTY on healthy | named on healthy |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for g, rules in res.items():
        healthy = g.startswith("healthy")
        for rule, c in rules.items():
            n = max(c["flights"], 1)
            lines.append(
                f"| {g} | {rule} | {c['flights']} | {c['exact_confident']} ({100 * c['exact_confident'] / n:.0f} %) | "
                f"{'-' if healthy else c['in_set']} | {c['confident_wrong']} | "
                f"{c['faulty_on_healthy'] if healthy else '-'} | {c['named_on_healthy'] if healthy else '-'} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m offline.vehicles.localise", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--fleet", required=True, type=Path, help="a same-airframe fleet folder (truth JSON beside each log)")
    p.add_argument("--nominal", action="store_true", help="also today's nominal diagnose verdict (slower)")
    p.add_argument("--cache", type=Path, default=DEFAULT_CACHE, help=f"calibrated vehicles cached here (default {DEFAULT_CACHE})")
    p.add_argument("--json", type=Path, default=None, help="write the table, every row and each airframe's shares here")
    p.add_argument(
        "--prediction-flights",
        type=float,
        default=PREDICTION_FLIGHTS,
        help=f"how many flights a predicted intercept weighs (default {PREDICTION_FLIGHTS:g}, the population prior's)",
    )
    args = p.parse_args(argv)
    if not args.fleet.is_dir():
        print(f"python -m offline.vehicles.localise: --fleet {args.fleet}: not a folder", file=sys.stderr)
        return 2
    nominal = load_vehicle(DEFAULT_VEHICLE)
    rows, airframes = score(load_fleet(args.fleet), nominal, args.cache, args.prediction_flights)
    if args.nominal:
        from offline.vehicles.evaluate import nominal_verdict_dicts

        for name, v in nominal_verdict_dicts(rows).items():
            next(r for r in rows if r["name"] == name)["verdicts"][NOMINAL_DIAGNOSE] = brief(v)
    res = table(rows)
    print(f"{args.fleet}: {len(airframes)} airframes, {len(rows)} later flights")
    print(format_table(res, args.fleet.name))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"table": res, "airframes": airframes, "rows": rows}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
