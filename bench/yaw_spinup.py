"""Why yaw disagrees under a motor lag, and what the rotors' spin-up reaction buys: six measurements.

    nice python -m bench.yaw_spinup candidates [--lags-ms 20 60] [--seeds 0 1 2] [--duration-s 40]
    nice python -m bench.yaw_spinup crazypad
    nice python -m bench.yaw_spinup resolution [--sizes 2.5e-6 5e-6 1e-5 2e-5] [--seeds 10] [--duration-s 40]
    nice python -m bench.yaw_spinup own [--lags-ms 60] [--seeds 5] [--duration-s 40] [--fixed-rotor-inertia 2e-5]
    nice python -m bench.yaw_spinup evalsim --out DIR [--lags-ms 30 45 60 80] [--seeds 5] [--nominal 60]
        [--duration-s 80] [--seed-base 90000]
    nice python -m bench.yaw_spinup localise --fleet DIR [DIR ...] --out DIR
    nice python -m bench.yaw_spinup attitude-delay [--seeds 50001 50003 55002 55003 55004] [--duration-s 40]

1. ``candidates`` (OUR simulator, ``offline.calibrate.nominal_flights``: the register drawn, the rotor inertia
   from its 1e-5..4e-5 kg m^2 range, every rotor lagging by ``--lags-ms``): with the thrust lag at its true
   value, each candidate yaw term's one parameter fitted on the fit blocks (bounded 1-D search on the yaw
   equation error), scored on the held-out blocks: none (the model before), the spin-up reaction (rotor inertia
   x dω/dt), a torque lag of its own (the yaw torque lagging by a different time constant from thrust), a drag
   torque ``ktau w_h^2 (w / w_h)^p`` with a fitted exponent. Also the yaw residual with the TRUE lag and no
   reaction: worse than the nominal 20 ms, the veto's cause.
2. ``crazypad``: the same question on CrazyPAD's 12 healthy motor logs (100 Hz; yaw and roll from the estimator's
   angles, twice differentiated) and its 8 healthy controller logs (gyro rates against the rate controller's
   outputs): each axis's acceleration against its command through a lag, with and without a lead (the spin-up
   reaction's form, b/a seconds), fitted on alternating 1-s blocks, held-out R^2 on the others.
3. ``resolution`` (OUR simulator): the rotor inertia hidden on the vehicle at each size, nominal lag, 2 flights of
   ``--duration-s``: how often a named term writes a rotor inertia, and its value.
4. ``evalsim`` (the evaluation-only simulator, fresh seeds, run only with the term and gates frozen): every rotor
   lagging by each of ``--lags-ms`` (``--seeds`` runs each) and ``--nominal`` runs with nothing hidden, 2 flights of
   ``--duration-s`` through a .tlog; each calibrated with the library before the spin-up reaction (lag terms with
   the rotor inertia held at the vehicle's 0, no ``rotor_inertia`` term) and with today's. Per run: what is named,
   the fitted lag, and the held-out residual RMS per axis of the nominal vehicle and of each library's result.
   Writes ``runs.jsonl`` as runs end and ``summary.json``. ``own`` does the same on OUR simulator's register
   flights with the rotor inertia drawn (as ``candidates``), or on its fixed path with ``--fixed-rotor-inertia``.
5. ``localise``: ``offline.vehicles.localise``'s rules on same-airframe fleets (``make evaluate-memory``'s, or the
   first airframes of one: ``offline.evalsim.sets.write_set("vehicles", ...)``, ``offline.vehicles.ours.write_fleet``)
   with the vehicle calibrated by the library before the spin-up reaction and by today's: both tables, each
   airframe's named terms and the largest hover-share difference between the two calibrated vehicles, and the later
   flights whose verdict differs. Writes ``localise.json`` under ``--out``.
6. ``attitude-delay`` (OUR simulator, nothing hidden): ``bench.evalsim_calibration``'s own flights
   (``nominal_flights`` at the given seeds, the lag pinned to the vehicle's) with the rotor inertia held at the
   vehicle's 0, as they are now, or drawn from the register's range, as they were before the library had the term;
   each calibrated with both libraries. Per run: the terms named, the unexplained residual and the telemetry-delay
   probe's fitted delay, beside the register's attitude log delay drawn for each flight.
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import json
import sys
import time
from pathlib import Path

import numpy as np

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

NOM = load_vehicle(DEFAULT_VEHICLE)
ROT = ("roll_accel_rad_s2", "pitch_accel_rad_s2", "yaw_accel_rad_s2")
LAG_TERMS = ("motor_time_constant", "rotor_time_constant")
CRAZYPAD = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "crazypad"


def library(before: bool) -> list:
    from offline.calibrate.terms import TERMS, without_spin_up

    if not before:
        return list(TERMS.values())
    return [without_spin_up(t) if t.name in LAG_TERMS else t for n, t in TERMS.items() if n != "rotor_inertia"]


# --- 1. candidate yaw terms on our simulator -------------------------------------------------------------------


def yaw_residual(seg, vehicle, rotor_inertia_kg_m2=0.0, torque_tau_s=None, drag_exponent=2.0) -> np.ndarray:
    """(T,) measured minus predicted yaw acceleration with one candidate yaw term (``offline.calibrate.physics``'s
    filters; the candidates are written here, not in the calibrator, so each can be compared)."""
    from offline.calibrate import physics as P

    w_cmd = P.target_omega_rad_s(seg, vehicle, fine=True)
    u = np.asarray(vehicle.motor_efficiency) * w_cmd
    taus = vehicle.rotor_time_constants_s
    w = P.first_order_lag(u, taus, seg.dt_fine_s)
    wq = w if torque_tau_s is None else P.first_order_lag(u, np.full(4, torque_tau_s), seg.dt_fine_s)
    w_h = vehicle.hover_omega_rad_s
    q = vehicle.ktau_nm_per_rad_s2 * w_h**2 * (np.maximum(wq, 0.0) / w_h) ** drag_exponent
    q = q + rotor_inertia_kg_m2 * (u - w) / taus
    J = np.asarray(vehicle.inertia_diag_kg_m2)
    om = seg.rates_fine_rad_s
    alpha = ((q * vehicle.spin_sign).sum(axis=1) - np.cross(om, om * J)[:, 2]) / J[2]
    return seg.rates_deriv_rad_s2[:, 2] - P.integrated(seg, alpha)


def _yaw_rms(segs, masks, vehicle, **kw) -> float:
    r = np.concatenate([yaw_residual(s, vehicle, **kw)[m] for s, m in zip(segs, masks)])
    return float(np.sqrt(np.mean(r**2)))


def lag_and_spin_up_register(tau_s: float):
    """The register as ``nominal_flights`` draws it, every rotor lagging by ``tau_s``, the rotor inertia drawn from
    the register's own range (nominal flights hold it at the vehicle's 0)."""
    from offline.calibrate.nominal_flights import nominal_register
    from offline.sim.assumptions import REGISTER

    j = REGISTER["rotor_inertia_kg_m2"]
    reg = nominal_register().with_range("motor_time_constant_s", tau_s, tau_s)
    return dataclasses.replace(reg, assumptions=tuple(j if a.name == j.name else a for a in reg.assumptions))


def candidates(lags_ms: list[float], seeds: list[int], duration_s: float) -> list[dict]:
    from scipy.optimize import minimize_scalar

    from offline.calibrate.fit import Data
    from offline.calibrate.nominal_flights import nominal_flights
    from offline.calibrate.prepare import prepare

    rows = []
    for lag_ms in lags_ms:
        tau = lag_ms / 1000.0
        reg = lag_and_spin_up_register(tau)
        for seed in seeds:
            segs = prepare(nominal_flights(NOM, 2, 60_000 + seed, duration_s, reg), NOM)
            data = Data.split(segs)
            F, H = data.fit_masks, data.held_masks
            lagged = dataclasses.replace(NOM, motor_time_constant_s=tau)
            fits = {
                "rotor_inertia_kg_m2": (lambda x: {"rotor_inertia_kg_m2": x}, (0.0, 2e-4)),
                "torque_tau_s": (lambda x: {"torque_tau_s": x}, (0.001, 0.3)),
                "drag_exponent": (lambda x: {"drag_exponent": x}, (1.0, 3.0)),
            }
            row = {
                "lag_ms": lag_ms,
                "seed": seed,
                "yaw_heldout_rms": {
                    "nominal_20ms": round(_yaw_rms(segs, H, NOM), 4),
                    "true_lag_alone": round(_yaw_rms(segs, H, lagged), 4),
                },
            }
            for name, (kw, bounds) in fits.items():
                r = minimize_scalar(
                    lambda x, kw=kw, segs=segs, F=F, lagged=lagged: _yaw_rms(segs, F, lagged, **kw(x)),
                    bounds=bounds,
                    method="bounded",
                )
                row["yaw_heldout_rms"][f"true_lag+{name}"] = round(_yaw_rms(segs, H, lagged, **kw(r.x)), 4)
                row[f"fitted_{name}"] = float(f"{r.x:.4g}")
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


# --- 2. CrazyPAD -------------------------------------------------------------------------------------------------


def _lag(u: np.ndarray, tau_s: float, dt_s: float) -> np.ndarray:
    from scipy.signal import lfilter

    a = np.exp(-dt_s / tau_s)
    return lfilter([1 - a], [1, -a], u - u[0]) + u[0]


def _prep(x: np.ndarray, w: int) -> np.ndarray:
    """The response-gain filters (``offline.response_gain``): [1/4, 1/2, 1/4] smoother, then minus a moving mean."""
    x = np.convolve(x, [0.25, 0.5, 0.25], mode="same")
    return x - np.convolve(x, np.ones(w) / w, mode="same")


def _axis_fit(t, acc, u, a, b, lead: bool) -> tuple[float, float, float, float]:
    """Best lag (1-s alternating blocks): (tau_s, held-out SSE, held-out SS, lead b/a in s)."""
    dt = float(np.median(np.diff(t)))
    sl = slice(a, b)
    y = _prep(acc, 50)[sl][20:-20]
    fit = ((np.floor((t[sl] - t[a]) / 1.0).astype(int) % 2) == 0)[20:-20]
    best = None
    for tau in np.arange(0.005, 0.1201, 0.005):
        lu = _lag(u, tau, dt)
        cols = [_prep(lu, 50)[sl][20:-20]] + ([_prep(np.gradient(lu) / dt, 50)[sl][20:-20]] if lead else [])
        X = np.column_stack(cols + [np.ones(len(y))])
        coef, *_ = np.linalg.lstsq(X[fit], y[fit], rcond=None)
        e = y[~fit] - X[~fit] @ coef
        sse = float(e @ e)
        if best is None or sse < best[1]:
            ss = float(np.sum((y[~fit] - y[~fit].mean()) ** 2))
            best = (float(tau), sse, ss, float(coef[1] / coef[0]) if lead else 0.0)
    return best


def crazypad(root: Path = CRAZYPAD) -> dict:
    import pandas as pd

    out: dict = {}
    for kind in ("motor", "controller"):
        per: dict = {}
        for f in sorted(glob.glob(str(root / kind / "normal_flight" / "*.csv.gz"))):
            d = pd.read_csv(f)
            t = d["t_ms"].to_numpy() / 1000.0
            dt = float(np.median(np.diff(t)))
            if kind == "motor":
                if "stateEstimate.yaw" not in d or "motor.m1" not in d:
                    continue
                m = np.column_stack([d[f"motor.m{i}"].to_numpy() for i in range(1, 5)]).astype(float)
                on = m.sum(axis=1) > 0
                # Bitcraze M1 front-right, M2 rear-right, M3 rear-left, M4 front-left; M1/M3 and M2/M4 share a spin.
                axes = {
                    "yaw": (
                        np.gradient(np.gradient(np.unwrap(np.radians(d["stateEstimate.yaw"].to_numpy())))) / dt**2,
                        m[:, 0] - m[:, 1] + m[:, 2] - m[:, 3],
                    ),
                    "roll": (
                        np.gradient(np.gradient(np.radians(d["stateEstimate.roll"].to_numpy()))) / dt**2,
                        m[:, 2] + m[:, 3] - m[:, 0] - m[:, 1],
                    ),
                }
            else:
                on = d["controller.cmd_thrust"].to_numpy() > 0
                axes = {
                    ax: (np.gradient(d[f"controller.r_{ax}"].to_numpy()) / dt, d[f"controller.cmd_{ax}"].to_numpy().astype(float))
                    for ax in ("roll", "pitch", "yaw")
                }
            idx = np.flatnonzero(on & (d["stateEstimate.z"].to_numpy() > 0.25))
            a, b = int(idx[0]) + 100, int(idx[-1]) - 100  # 1 s off each end: take-off and landing
            for ax, (acc, u) in axes.items():
                for lead in (False, True):
                    per.setdefault((ax, lead), []).append(_axis_fit(t, acc, u, a, b, lead))
        out[kind] = {
            f"{ax}{' +lead' if lead else ''}": {
                "flights": len(v),
                "heldout_r2": round(1.0 - sum(x[1] for x in v) / sum(x[2] for x in v), 3),
                "tau_ms_median": round(1000 * float(np.median([x[0] for x in v])), 1),
                **({"lead_s_median": round(float(np.median([x[3] for x in v])), 4)} if lead else {}),
            }
            for (ax, lead), v in per.items()
        }
    return out


# --- 3. resolution on our simulator ------------------------------------------------------------------------------


def _rotor_inertia_named(findings: list[dict]) -> float | None:
    vals = [f["params"]["rotor_inertia_kg_m2"] for f in findings if "rotor_inertia_kg_m2" in f["params"]]
    return vals[-1] if vals else None


def resolution(sizes: list[float], seeds: int, duration_s: float) -> list[dict]:
    from offline.calibrate.calibrate import calibrate_vehicle
    from offline.calibrate.nominal_flights import nominal_flights

    rows = []
    for size in sizes:
        truth = dataclasses.replace(NOM, rotor_inertia_kg_m2=size)
        named, vals = 0, []
        for seed in range(seeds):
            r = calibrate_vehicle(nominal_flights(truth, 2, 80_000 + seed, duration_s), NOM)
            j = _rotor_inertia_named(r.findings)
            named += j is not None
            vals += [j] if j is not None else []
            print(
                json.dumps({"size": size, "seed": seed, "named": [f["effect"] for f in r.findings], "rotor_inertia": j}),
                flush=True,
            )
        row = {"size_kg_m2": size, "runs": seeds, "named": named, "fitted_mean": float(np.mean(vals)) if vals else None}
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def own(lags_ms: list[float], seeds: int, duration_s: float, fixed_rotor_inertia_kg_m2: float | None = None) -> dict:
    """``evalsim``'s before/after on OUR simulator: its register flights with the spin-up reaction drawn, or (with
    ``fixed_rotor_inertia_kg_m2``) its fixed path with that rotor inertia on the vehicle."""
    from offline.calibrate.nominal_flights import fixed_flights, nominal_flights

    rows = []
    for lag in lags_ms:
        for seed in range(seeds):
            if fixed_rotor_inertia_kg_m2 is None:
                tabs = nominal_flights(NOM, 2, 61_000 + seed, duration_s, lag_and_spin_up_register(lag / 1000.0))
            else:
                truth = dataclasses.replace(
                    NOM, motor_time_constant_s=lag / 1000.0, rotor_inertia_kg_m2=fixed_rotor_inertia_kg_m2
                )
                tabs = fixed_flights(truth, 2, seed, duration_s)
            row = {"lag_ms": lag, "seed": seed} | calibrate_both(tabs)
            rows.append(row)
            print(
                json.dumps(
                    {k: row[k] for k in ("lag_ms", "seed", "named", "fitted_lag_s", "rotor_inertia_kg_m2", "before_named")}
                ),
                flush=True,
            )
    return summarise(rows)


# --- 4. the evaluation-only simulator ----------------------------------------------------------------------------


def _per_axis(res, masks) -> dict[str, float]:
    from offline.calibrate.fit import rms_by_signal

    r = rms_by_signal(res, masks)
    return {s: round(r[s], 5) for s in ROT}


def calibrate_both(tabs, before: bool = True) -> dict:
    """Today's calibration (named, fitted lag, per-axis held-out RMS) and (``before``) the library before the
    spin-up reaction on the same data."""
    from offline.calibrate.calibrate import calibrate_vehicle
    from offline.calibrate.fit import select_terms
    from offline.calibrate.unexplained import delay_probe

    r = calibrate_vehicle(tabs, NOM)
    data = r.data
    old = select_terms(data, NOM, library(before=True), rival=delay_probe) if before else None
    lag = next((f for f in r.findings if f["effect"] in LAG_TERMS), None)
    taus = [v for k, v in (lag["params"].items() if lag else []) if k.endswith("_s")]
    return {
        "named": [f["effect"] for f in r.findings],
        "cause": r.cause,
        "fitted_lag_s": float(np.mean(taus)) if taus else None,
        "rotor_inertia_kg_m2": _rotor_inertia_named(r.findings),
        "unexplained": r.unexplained["summary"] if r.unexplained["found"] else None,
        "vetoed": [n for n in r.notes if n.startswith("round ")],
        "before_named": old.chosen if old else None,
        "before_vetoed": {
            n: v.why
            for s in (old.steps if old else [])
            for n, v in s.verdicts.items()
            if n in LAG_TERMS and v.gate == "consistency"
        },
        "heldout_rms": {
            "nominal": _per_axis(r.selection.nominal_residuals, data.held_masks),
            "before": _per_axis(old.final.residuals if old and old.final else r.selection.nominal_residuals, data.held_masks)
            if old
            else None,
            "after": _per_axis(
                r.selection.final.residuals if r.selection.final else r.selection.nominal_residuals, data.held_masks
            ),
        },
    }


def lag_seed(seed_base: int, lag_ms: float, k: int) -> int:
    """The flight seed of the ``k``-th run of an all-rotor lag of ``lag_ms`` (``evalsim``'s plan)."""
    return seed_base + 100 * int(lag_ms) + k


def lag_pair_specs(tau_s: float, seed: int, duration_s: float) -> list:
    """The two evaluation-only flights of one run: every rotor lagging by ``tau_s``, every motor's efficiency 1."""
    from bench.evalsim_calibration import _af
    from offline.evalsim.sets import motor_lag_specs

    return [_af(sp, motor_thrust_efficiency=(1.0,) * 4) for sp in motor_lag_specs([tau_s] * 4, 2, seed, duration_s)]


def evalsim(out: Path, lags_ms: list[float], seeds: int, nominal: int, duration_s: float, seed_base: int) -> dict:
    from bench.evalsim_calibration import eval_tables

    out.mkdir(parents=True, exist_ok=True)
    runs = out / "runs.jsonl"
    plan = [(lag, lag_seed(seed_base, lag, s)) for s in range(seeds) for lag in lags_ms]
    plan += [(None, seed_base + 50_000 + s) for s in range(nominal)]
    rows = []
    batch = 8  # runs simulated together (16 flights): the evaluation simulator's cost per flight falls with the batch
    for i in range(0, len(plan), batch):
        chunk = plan[i : i + batch]
        specs = []
        for lag, seed in chunk:
            specs += lag_pair_specs(NOM.motor_time_constant_s if lag is None else lag / 1000.0, seed, duration_s)
        tabs = eval_tables(specs)
        for k, (lag, seed) in enumerate(chunk):
            t0 = time.process_time()
            # Nothing hidden: today's library only (the verdict the target is about; half the cost).
            row = {"lag_ms": lag, "seed": seed} | calibrate_both(tabs[2 * k : 2 * k + 2], before=lag is not None)
            row["cpu_s"] = round(time.process_time() - t0, 1)
            rows.append(row)
            with runs.open("a", encoding="utf-8") as fh:
                fh.write(json.dumps(row) + "\n")
            print(
                json.dumps({k: row[k] for k in ("lag_ms", "seed", "named", "fitted_lag_s", "before_named", "cpu_s")}), flush=True
            )
    summary = summarise(rows)
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return summary


def summarise(rows: list[dict]) -> dict:
    out: dict = {}
    for lag in sorted({r["lag_ms"] for r in rows}, key=lambda x: -1 if x is None else x):
        rs = [r for r in rows if r["lag_ms"] == lag]
        key = "nothing_hidden" if lag is None else f"lag_{lag:g}ms"
        cell = {"runs": len(rs)}
        if lag is None:
            cell["named_a_cause"] = sum(r["cause"] is not None for r in rs)
            cell["named_terms"] = sorted({t for r in rs for t in r["named"]})
        else:
            ok = [r for r in rs if set(r["named"]) & set(LAG_TERMS)]
            cell["lag_named"] = len(ok)
            cell["before_lag_named"] = sum(bool(set(r["before_named"]) & set(LAG_TERMS)) for r in rs)
            cell["within_15pct"] = sum(abs(r["fitted_lag_s"] - lag / 1000.0) <= 0.15 * lag / 1000.0 for r in ok)
            cell["fitted_lag_ms"] = sorted(round(1000 * r["fitted_lag_s"], 1) for r in ok)
            cell["rotor_inertia_written"] = sum(r["rotor_inertia_kg_m2"] is not None and r["rotor_inertia_kg_m2"] > 0 for r in rs)
        for which in ("nominal", "before", "after"):
            got = [r["heldout_rms"][which] for r in rs if r["heldout_rms"][which]]
            if got:
                cell[f"heldout_rms_median_{which}"] = {s: float(np.median([g[s] for g in got])) for s in ROT}
        out[key] = cell
    return out


# --- 5. localisation with a vehicle calibrated by each library ----------------------------------------------------


def localise(fleets: list[Path], out: Path) -> dict:
    """Each fleet scored by ``offline.vehicles.localise.score`` twice: the vehicle calibrated by the library before
    the spin-up reaction, then by today's. The calibration cache's key knows the calibrator's source, not the term
    library it was handed, so each library caches in its own folder (``out/cal-before``, ``out/cal-after``)."""
    from unittest import mock

    from offline.calibrate.terms import TERMS
    from offline.vehicles.evaluate import load_fleet
    from offline.vehicles.localise import format_table, score, table

    res: dict = {}
    for folder in fleets:
        by = load_fleet(folder)
        got = {}
        for which in ("before", "after"):
            terms = {t.name: t for t in library(before=which == "before")}
            with mock.patch.dict(TERMS, terms, clear=True):  # calibrate_vehicle reads its library from TERMS
                got[which] = score(by, NOM, out / f"cal-{which}")
        (rows_b, af_b), (rows_a, af_a) = got["before"], got["after"]
        airframes = {
            af: {
                "named_2": {"before": af_b[af]["named_2"], "after": af_a[af]["named_2"]},
                "named_3": {"before": af_b[af]["named_3"], "after": af_a[af]["named_3"]},
                "share_diff_max": max(
                    float(np.max(np.abs(np.subtract(af_a[af][k], af_b[af][k])))) for k in ("calibrated_2", "calibrated_3")
                ),
            }
            for af in af_a
        }
        pairs = [(b, a, rule) for b, a in zip(rows_b, rows_a, strict=True) for rule in a["verdicts"]]
        changed = [
            {"name": a["name"], "rule": rule, "before": b["verdicts"][rule], "after": a["verdicts"][rule]}
            for b, a, rule in pairs
            if _verdict(a["verdicts"][rule]) != _verdict(b["verdicts"][rule])
        ]
        statistic_change = max(
            (abs(a["verdicts"][r]["fault_statistic"] - b["verdicts"][r]["fault_statistic"]) for b, a, r in pairs), default=0.0
        )
        res[str(folder)] = {
            "airframes": airframes,
            "later_flights": len(rows_a),
            "verdicts_changed": changed,
            "fault_statistic_change_max": statistic_change,
            "table_before": table(rows_b),
            "table_after": table(rows_a),
        }
        print(
            f"{folder}: {len(by)} airframes, {len(rows_a)} later flights; verdicts changed (propellers, confidence or "
            f"set, any rule): {len(changed)}; fault statistic moved by at most {statistic_change:.3g}",
            file=sys.stderr,
        )
        for which, rows in (("library before the spin-up reaction", rows_b), ("today's library", rows_a)):
            print(format_table(table(rows), f"{folder.name}, {which}"), file=sys.stderr)
    out.mkdir(parents=True, exist_ok=True)
    (out / "localise.json").write_text(json.dumps(res, indent=1, default=float) + "\n", encoding="utf-8")
    return res


def _verdict(v: dict) -> tuple:
    """What a verdict says (its propellers, confidence and set), without the statistic behind it."""
    return tuple(v["faulty_propellers"]), v["confidence"], tuple(v["set"])


# --- 6. the register's attitude delay, with and without the spin-up reaction in the flights ----------------------


def attitude_delay(seeds: list[int], duration_s: float) -> list[dict]:
    from unittest import mock

    from offline.calibrate.calibrate import calibrate_vehicle
    from offline.calibrate.nominal_flights import nominal_flights, nominal_register
    from offline.calibrate.terms import TERMS
    from offline.sim.assumptions import draw_flights

    tau = NOM.motor_time_constant_s
    registers = {
        "rotor inertia 0": nominal_register().with_range("motor_time_constant_s", tau, tau),
        "rotor inertia drawn": lag_and_spin_up_register(tau),
    }
    rows = []
    for seed in seeds:
        for flights, register in registers.items():
            drawn = draw_flights(register, seed, range(2))
            tabs = nominal_flights(NOM, 2, seed, duration_s, register)
            for which in ("before", "after"):
                with mock.patch.dict(TERMS, {t.name: t for t in library(before=which == "before")}, clear=True):
                    r = calibrate_vehicle(tabs, NOM)
                row = {
                    "seed": seed,
                    "flights": flights,
                    "library": which,
                    "attitude_log_delay_ms": [round(1000 * float(np.mean(f.values["attitude_log_delay_s"])), 1) for f in drawn],
                    "rotor_inertia_kg_m2": [float(np.mean(f.values["rotor_inertia_kg_m2"])) for f in drawn],
                    "named": [f["effect"] for f in r.findings],
                    "unexplained": r.unexplained["summary"] if r.unexplained["found"] else None,
                    "delay_probe_ms": round(1000 * r.unexplained["probes"]["telemetry_delay"]["value"], 1),
                }
                rows.append(row)
                print(json.dumps(row), file=sys.stderr, flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.yaw_spinup", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    c = sub.add_parser("candidates")
    c.add_argument("--lags-ms", type=float, nargs="+", default=[20.0, 60.0])
    c.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    c.add_argument("--duration-s", type=float, default=40.0)
    sub.add_parser("crazypad")
    r = sub.add_parser("resolution")
    r.add_argument("--sizes", type=float, nargs="+", default=[2.5e-6, 5e-6, 1e-5, 2e-5])
    r.add_argument("--seeds", type=int, default=10)
    r.add_argument("--duration-s", type=float, default=40.0)
    o = sub.add_parser("own")
    o.add_argument("--lags-ms", type=float, nargs="+", default=[60.0])
    o.add_argument("--seeds", type=int, default=5)
    o.add_argument("--duration-s", type=float, default=40.0)
    o.add_argument("--fixed-rotor-inertia", type=float, default=None, help="kg m^2: the fixed path with this rotor inertia")
    e = sub.add_parser("evalsim")
    e.add_argument("--out", type=Path, required=True)
    e.add_argument("--lags-ms", type=float, nargs="+", default=[30.0, 45.0, 60.0, 80.0])
    e.add_argument("--seeds", type=int, default=5)
    e.add_argument("--nominal", type=int, default=60)
    e.add_argument("--duration-s", type=float, default=80.0)
    e.add_argument("--seed-base", type=int, default=90_000)
    lo = sub.add_parser("localise")
    lo.add_argument("--fleet", type=Path, nargs="+", required=True, help="same-airframe fleet folders")
    lo.add_argument("--out", type=Path, required=True, help="localise.json and the two calibration caches go here")
    ad = sub.add_parser("attitude-delay")
    ad.add_argument("--seeds", type=int, nargs="+", default=[50_001, 50_003, 55_002, 55_003, 55_004])
    ad.add_argument("--duration-s", type=float, default=40.0)
    a = ap.parse_args(argv)
    if a.what == "candidates":
        res = candidates(a.lags_ms, a.seeds, a.duration_s)
    elif a.what == "crazypad":
        res = crazypad()
    elif a.what == "own":
        res = own(a.lags_ms, a.seeds, a.duration_s, a.fixed_rotor_inertia)
    elif a.what == "resolution":
        res = resolution(a.sizes, a.seeds, a.duration_s)
    elif a.what == "localise":
        res = localise(a.fleet, a.out)
    elif a.what == "attitude-delay":
        res = attitude_delay(a.seeds, a.duration_s)
    else:
        res = evalsim(a.out, a.lags_ms, a.seeds, a.nominal, a.duration_s, a.seed_base)
    json.dump(res, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
