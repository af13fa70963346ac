"""Why a hidden motor lag fits long on OUR simulator: its fit against the attitude log delay and the telemetry
jitter the flights carry.

    nice python -m bench.lag_delay --out FILE [--lags-ms 60] [--delays-ms 0 15 30] [--jitters-ms 0 5]
        [--seeds 3] [--duration-s 40]
    nice python -m bench.lag_delay --out FILE --fixed-path [--lags-ms 60 80] [--seeds 2] [--duration-s 40]

Every rotor lagging by each of ``--lags-ms``: ``bench.evalsim_calibration``'s own flights (``nominal_flights`` at
``OWN_SEED_BASE + seed``, the register's lag pinned to the vehicle's) with the register's ``attitude_log_delay_s``
pinned at each of ``--delays-ms`` and ``telemetry_jitter_std_s`` at each of ``--jitters-ms`` (every other draw
unchanged: a pinned entry still takes its variate). Per run: what calibrate names, the first round's
``motor_time_constant`` fit (value, held-out gain, whether named) whatever is named, and the outside-library
rival's delay. Writes one JSON line per run to ``--out`` and prints the fitted lag per (lag, delay, jitter) cell.
``--fixed-path``: our simulator's fixed path instead (no register draw: no delay, no jitter, exact 20 Hz), each
pair calibrated as tables and again after a .tlog round trip (``offline.sim.io_tlog.write_tlog``, ``read_log``),
the path every evaluation-only run takes.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

NOM = load_vehicle(DEFAULT_VEHICLE)


def first_round_lag(r) -> dict:
    """Calibration ``r``'s first-round ``motor_time_constant`` fit, whatever was named: its value, held-out gain and
    the gate that decided it."""
    from offline.calibrate.terms import TERMS

    first = r.selection.steps[0]
    verdict = first.verdicts["motor_time_constant"]
    tau_s = first.trials["motor_time_constant"].params(TERMS["motor_time_constant"])["motor_time_constant_s"]
    return {
        "round1_motor_time_constant_ms": round(1000 * tau_s, 1),
        "round1_motor_time_constant_gain": round(verdict.gain, 1),
        "round1_motor_time_constant_gate": verdict.gate,
    }


def run(lag_ms: float, delay_ms: float, jitter_ms: float, seed: int, duration_s: float) -> dict:
    from bench.evalsim_calibration import OWN_FLIGHTS, OWN_SEED_BASE, _lag_all_fitted, own_register
    from offline.calibrate.calibrate import calibrate_vehicle
    from offline.calibrate.nominal_flights import nominal_flights

    v = dataclasses.replace(NOM, motor_time_constant_s=lag_ms / 1000.0)
    reg = own_register(v).with_range("attitude_log_delay_s", delay_ms / 1000.0, delay_ms / 1000.0)
    reg = reg.with_range("telemetry_jitter_std_s", jitter_ms / 1000.0, jitter_ms / 1000.0)
    r = calibrate_vehicle(nominal_flights(v, OWN_FLIGHTS, OWN_SEED_BASE + seed, duration_s, reg), NOM)
    named = _lag_all_fitted({f["effect"]: (f["params"], f["std"]) for f in r.findings})
    rival = r.selection.steps[0].rival or {}
    return {
        "lag_ms": lag_ms,
        "delay_ms": delay_ms,
        "jitter_ms": jitter_ms,
        "seed": seed,
        "named": [f["effect"] for f in r.findings],
        "named_lag_ms": round(1000 * named[0], 1) if named else None,
        **first_round_lag(r),
        "rival_delay_ms": round(1000 * rival["delay_s"], 1) if "delay_s" in rival else None,
        "unexplained": r.unexplained["summary"],
    }


def fixed_run(lag_ms: float, seed: int, duration_s: float, through_tlog: bool) -> dict:
    """Our simulator's fixed path (no register draw, exact 20 Hz, no delay, no jitter), every rotor lagging by
    ``lag_ms``: the flights as tables, or written to a .tlog and read back as a user's log is."""
    import tempfile

    from monitor.logs import read_log
    from offline.calibrate.calibrate import calibrate_vehicle
    from offline.calibrate.nominal_flights import _simulate
    from offline.sim.io_tlog import write_tlog

    v = dataclasses.replace(NOM, motor_time_constant_s=lag_ms / 1000.0)
    log = _simulate(v, 2, seed, duration_s)
    if through_tlog:
        with tempfile.TemporaryDirectory() as d:
            tabs = [read_log(write_tlog(Path(d) / f"{i}.tlog", log, i), esc=NOM.esc) for i in range(2)]
    else:
        tabs = [log.to_flight_table(i, source=f"fixed-{seed}-{i}") for i in range(2)]
    r = calibrate_vehicle(tabs, NOM)
    return {
        "path": "fixed-tlog" if through_tlog else "fixed",
        "lag_ms": lag_ms,
        "seed": seed,
        "named": [f["effect"] for f in r.findings],
        **first_round_lag(r),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.lag_delay", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--lags-ms", type=float, nargs="+", default=[60.0])
    ap.add_argument("--delays-ms", type=float, nargs="+", default=[0.0, 15.0, 30.0])
    ap.add_argument("--jitters-ms", type=float, nargs="+", default=[0.0, 5.0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--duration-s", type=float, default=40.0)
    ap.add_argument(
        "--fixed-path",
        action="store_true",
        help="our fixed path instead (no delay, no jitter): each pair as tables and through a .tlog",
    )
    a = ap.parse_args(argv)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    if a.fixed_path:
        with a.out.open("w", encoding="utf-8") as f:
            for lag in a.lags_ms:
                for seed in range(a.seeds):
                    for tlog in (False, True):
                        row = fixed_run(lag, seed, a.duration_s, tlog)
                        f.write(json.dumps(row) + "\n")
                        print(json.dumps(row), flush=True)
        return 0
    with a.out.open("w", encoding="utf-8") as f:
        for lag in a.lags_ms:
            for delay in a.delays_ms:
                for jitter in a.jitters_ms:
                    for seed in range(a.seeds):
                        row = run(lag, delay, jitter, seed, a.duration_s)
                        rows.append(row)
                        f.write(json.dumps(row) + "\n")
                        f.flush()
                        print(json.dumps(row), file=sys.stderr, flush=True)
    cells = {}
    for r in rows:
        cells.setdefault((r["lag_ms"], r["delay_ms"], r["jitter_ms"]), []).append(r)
    for (lag, delay, jitter), rs in cells.items():
        fits = [r["round1_motor_time_constant_ms"] for r in rs]
        print(
            json.dumps(
                {
                    "lag_ms": lag,
                    "delay_ms": delay,
                    "jitter_ms": jitter,
                    "runs": len(rs),
                    "lag_named": sum(r["named_lag_ms"] is not None for r in rs),
                    "round1_lag_ms_mean": round(float(np.mean(fits)), 1),
                    "round1_lag_ms_range": [min(fits), max(fits)],
                    "excess_over_truth_ms_mean": round(float(np.mean(fits)) - lag, 1),
                }
            )
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
