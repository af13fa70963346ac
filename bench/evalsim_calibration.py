"""The hidden-effect matrix: does ``propwatch calibrate`` name what is hidden, and only that?

    nice python -m bench.evalsim_calibration --out out/evaluate-calibration          # make evaluate-calibration
    nice python -m bench.evalsim_calibration --out DIR --seeds 2 --nominal 10 --outside-seeds 2   # reduced
    python -m bench.evalsim_calibration --out DIR --rescore A/runs.jsonl B/runs.jsonl   # earlier runs, scored again

Each run is what a user has: 2 healthy flights of ``--duration-s`` at 20 Hz with telemetry jitter and drops,
read back through a .tlog, calibrated against the nominal vehicle (``offline.calibrate.calibrate``) with the
whole term library and the gates in force.

1. **Resolution, stated beforehand, on OUR simulator** (``offline.calibrate.nominal_flights``: the register
   drawn, the hidden effect on the vehicle): every effect at three sizes, ``--own-seeds`` seeds; an effect's
   resolution is the smallest size named in every own-simulator run ("not identifiable below X").
   ``--own-nominal`` runs with nothing hidden measure, on our simulator, what the outside-library checks must
   stay clear of (the delay rival against the lag terms, the kinematic residual's correlation time).
2. **Outside the library** (evaluation-only simulator): a damaged propeller in a "healthy" flight, a telemetry
   delay between the motor outputs and the estimator, coloured (AR(1)) noise on the rates and attitude: the share
   of runs reporting an "unexplained residual", what was named instead, and how often a named motor_efficiency
   asks for one rotor's propeller to be inspected.
3. **Wrong naming**: ``--nominal`` evaluation-simulator runs with nothing hidden (its small motor spread removed).
4. **The matrix on the evaluation-only simulator** (``offline/evalsim``, never tuned on): every effect at the
   same three sizes, ``--seeds`` seeds; per cell the share of runs naming the hidden effect's term, the share
   naming another term, and the fitted value against the truth with its standard error.

Our simulator's flights really carry the register's ``attitude_log_delay_s`` (0-30 ms per flight), an effect
outside the library: each own-simulator run records the delay its flights drew, and a ``telemetry_delay`` report
there counts as true where a flight's delay is at least ``DELAY_REPORT_RESOLUTION_S``, false below it
(``score_delay_report``).

Writes ``runs.jsonl`` as runs end, ``matrix.json`` (every run) and ``matrix.md`` (the tables) at the end; prints
one JSON line per run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import tempfile
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.logs import read_log
from monitor.vehicle import DEFAULT_VEHICLE, VehicleConfig, load_vehicle

NOM = load_vehicle(DEFAULT_VEHICLE)
HOVER_RPM = NOM.hover_omega_rad_s * 60.0 / (2 * math.pi)
OWN_FLIGHTS = 2  # flights per own-simulator run
OWN_SEED_BASE = 50_000  # own_tables' flights: nominal_flights(..., OWN_SEED_BASE + seed)
OWN_NOMINAL_SEED_BASE = 5000  # the nothing-hidden own runs pass OWN_NOMINAL_SEED_BASE + their seed to own_tables
# The smallest attitude log delay whose ``telemetry_delay`` report counts as true on our simulator
# (``score_delay_report``). offline.calibrate states no resolution for that probe (``unexplained.DELAY_GRID_S`` is
# its search grid, refined to 1 ms), so this is the smallest delay it reported in the matrix's runs: 18.9 ms, on
# our simulator's nothing-hidden run 5002 (``nice -n 19 python -m bench.evalsim_calibration --out
# out/evaluate-calibration-own --effects lag_one_rotor lag_all_rotors esc_curve drag inertia mass gyro_bias
# --own-seeds 5 --own-nominal 10 --seeds 0 --nominal 0 --outside-seeds 0``: delay_probe_ms). The evaluation-only
# simulator's phases (``--own-seeds 0 --own-nominal 0``) reported none below 78 ms.
DELAY_REPORT_RESOLUTION_S = 0.0189


@dataclass(frozen=True)
class Effect:
    name: str
    terms: tuple[str, ...]  # the library terms that name it
    sizes: tuple[float, float, float]
    unit: str
    own: Callable  # (vehicle, size, rng) -> vehicle
    evalsim: Callable  # (spec, size, rng) -> spec
    truth: Callable  # (size, rng) -> value in the fitted value's unit
    fitted: Callable  # (findings by term) -> (value, standard error) or None


def _rotor(rng) -> int:
    return int(rng.integers(4))


def _direction(rng) -> np.ndarray:
    a = rng.uniform(0, 2 * np.pi)
    return np.array([np.cos(a), np.sin(a)])


def _af(spec, **kw):
    return dataclasses.replace(spec, airframe=spec.airframe.with_(**kw))


def _pair(f: dict, name: str, value, se) -> tuple[float, float] | None:
    """(fitted value, its standard error) of term ``name`` where it was named: ``value(params)``, ``se(params, stds)``."""
    if name not in f:
        return None
    p, s = f[name]
    return float(value(p)), float(se(p, s))


def _spread(rng, size) -> np.ndarray:
    """Four thrust efficiencies spread +-size, mean 1."""
    e = 1.0 + size * np.array([1.0, -1.0, 0.5, -0.5])[rng.permutation(4)]
    return e


def _lag_all_fitted(f):
    if "motor_time_constant" in f:
        p, s = f["motor_time_constant"]
        return p["motor_time_constant_s"], s["motor_time_constant_s"]
    if "rotor_time_constant" in f:
        p, s = f["rotor_time_constant"]
        taus = [k for k in p if k.startswith("tau_")]
        return float(np.mean([p[k] for k in taus])), float(np.mean([s[k] for k in taus]))
    return None


def _lag_one_fitted(rotor_of):
    def fitted(f, rng):
        if "rotor_time_constant" not in f:
            return None
        p, s = f["rotor_time_constant"]
        k = rotor_of(rng)
        return p[f"tau_{k + 1}_s"], s[f"tau_{k + 1}_s"]

    return fitted


def _esc_scaled(esc, gain):
    from monitor.esc import EscCurve

    return EscCurve(esc.a_rpm_per_cmd2 * gain, esc.b_rpm_per_cmd * gain, esc.c_rpm * gain, esc.cmd_min, esc.cmd_max, esc.cmd_unit)


def _effects() -> dict[str, Effect]:
    from offline.calibrate.terms import TERMS

    def taus(size, rng, one):
        t = np.full(4, NOM.motor_time_constant_s)
        if one:
            t[_rotor(rng)] = size
        else:
            t[:] = size
        return t

    def cg(size, rng):
        return tuple(float(x) for x in size * _direction(rng)) + (0.0,)

    eff_rotor = _rotor  # the weak motor is drawn first from the run's rng
    effects = [
        Effect(
            "cg_offset",
            ("cg_offset",),
            (0.005, 0.010, 0.020),
            "m (|offset|)",
            lambda v, s, r: dataclasses.replace(v, cg_offset_frd_m=cg(s, r)),
            lambda sp, s, r: _af(sp, cg_offset_frd_m=cg(s, r)),
            lambda s, r: s,
            lambda f, r: _pair(
                f,
                "cg_offset",
                lambda p: np.hypot(p["cg_x_m"], p["cg_y_m"]),
                lambda p, s: np.hypot(s["cg_x_m"], s["cg_y_m"]) / 2**0.5,
            ),
        ),
        Effect(
            "weak_motor",
            ("motor_efficiency",),
            (0.03, 0.06, 0.12),
            "thrust loss of the weak rotor (1 - eff^2 relative to the others)",
            lambda v, s, r: dataclasses.replace(v, motor_efficiency=_weak(np.ones(4), math.sqrt(1 - s), eff_rotor(r))),
            lambda sp, s, r: _af(sp, motor_thrust_efficiency=_weak(sp.airframe.motor_thrust_efficiency, 1 - s, eff_rotor(r))),
            lambda s, r: s,
            lambda f, r: _weak_fitted(f, eff_rotor(r)),
        ),
        Effect(
            "motor_spread",
            ("motor_efficiency",),
            (0.02, 0.04, 0.08),
            "half-range of the thrust efficiencies",
            lambda v, s, r: dataclasses.replace(v, motor_efficiency=tuple(float(x) for x in np.sqrt(_spread(r, s)))),
            lambda sp, s, r: _af(
                sp,
                motor_thrust_efficiency=tuple(float(a * b) for a, b in zip(sp.airframe.motor_thrust_efficiency, _spread(r, s))),
            ),
            lambda s, r: s,
            lambda f, r: _spread_fitted(f),
        ),
        Effect(
            "lag_one_rotor",
            ("rotor_time_constant",),
            (0.045, 0.060, 0.090),
            "s (the slow rotor's time constant)",
            lambda v, s, r: TERMS["rotor_time_constant"].set(v, np.append(taus(s, r, True), v.rotor_inertia_kg_m2)),
            lambda sp, s, r: _af(sp, motor_time_constant_s=tuple(float(x) for x in taus(s, r, True))),
            lambda s, r: s,
            lambda f, r: _lag_one_fitted(_rotor)(f, r),
        ),
        Effect(
            "lag_all_rotors",
            ("motor_time_constant", "rotor_time_constant"),
            (0.035, 0.045, 0.060),
            "s",
            lambda v, s, r: dataclasses.replace(v, motor_time_constant_s=s),
            lambda sp, s, r: _af(sp, motor_time_constant_s=(s,) * 4),
            lambda s, r: s,
            lambda f, r: _lag_all_fitted(f),
        ),
        Effect(
            "esc_curve",
            ("esc_curve",),
            (0.02, 0.04, 0.08),
            "RPM gain error at hover (|1 - rpm_gain - rpm_offset / hover RPM|)",
            lambda v, s, r: TERMS["esc_curve"].set(v, np.array([1.0 - s, 0.0])),
            lambda sp, s, r: _af(sp, esc=_esc_scaled(sp.airframe.esc, 1.0 - s)),
            lambda s, r: s,
            lambda f, r: _pair(
                f, "esc_curve", lambda p: abs(1.0 - p["rpm_gain"] - p["rpm_offset"] / HOVER_RPM), lambda p, s: s["rpm_gain"]
            ),
        ),
        Effect(
            "drag",
            ("drag",),
            (0.1, 0.3, 0.6),
            "N per m/s (horizontal; evalsim: rotor H-force 4 k_d w_hover)",
            lambda v, s, r: dataclasses.replace(v, linear_drag_n_per_m_s=(s, s, 0.5 * s)),
            lambda sp, s, r: _af(sp, rotor_drag_kg_per_rad=s / (4 * NOM.hover_omega_rad_s)),
            lambda s, r: s,
            lambda f, r: _pair(
                f,
                "drag",
                lambda p: 0.5 * (p["drag_x_n_per_m_s"] + p["drag_y_n_per_m_s"]),
                lambda p, s: 0.5 * np.hypot(s["drag_x_n_per_m_s"], s["drag_y_n_per_m_s"]),
            ),
        ),
        Effect(
            "inertia",
            ("inertia",),
            (0.15, 0.30, 0.60),
            "relative error of Ixx",
            lambda v, s, r: dataclasses.replace(v, inertia_diag_kg_m2=tuple(x * (1 + s) for x in v.inertia_diag_kg_m2)),
            lambda sp, s, r: _af(sp, inertia_diag_kg_m2=tuple(x * (1 + s) for x in sp.airframe.inertia_diag_kg_m2)),
            lambda s, r: s,
            lambda f, r: _pair(
                f,
                "inertia",
                lambda p: p["ixx_kg_m2"] / NOM.inertia_diag_kg_m2[0] - 1.0,
                lambda p, s: s["ixx_kg_m2"] / NOM.inertia_diag_kg_m2[0],
            ),
        ),
        Effect(
            "mass",
            ("mass",),
            (0.05, 0.10, 0.20),
            "relative extra mass",
            lambda v, s, r: dataclasses.replace(v, mass_kg=v.mass_kg * (1 + s)),
            lambda sp, s, r: _af(sp, payload_kg=NOM.mass_kg * s),
            lambda s, r: s,
            lambda f, r: _pair(f, "mass", lambda p: p["mass_kg"] / NOM.mass_kg - 1.0, lambda p, s: s["mass_kg"] / NOM.mass_kg),
        ),
        Effect(
            "gyro_bias",
            ("gyro_bias",),
            (0.005, 0.010, 0.020),
            "rad/s (|bias|)",
            lambda v, s, r: dataclasses.replace(v, gyro_bias_frd_rad_s=_bias(s, r)),
            lambda sp, s, r: dataclasses.replace(sp, sensors=dataclasses.replace(sp.sensors, gyro_bias_frd_rad_s=_bias(s, r))),
            lambda s, r: s,
            lambda f, r: _pair(
                f, "gyro_bias", lambda p: np.linalg.norm(list(p.values())), lambda p, s: np.mean(list(s.values()))
            ),
        ),
    ]
    return {e.name: e for e in effects}


def _weak(eff, factor: float, k: int) -> tuple[float, ...]:
    """``eff`` with rotor k's entry times ``factor`` (k drawn once per run by the caller)."""
    return tuple(float(e) * factor if i == k else float(e) for i, e in enumerate(eff))


