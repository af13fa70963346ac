"""Is a motor lag identifiable from 20 Hz telemetry of the evaluation-only simulator? A sweep.

    nice python -m bench.evalsim_lag --out out/evalsim-lag [--duration-s 40] [--flights 2]
        [--lags-ms 20 30 45 60 75] [--pattern common one] [--jitter-ms 0 4] [--seeds 0]

For every (pattern, hidden lag, telemetry jitter, seed): fly ``--flights`` healthy evalsim flights
(``offline/evalsim``, RotorPy-based, never used for training) of the paper quad with the hidden
motor time constant on all four rotors (``common``) or on rotor 2 only, the other three at the
nominal vehicle's value (``one``); write them as .tlog, read them back through ``monitor.logs``
(the 20 Hz grid, as ``propwatch calibrate`` reads them) and run ``offline.calibrate.calibrate``
against the nominal vehicle. One JSON line per run: the cause named, the fitted time constant(s),
the motor-lag term's held-out BIC gain, pooled held-out RMS reduction and worst-signal ratio (the
selection gates of ``offline.calibrate.fit``), and what the TRUE lags cut from the nominal model's held-out
residual (``truth_rms_cut_pct``: the most any lag term could gain on these flights; ``--truth-only`` skips
the calibration). Results: offline/evalsim/README.md, "Motor lag at 20 Hz".
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from monitor.logs import read_log  # noqa: E402
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402

LAG_TERMS = ("motor_time_constant", "rotor_time_constant")


def read_back(specs, logs, tmp: Path):
    from offline.sim.io_tlog import write_tlog

    v = load_vehicle(DEFAULT_VEHICLE)
    tabs = []
    for spec, log in zip(specs, logs, strict=True):
        path = write_tlog(tmp / f"{spec.name}.tlog", log, 0)
        tabs.append(read_log(path, esc=v.esc))
    return tabs


def summarise(r) -> dict:
    """The cause, the lag term's first-round trial and its gates."""
    from offline.calibrate.fit import relative_rms, worst_signal
    from offline.calibrate.terms import TERMS

    first = r.selection.steps[0]
    base_rms = r.gain["heldout_residual_rms_by_signal_before"]  # the nominal model's, held-out blocks
    out = {"cause": r.cause, "findings": [f["effect"] for f in r.findings]}
    for name in LAG_TERMS:
        fit = first.trials.get(name)
        if fit is None:
            continue
        out[name] = {
            "identifiable": all(fit.identifiable.values()),
            "params_ms": {k: round(1000 * v, 1) for k, v in fit.params(TERMS[name]).items() if k.endswith("_s")},
            "std_ms": {k: round(1000 * v, 1) for k, v in fit.stds(TERMS[name]).items() if k.endswith("_s")},
            "delta_bic": round(first.base_bic - fit.bic, 1),
            "rms_reduction_pct": round(100 * (1 - relative_rms(fit.held_rms, base_rms)), 2),
            "worst_signal_ratio": round(worst_signal(fit.held_rms, base_rms), 3),
        }
    for f in r.findings:
        if f["effect"] in LAG_TERMS:
            out["named_params_ms"] = {k: round(1000 * v, 1) for k, v in f["params"].items() if k.endswith("_s")}
    return out


def truth_gain(tabs, nom, taus_s) -> dict:
    """What the TRUE lags buy over the nominal vehicle on the held-out blocks: the most any lag term could gain."""
    from offline.calibrate.fit import Data, relative_rms, rms_by_signal
    from offline.calibrate.physics import ROT_SIGNALS
    from offline.calibrate.prepare import prepare

    data = Data.split(prepare(tabs, nom))
    taus = np.asarray(taus_s, dtype=np.float64)
    true = dataclasses.replace(nom, motor_time_constant_s=float(taus.mean()), motor_time_constant_ratio=tuple(taus / taus.mean()))
    base, best = rms_by_signal(data.residuals(nom), data.held_masks), rms_by_signal(data.residuals(true), data.held_masks)
    return {
        "truth_rms_cut_pct": round(100 * (1 - relative_rms(best, base)), 2),
        "truth_moment_rms_cut_pct": {s.split("_")[0]: round(100 * (1 - best[s] / base[s]), 1) for s in ROT_SIGNALS},
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--duration-s", type=float, default=40.0)
    ap.add_argument("--flights", type=int, default=2)
    ap.add_argument("--lags-ms", type=float, nargs="+", default=[20.0, 30.0, 45.0, 60.0, 75.0])
    ap.add_argument("--pattern", nargs="+", default=["common", "one"], choices=["common", "one"])
    ap.add_argument("--jitter-ms", type=float, nargs="+", default=[0.0, 4.0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--rotor", type=int, default=2, help="PX4 rotor number of the slow motor (pattern 'one')")
    ap.add_argument(
        "--truth-only", action="store_true", help="no calibration: only what the true lags cut from the nominal residual"
    )
    ap.add_argument(
        "--hidden-set",
        action="store_true",
        help="instead of the sweep: the 2 healthy flights of the 'hidden' set's motor-lag airframe (bench/evalsim_hidden.py)",
    )
    args = ap.parse_args(argv)
    from offline.calibrate.calibrate import calibrate_vehicle
    from offline.evalsim.flight import simulate_flights
    from offline.evalsim.sets import motor_lag_specs

    nom = load_vehicle(DEFAULT_VEHICLE)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    if args.hidden_set:
        from offline.evalsim.sets import build_set

        specs = [s for s in build_set("hidden", 18, 0, args.duration_s) if s.nuisance == "motor_lag" and not s.faulty_propellers]
        logs = simulate_flights(specs)
        with tempfile.TemporaryDirectory() as tmp:
            tabs = read_back(specs, logs, Path(tmp))
        row = {
            "hidden_set": specs[0].airframe_id,
            "hidden_ms": [round(1000 * t, 1) for t in specs[0].airframe.motor_time_constant_s],
        }
        row.update(summarise(calibrate_vehicle(tabs, nom)))
        print(json.dumps(row), flush=True)
        (args.out / "evalsim-lag-hidden.json").write_text(json.dumps(row, indent=1))
        return 0
    for seed in args.seeds:
        for jitter_ms in args.jitter_ms:
            for pattern in args.pattern:
                for lag_ms in args.lags_ms:
                    taus = np.full(4, nom.motor_time_constant_s)
                    if pattern == "common":
                        taus[:] = lag_ms / 1000
                    else:
                        taus[args.rotor - 1] = lag_ms / 1000
                    specs = motor_lag_specs(taus, args.flights, seed, args.duration_s, jitter_ms / 1000)
                    t0 = time.process_time()
                    logs = simulate_flights(specs)
                    with tempfile.TemporaryDirectory() as tmp:
                        tabs = read_back(specs, logs, Path(tmp))
                    t1 = time.process_time()
                    found = {} if args.truth_only else summarise(calibrate_vehicle(tabs, nom))
                    t2 = time.process_time()
                    row = {
                        "seed": seed,
                        "jitter_ms": jitter_ms,
                        "pattern": pattern,
                        "hidden_ms": [round(1000 * t, 1) for t in taus],
                        **found,
                        **truth_gain(tabs, nom, taus),
                        "cpu_s": {"simulate": round(t1 - t0, 1), "calibrate": round(t2 - t1, 1)},
                    }
                    rows.append(row)
                    print(json.dumps(row), flush=True)
    (args.out / "evalsim-lag.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
