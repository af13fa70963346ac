"""The held-out gain gate against the log's length: the same flights calibrated with the gate fixed at
``fit.MIN_DELTA_BIC`` and with the gate in force (``fit.gain_threshold``: MIN_DELTA_BIC per ``fit.GATE_HELDOUT_S``
of held-out log, never below it).

    nice python -m bench.gate_length own --out FILE [--pairs 40] [--duration-s 80] [--seed 12]
    nice python -m bench.gate_length own-lag --out FILE [--lags-ms 35 45 60] [--seeds 3] [--duration-s 80]
    nice python -m bench.gate_length evalsim --out FILE [--nominal 60] [--duration-s 80] [--seed-base 300000]
    nice python -m bench.gate_length evalsim-lag --out FILE [--lags-ms 45] [--seeds 5] [--duration-s 80]
        [--seed-base 190000]

1. ``own`` (OUR simulator, nothing hidden): ``offline.calibrate.nominal_flights`` pairs, as
   ``offline.calibrate.derive_gates`` flies them (seed ``--seed`` x 1000 + pair): anything named is named wrongly.
2. ``own-lag`` (OUR simulator): every rotor lagging by each of ``--lags-ms``, the flights of
   ``bench.evalsim_calibration``'s own phase (``own_tables``, seeds 0..``--seeds``-1): how often the lag is named.
3. ``evalsim`` (the evaluation-only simulator, nothing hidden, fresh seeds; run only with the gate frozen):
   ``bench.evalsim_calibration``'s nothing-hidden runs (``eval_specs(--seed-base + seed, ...)``).
4. ``evalsim-lag`` (the evaluation-only simulator, run only with the gate frozen): ``bench.yaw_spinup evalsim``'s
   runs with every rotor lagging, the same flights (``--seed-base`` 190000: docs/CALIBRATION.md's 2 x 80 s table).

Each flight pair is flown once and calibrated with each gate (where the fixed gate names nothing and reports no
unexplained residual, the gate in force cannot either, and its result is the fixed gate's, ``from_fixed``). Per run, per gate: the terms named, the unexplained residual's
summary, the gate's threshold and the held-out seconds. Writes one JSON line per run to ``--out`` and prints a
summary.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

NOM = load_vehicle(DEFAULT_VEHICLE)


def both_gates(tabs) -> dict:
    """``tabs`` calibrated with the gate fixed at MIN_DELTA_BIC ("fixed") and with the gate in force ("scaled")."""
    from offline.calibrate import fit
    from offline.calibrate.calibrate import calibrate_vehicle

    out = {}
    in_force = fit.GATE_HELDOUT_S
    for name, ref in (("fixed", math.inf), ("scaled", in_force)):
        if name == "scaled" and not out["fixed"]["named"] and not out["fixed"]["unexplained"]:
            # Exact without a second fit: the first round's fits do not depend on the gate, nothing cleared the
            # lower one, so nothing clears the higher one (the rival runs only where a term passes).
            out["scaled"] = out["fixed"] | {"threshold": out["fixed"]["scaled_threshold"], "from_fixed": True}
            continue
        fit.GATE_HELDOUT_S = ref
        try:
            r = calibrate_vehicle(tabs, NOM)
        finally:
            fit.GATE_HELDOUT_S = in_force
        first = r.selection.steps[0]
        out[name] = {
            "named": [f["effect"] for f in r.findings],
            "fitted": {f["effect"]: f["params"] for f in r.findings},
            "unexplained": r.unexplained["found"],
            "unexplained_summary": r.unexplained["summary"],
            "threshold": round(first.threshold, 1),
            "heldout_s": round(r.data.heldout_s, 1),
            "round1_gains": {n: round(v.gain, 1) for n, v in first.verdicts.items()},
            "scaled_threshold": round(fit.gain_threshold(r.data), 1),
        }
    return out


def own(pairs: int, duration_s: float, seed: int):
    from offline.calibrate.nominal_flights import nominal_flights, nominal_register
    from offline.sim.assumptions import draw_flights

    for p in range(pairs):
        s = seed * 1000 + p
        draws = draw_flights(nominal_register(), s, range(2))
        delays = [round(1000 * float(f["attitude_log_delay_s"]), 1) for f in draws]
        yield {"sim": "own", "effect": "none", "pair": p, "flight_seed": s, "attitude_log_delay_ms": delays} | both_gates(
            nominal_flights(NOM, 2, s, duration_s)
        )


def own_lag(lags_ms: list[float], seeds: int, duration_s: float):
    import dataclasses

    from bench.evalsim_calibration import own_tables

    for lag in lags_ms:
        v = dataclasses.replace(NOM, motor_time_constant_s=lag / 1000.0)
        for seed in range(seeds):
            yield {"sim": "own", "effect": "lag_all_rotors", "lag_ms": lag, "seed": seed} | both_gates(
                own_tables(v, seed, duration_s)
            )


def evalsim(nominal: int, duration_s: float, seed_base: int):
    from bench.evalsim_calibration import eval_specs, eval_tables

    for seed in range(nominal):
        yield {"sim": "evalsim", "effect": "none", "seed": seed_base + seed} | both_gates(
            eval_tables(eval_specs(seed_base + seed, duration_s))
        )


def evalsim_lag(lags_ms: list[float], seeds: int, duration_s: float, seed_base: int):
    """``bench.yaw_spinup evalsim``'s lag runs: every rotor lagging by ``lag`` ms, the same flights
    (``yaw_spinup.lag_pair_specs`` at ``yaw_spinup.lag_seed``; the default seed base flies docs/CALIBRATION.md's
    2 x 80 s lag table again)."""
    from bench.evalsim_calibration import eval_tables
    from bench.yaw_spinup import lag_pair_specs, lag_seed

    for lag in lags_ms:
        plan = [lag_seed(seed_base, lag, s) for s in range(seeds)]
        tabs = eval_tables([sp for seed in plan for sp in lag_pair_specs(lag / 1000.0, seed, duration_s)])
        for k, seed in enumerate(plan):
            yield {"sim": "evalsim", "effect": "lag_all_rotors", "lag_ms": lag, "seed": seed} | both_gates(
                tabs[2 * k : 2 * k + 2]
            )


def summarise(rows: list[dict]) -> dict:
    out = {}
    for gate in ("fixed", "scaled"):
        named: dict[str, int] = {}
        for r in rows:
            for t in r[gate]["named"]:
                named[t] = named.get(t, 0) + 1
        out[gate] = {
            "runs": len(rows),
            "runs_naming_a_term": sum(bool(r[gate]["named"]) for r in rows),
            "named_terms": named,
            "unexplained": sum(bool(r[gate]["unexplained"]) for r in rows),
            "threshold_range": [min(r[gate]["threshold"] for r in rows), max(r[gate]["threshold"] for r in rows)]
            if rows
            else None,
        }
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.gate_length", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    o = sub.add_parser("own")
    o.add_argument("--pairs", type=int, default=40)
    o.add_argument("--seed", type=int, default=12)
    ol = sub.add_parser("own-lag")
    ol.add_argument("--lags-ms", type=float, nargs="+", default=[35.0, 45.0, 60.0])
    ol.add_argument("--seeds", type=int, default=3)
    e = sub.add_parser("evalsim")
    e.add_argument("--nominal", type=int, default=60)
    e.add_argument("--seed-base", type=int, default=300_000)
    el = sub.add_parser("evalsim-lag")
    el.add_argument("--lags-ms", type=float, nargs="+", default=[45.0])
    el.add_argument("--seeds", type=int, default=5)
    el.add_argument("--seed-base", type=int, default=190_000)
    for p in (o, ol, e, el):
        p.add_argument("--out", type=Path, required=True)
        p.add_argument("--duration-s", type=float, default=80.0)
    a = ap.parse_args(argv)
    if a.cmd == "own":
        runs = own(a.pairs, a.duration_s, a.seed)
    elif a.cmd == "own-lag":
        runs = own_lag(a.lags_ms, a.seeds, a.duration_s)
    elif a.cmd == "evalsim-lag":
        runs = evalsim_lag(a.lags_ms, a.seeds, a.duration_s, a.seed_base)
    else:
        runs = evalsim(a.nominal, a.duration_s, a.seed_base)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    rows, t0 = [], time.time()
    with a.out.open("w", encoding="utf-8") as f:
        for row in runs:
            rows.append(row)
            f.write(json.dumps(row) + "\n")
            f.flush()
            brief = {k: row[k] for k in row if k not in ("fixed", "scaled")}
            brief |= {g: row[g]["named"] for g in ("fixed", "scaled")} | {"wall_s": round(time.time() - t0)}
            print(json.dumps(brief), file=sys.stderr, flush=True)
    print(json.dumps({"config": {k: str(v) for k, v in vars(a).items()}, "summary": summarise(rows)}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