def _bias(size, rng) -> tuple[float, float, float]:
    d = rng.normal(size=3)
    return tuple(float(x) for x in size * d / np.linalg.norm(d))


def _weak_fitted(f, k):
    if "motor_efficiency" not in f:
        return None
    p, s = f["motor_efficiency"]
    e = np.array([p[f"eff_{i + 1}"] for i in range(4)])
    others = np.delete(e, k).mean()
    return float(1.0 - (e[k] / others) ** 2), float(2.0 * s[f"eff_{k + 1}"])


def _spread_fitted(f):
    if "motor_efficiency" not in f:
        return None
    p, s = f["motor_efficiency"]
    e2 = np.array([p[f"eff_{i + 1}"] for i in range(4)]) ** 2
    return float((e2.max() - e2.min()) / 2 / e2.mean()), float(2.0 * np.mean(list(s.values())))


def _rng(*key) -> np.random.Generator:
    return np.random.default_rng([zlib.crc32(str(k).encode()) for k in key])


def calibrate_tables(tabs, rival_vs_lag: bool = False) -> dict:
    """One run's verdicts. ``rival_vs_lag``: also the outside-library rival's held-out BIC lead over the better
    lag term in round 1 (computed when selection did not run it): what fit.RIVAL_MARGIN_BIC must stay above on
    real lags, and what a delay gives."""
    from offline.calibrate.calibrate import LAG_TERMS, calibrate_vehicle
    from offline.calibrate.unexplained import delay_probe

    r = calibrate_vehicle(tabs, NOM)
    extra = {}
    if rival_vs_lag:
        first = r.selection.steps[0]
        rv = first.rival or delay_probe(r.data, NOM, 0)
        lag = min(first.trials[n].bic for n in LAG_TERMS if n in first.trials)
        extra = {"rival_minus_lag": round(lag - rv["bic"], 1), "rival_delay_ms": round(1000 * rv["delay_s"], 1)}
    return extra | {
        "cause": r.cause,
        "named": [f["effect"] for f in r.findings],
        "findings": {f["effect"]: (f["params"], f["std"]) for f in r.findings},
        "unexplained": r.unexplained["found"],
        "unexplained_summary": r.unexplained["summary"],
        "vetoed": [n for n in r.notes if n.startswith("round ")],
        # The outside-library rival against each round's best passing term (fit.RIVAL_MARGIN_BIC).
        "rival": [
            {
                "round": k + 1,
                "versus": s.rival["versus"],
                "rival_minus_best": round(s.rival["lead"], 1),
                "delay_ms": round(1000 * s.rival["delay_s"], 1),
            }
            for k, s in enumerate(r.selection.steps)
            if s.rival
        ],
        "inspect_rotor": r.inspect_rotor,
        "kin_corr_time": r.unexplained["probes"]["slow_kinematic_error"]["corr_time_samples"],
        # The variance check a whiteness check is compared with: the kinematic residual's held-out RMS, largest axis.
        "kin_rms": max(v for k, v in r.gain["heldout_residual_rms_by_signal_after"].items() if k.endswith("_kin_rad_s")),
        "delay_probe_ms": round(1000 * r.unexplained["probes"]["telemetry_delay"]["value"], 1),
    }


def own_register(vehicle: VehicleConfig):
    """The assumption register an own-simulator run of ``vehicle`` draws its flights from."""
    from offline.calibrate.nominal_flights import nominal_register

    # offline.sim takes each flight's motor time constant from the register (PerFlightTerms), not from the
    # vehicle: pinned to the vehicle's, or a lag hidden on the vehicle never reaches the flights.
    tau = vehicle.motor_time_constant_s
    return nominal_register().with_range("motor_time_constant_s", tau, tau)


def own_tables(vehicle: VehicleConfig, seed: int, duration_s: float):
    from offline.calibrate.nominal_flights import nominal_flights

    return nominal_flights(vehicle, OWN_FLIGHTS, OWN_SEED_BASE + seed, duration_s, own_register(vehicle))


def own_attitude_delays_s(vehicle: VehicleConfig, seed: int) -> list[float]:
    """The ``attitude_log_delay_s`` each flight of ``own_tables(vehicle, seed, ...)`` draws from the register: the
    estimator's delay behind the motor outputs that the run's flights really carry (no flight is simulated)."""
    from offline.sim.assumptions import draw_flights

    draws = draw_flights(own_register(vehicle), OWN_SEED_BASE + seed, range(OWN_FLIGHTS))
    return [float(f["attitude_log_delay_s"]) for f in draws]


def _own_run(effects: dict[str, Effect], row: dict) -> tuple[VehicleConfig, int]:
    """(vehicle, seed passed to ``own_tables``) of an own-simulator run, from its row."""
    if row["effect"] == "none":
        return NOM, OWN_NOMINAL_SEED_BASE + row["seed"]
    name, size, seed = row["effect"], row["size"], row["seed"]
    return effects[name].own(NOM, size, _rng("own", name, size, seed)), seed


def delay_reported(row: dict) -> bool:
    """Whether the run reported a ``telemetry_delay`` unexplained residual (``unexplained_residual``'s summary
    gives each probe found on a line of its own, led by the probe's name)."""
    return bool(row["unexplained"]) and any(
        line.startswith("telemetry_delay (") for line in row["unexplained_summary"].split("; ")
    )


def score_delay_report(row: dict, resolution_s: float = DELAY_REPORT_RESOLUTION_S) -> bool | None:
    """A run's ``telemetry_delay`` report scored against the attitude log delay its flights drew
    (``attitude_log_delay_ms``, own-simulator runs): True (a delay the flights carry) where the largest flight's
    drawn delay is at least ``resolution_s``, False (a delay they do not carry) below it; None where the run
    reports no delay or its flights' delay is not known (the evaluation-only simulator's runs)."""
    drawn = row.get("attitude_log_delay_ms")
    if not drawn or not delay_reported(row):
        return None
    return max(drawn) >= 1000.0 * resolution_s


def eval_tables(specs, post=None):
    from offline.evalsim.flight import simulate_flights
    from offline.sim.io_tlog import write_tlog

    logs = simulate_flights(specs)
    with tempfile.TemporaryDirectory() as d:
        tabs = [read_log(write_tlog(Path(d) / f"{i}.tlog", lg, 0), esc=NOM.esc) for i, lg in enumerate(logs)]
    return [post(t, i) for i, t in enumerate(tabs)] if post else tabs


def eval_specs(seed: int, duration_s: float):
    from offline.evalsim.sets import motor_lag_specs

    # evalsim's airframes carry a +-1 % thrust spread (a real, small effect); the matrix starts from none.
    return [
        _af(sp, motor_thrust_efficiency=(1.0,) * 4)
        for sp in motor_lag_specs([NOM.motor_time_constant_s] * 4, 2, 70_000 + seed, duration_s)
    ]


def _outside() -> dict[str, tuple[Callable, Callable | None]]:
    """name -> (spec modifier, table post-processor)."""
    from offline.calibrate.nominal_flights import degrade_table
    from offline.evalsim.airframe import Damage

    def damaged(sp, r):
        k = _rotor(r)
        one = lambda x: tuple(x if i == k else 0.0 for i in range(4))  # noqa: E731
        return _af(
            sp,
            damage=Damage(
                thrust_loss_at_hover=one(float(r.uniform(0.08, 0.15))),
                torque_per_thrust_change=one(float(r.uniform(-0.10, -0.04))),
                flutter_thrust_std=one(0.01),
                vibration_1p_m_s2=one(0.6),
            ),
        )

    def delay(t, i):
        return degrade_table(t, 0.08, 0.0, 0.0, np.random.default_rng(i))

    def coloured(t, i):
        rng = np.random.default_rng([i, 3])
        n, a = len(t.timestamp_us), 0.95  # AR(1) at 20 Hz: correlation time ~1 s
        z = np.zeros((n, 6))
        e = rng.normal(size=(n, 6)) * np.sqrt(1 - a**2)
        for k in range(1, n):
            z[k] = a * z[k - 1] + e[k]
        return dataclasses.replace(
            t,
            roll_rate_rad_s=t.roll_rate_rad_s + 0.02 * z[:, 0],
            pitch_rate_rad_s=t.pitch_rate_rad_s + 0.02 * z[:, 1],
            yaw_rate_rad_s=t.yaw_rate_rad_s + 0.02 * z[:, 2],
            roll_rad=t.roll_rad + 0.005 * z[:, 3],
            pitch_rad=t.pitch_rad + 0.005 * z[:, 4],
        )

    return {
        "damaged_propeller": (damaged, None),
        "telemetry_delay_80ms": (lambda sp, r: sp, delay),
        "coloured_noise": (lambda sp, r: sp, coloured),
    }


def _cell(rows: list[dict], terms: tuple[str, ...]) -> dict:
    named = sum(bool(set(r["named"]) & set(terms)) for r in rows)
    wrong = sum(bool(set(r["named"]) - set(terms)) for r in rows)
    vals = [(r["fitted"], r["fitted_se"], r["truth"]) for r in rows if r.get("fitted") is not None]
    return {
        "runs": len(rows),
        "named": named,
        "wrong_named": wrong,
        "fitted_mean": float(np.mean([v[0] for v in vals])) if vals else None,
        "fitted_se_mean": float(np.mean([v[1] for v in vals])) if vals else None,
        "truth": rows[0]["truth"] if rows else None,
        "unexplained": sum(bool(r["unexplained"]) for r in rows),
        **_delay_counts(rows),
        "inspect_rotor": sum(r.get("inspect_rotor") is not None for r in rows),
        "rival_minus_best_max": max((x["rival_minus_best"] for r in rows for x in r["rival"]), default=None),
        "rival_minus_lag_max": _max_of(rows, "rival_minus_lag"),
    }


def _delay_counts(rows) -> dict:
    """Runs whose telemetry_delay report is true / false by ``score_delay_report`` (own-simulator runs)."""
    scores = [score_delay_report(r) for r in rows]
    return {"delay_true": sum(x is True for x in scores), "delay_false": sum(x is False for x in scores)}


def _max_of(rows, key):
    return max((r[key] for r in rows if r.get(key) is not None), default=None)


def markdown(res: dict) -> str:
    cfg = res["config"]
    lines = [
        "# Hidden-effect matrix (`python -m bench.evalsim_calibration`)",
        "",
        f"Config: {json.dumps(cfg)}",
        "",
        "## Resolution on our own simulator (stated before the evaluation runs)",
        "",
        "| effect | unit | " + " | ".join(f"size {i + 1}" for i in range(3)) + " | resolution | rival - lag (max) "
        "| unexplained | delay reports: true / false |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    f = lambda x: "-" if x is None else f"{x:.4g}"  # noqa: E731
    for name, e in res["own"].items():
        cells = " | ".join(f"{c['size']:g}: {c['named']}/{c['runs']}" for c in e["cells"])
        rival = max((c["rival_minus_lag_max"] for c in e["cells"] if c["rival_minus_lag_max"] is not None), default=None)
        runs = sum(c["runs"] for c in e["cells"])
        lines.append(
            f"| {name} | {e['unit']} | {cells} | {e['resolution'] if e['resolution'] is not None else 'none of the sizes'} "
            f"| {f(rival)} | {sum(c['unexplained'] for c in e['cells'])}/{runs} "
            f"| {sum(c['delay_true'] for c in e['cells'])} / {sum(c['delay_false'] for c in e['cells'])} |"
        )
    if "own_nominal" in res:
        n = res["own_nominal"]
        lines += [
            "",
            f"Nothing hidden on our simulator: {n['wrong_named']} of {n['runs']} runs named a term, a cause that is "
            f"not there ({json.dumps(n['named_terms'])}); {n['unexplained']} reported an unexplained residual, of "
            f"which {n['delay_true']} the attitude log delay the flights carry and {n['delay_false']} a delay they do "
            "not carry; the rival's BIC "
            f"minus the best passing term's, largest: {f(n['rival_minus_best_max'])} (the rival wins above "
            f"fit.RIVAL_MARGIN_BIC), over the better lag term: {f(n['rival_minus_lag_max'])}; the kinematic residual's "
            f"correlation time, largest: {f(n['kin_corr_time_max'])} "
            "(unexplained.KIN_CORR_TIME_MAX).",
        ]
    lines += [
        "",
        f"A telemetry_delay report is true where a flight of the run drew an attitude log delay of at least "
        f"{1000 * res['delay_resolution_s']:g} ms (score_delay_report).",
        "",
        "## Evaluation-only simulator",
        "",
        "| effect | size | above resolution | named | wrong-named | fitted (mean) | SE (mean) | truth | unexplained "
        "| inspect rotor |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, e in res["evalsim"].items():
        for c in e["cells"]:
            lines.append(
                f"| {name} | {c['size']:g} | {'yes' if c['above_resolution'] else 'no'} | {c['named']}/{c['runs']} | "
                f"{c['wrong_named']}/{c['runs']} | {f(c['fitted_mean'])} | {f(c['fitted_se_mean'])} | {f(c['truth'])} | "
                f"{c['unexplained']}/{c['runs']} | {c['inspect_rotor']}/{c['runs']} |"
            )
    n = res["nominal"]
    lines += [
        "",
        f"**Nothing hidden**: {n['wrong_named']} of {n['runs']} runs ({2 * n['runs']} flights) named a term "
        f"({json.dumps(n['named_terms'])}); {n['unexplained']} reported an unexplained residual; rival minus best "
        f"passing term, largest: {f(n['rival_minus_best_max'])}; over the better lag term: {f(n['rival_minus_lag_max'])}; "
        f"kinematic correlation time, largest: {f(n['kin_corr_time_max'])}.",
        "",
        "## Outside the library",
        "",
        "| effect | runs | unexplained residual | named instead | inspect rotor (caveat) | rival - best (max) "
        "| rival - lag (min) | kin. corr. time (min) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, o in res["outside"].items():
        lines.append(
            f"| {name} | {o['runs']} | {o['unexplained']} | {json.dumps(o['named_terms'])} | {o['inspect_rotor']} | "
            f"{f(o['rival_minus_best_max'])} | {f(o['rival_minus_lag_min'])} | {f(o['kin_corr_time_min'])} |"
        )
    return "\n".join(lines) + "\n"


def _count(rows) -> dict:
    out: dict[str, int] = {}
    for r in rows:
        for t in r["named"]:
            out[t] = out.get(t, 0) + 1
    return out


def _nominal_summary(rows) -> dict:
    return {
        "runs": len(rows),
        "wrong_named": sum(bool(r["named"]) for r in rows),
        "named_terms": _count(rows),
        "unexplained": sum(r["unexplained"] for r in rows),
        **_delay_counts(rows),
        "rival_minus_best_max": max((x["rival_minus_best"] for r in rows for x in r["rival"]), default=None),
        "kin_corr_time_max": _max_of(rows, "kin_corr_time"),
        "kin_rms_max": _max_of(rows, "kin_rms"),
        "rival_minus_lag_max": _max_of(rows, "rival_minus_lag"),
    }


def summarise(runs: list[dict], effects: dict[str, Effect], outside: list[str], config: dict) -> dict:
    """The matrix's tables from its runs (rows as ``runs.jsonl`` holds them): each phase's cells per effect and size."""

    def pick(sim: str, effect: str, size: float | None = None) -> list[dict]:
        return [r for r in runs if r["sim"] == sim and r["effect"] == effect and (size is None or r.get("size") == size)]

    res: dict = {"config": config, "delay_resolution_s": DELAY_REPORT_RESOLUTION_S, "own": {}}
    # 1. Resolution on our own simulator.
    for name, e in effects.items():
        cells = [{"size": size, **_cell([r | {"truth": size} for r in pick("own", name, size)], e.terms)} for size in e.sizes]
        ok = [c["size"] for c in cells if c["runs"] and c["named"] == c["runs"]]  # a cell with no run names nothing
        res["own"][name] = {"unit": e.unit, "cells": cells, "resolution": min(ok) if ok else None}
    res["own_nominal"] = _nominal_summary(pick("own", "none"))
    # 2. Outside the library.
    res["outside"] = {}
    for name in outside:
        rows = pick("evalsim", name)
        res["outside"][name] = {
            "runs": len(rows),
            "unexplained": sum(r["unexplained"] for r in rows),
            "named_terms": _count(rows),
            "inspect_rotor": sum(r["inspect_rotor"] is not None for r in rows),
            "rival_minus_best_max": max((x["rival_minus_best"] for r in rows for x in r["rival"]), default=None),
            "rival_minus_lag_min": min(
                (r["rival_minus_lag"] for r in rows if r.get("rival_minus_lag") is not None), default=None
            ),
            "kin_corr_time_min": min((r["kin_corr_time"] for r in rows), default=None),
            "kin_rms_min": min((r["kin_rms"] for r in rows), default=None),
        }
    # 3. Nothing hidden.
    res["nominal"] = _nominal_summary(pick("evalsim", "none"))
    # 4. The matrix on the evaluation-only simulator.
    res["evalsim"] = {}
    for name, e in effects.items():
        resolution = res["own"][name]["resolution"]
        cells = [
            {
                "size": size,
                "above_resolution": resolution is not None and size >= resolution,
                **_cell(pick("evalsim", name, size), e.terms),
            }
            for size in e.sizes
        ]
        res["evalsim"][name] = {"unit": e.unit, "terms": list(e.terms), "cells": cells}
    res["runs"] = runs
    return res


def rescore(paths: list[Path], effects: dict[str, Effect]) -> list[dict]:
    """The rows of ``runs.jsonl`` files, each own-simulator row given the attitude log delay its flights drew
    where it does not hold it (rows written before the matrix recorded it)."""
    rows = []
    for path in paths:
        for line in path.read_text(encoding="utf-8").splitlines():
            if not line.strip():
                continue
            row = json.loads(line)
            if row["sim"] == "own" and "attitude_log_delay_ms" not in row:
                row["attitude_log_delay_ms"] = _delays_ms(own_attitude_delays_s(*_own_run(effects, row)))
            rows.append(row)
    return rows


def _delays_ms(delays_s: list[float]) -> list[float]:
    return [round(1000.0 * d, 2) for d in delays_s]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.evalsim_calibration", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--duration-s", type=float, default=40.0)
    ap.add_argument("--own-seeds", type=int, default=5)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--nominal", type=int, default=60, help="evalsim runs with nothing hidden (2 flights each)")
    ap.add_argument("--outside-seeds", type=int, default=10)
    ap.add_argument("--own-nominal", type=int, default=10, help="our-simulator runs with nothing hidden (2 flights each)")
    ap.add_argument("--effects", nargs="+", default=None)
    ap.add_argument("--outside", nargs="+", default=None, help="outside-library effects to run (default: all)")
    ap.add_argument(
        "--rescore",
        type=Path,
        nargs="+",
        default=None,
        help="runs.jsonl files of earlier runs: score their rows again (no flight is simulated) and write the tables",
    )
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    effects = _effects()
    if a.effects:
        effects = {k: effects[k] for k in a.effects}
    outside = [n for n in _outside() if not a.outside or n in a.outside]
    config = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(a).items() if k != "rescore"}
    if a.rescore:
        # The runs' own counts and seeds are in their rows; only what selects the tables applies here.
        config = {"out": str(a.out), "effects": a.effects, "outside": a.outside, "rescore": [str(x) for x in a.rescore]}
        rows = rescore(a.rescore, _effects())
        res = summarise(rows, effects, [n for n in outside if any(r["effect"] == n for r in rows)], config)
        return _write(a.out, res)
    t0 = time.time()

    runs: list[dict] = []
    partial = (a.out / "runs.jsonl").open("w", encoding="utf-8")  # every run as it ends (a cut-short run keeps them)

    def log(row, keys):
        runs.append(row)
        partial.write(json.dumps(row, default=float) + "\n")
        partial.flush()
        print(json.dumps({k: row.get(k) for k in keys} | {"wall_s": round(time.time() - t0)}, default=float), flush=True)

    # 1. Resolution on our own simulator.
    for name, e in effects.items():
        for size in e.sizes:
            for seed in range(a.own_seeds):
                r = _rng("own", name, size, seed)
                v = e.own(NOM, size, r)
                row = {"sim": "own", "effect": name, "size": size, "seed": seed} | calibrate_tables(
                    own_tables(v, seed, a.duration_s), name.startswith("lag_")
                )
                row["attitude_log_delay_ms"] = _delays_ms(own_attitude_delays_s(v, seed))
                log(row, ("sim", "effect", "size", "seed", "named", "unexplained", "rival", "rival_minus_lag"))
    for seed in range(a.own_nominal):
        row = {"sim": "own", "effect": "none", "seed": seed} | calibrate_tables(
            own_tables(NOM, OWN_NOMINAL_SEED_BASE + seed, a.duration_s), True
        )
        row["attitude_log_delay_ms"] = _delays_ms(own_attitude_delays_s(NOM, OWN_NOMINAL_SEED_BASE + seed))
        log(row, ("sim", "effect", "seed", "named", "unexplained", "rival", "rival_minus_lag", "kin_corr_time"))
    # 2. Outside the library (before the matrix: a run cut short keeps the targets the matrix cannot miss).
    for name, (mod, post) in _outside().items():
        if name not in outside:
            continue
        for seed in range(a.outside_seeds):
            specs = [mod(sp, _rng("outside", name, seed)) for sp in eval_specs(2000 + seed, a.duration_s)]
            row = {"sim": "evalsim", "effect": name, "seed": seed, **calibrate_tables(eval_tables(specs, post), "delay" in name)}
            log(
                row,
                (
                    "sim",
                    "effect",
                    "seed",
                    "named",
                    "unexplained",
                    "unexplained_summary",
                    "rival",
                    "rival_minus_lag",
                    "inspect_rotor",
                    "kin_corr_time",
                ),
            )
    # 3. Nothing hidden.
    for seed in range(a.nominal):
        row = {
            "sim": "evalsim",
            "effect": "none",
            "seed": seed,
            **calibrate_tables(eval_tables(eval_specs(1000 + seed, a.duration_s)), True),
        }
        log(row, ("sim", "effect", "seed", "named", "unexplained", "rival", "rival_minus_lag"))
    # 4. The matrix on the evaluation-only simulator.
    for name, e in effects.items():
        for size in e.sizes:
            for seed in range(a.seeds):
                specs = [e.evalsim(sp, size, _rng("evalsim", name, size, seed)) for sp in eval_specs(seed, a.duration_s)]
                out = calibrate_tables(eval_tables(specs), name.startswith("lag_"))
                fitted = e.fitted(out["findings"], _rng("evalsim", name, size, seed))
                row = {"sim": "evalsim", "effect": name, "size": size, "seed": seed, **out}
                row |= {
                    "truth": e.truth(size, None),
                    "fitted": fitted[0] if fitted else None,
                    "fitted_se": fitted[1] if fitted else None,
                }
                log(
                    row,
                    (
                        "sim",
                        "effect",
                        "size",
                        "seed",
                        "named",
                        "fitted",
                        "unexplained",
                        "rival",
                        "rival_minus_lag",
                        "inspect_rotor",
                    ),
                )
    return _write(a.out, summarise(runs, effects, outside, config))


def _write(out: Path, res: dict) -> int:
    (out / "matrix.json").write_text(json.dumps(res, indent=1, default=float) + "\n", encoding="utf-8")
    (out / "matrix.md").write_text(markdown(res), encoding="utf-8")
    print(markdown(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
