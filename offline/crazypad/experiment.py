"""The sim-to-real loop on CrazyPAD, end to end.

1. read every motor-config flight through the project's reader;
2. calibrate each airframe (E8, E9) on its ``calibration`` healthy flights
   (``offline.calibrate.fit.calibrate_steady``), score on its ``holdout`` flights, and
   check the gain in the simulator too (mission flown by the nominal and the
   calibrated vehicle against the held-out real flights);
3. simulate the training set by one recipe (``offline.crazypad.simdata``) on
   the nominal vehicle and on the calibrated vehicles, train the same CNN on
   each (``offline.classifier.train``), export both to ONNX;
4. diagnose every held-out healthy and every fault flight with each model
   through ``monitor.diagnose.engine.diagnose_table`` (what ``propwatch
   diagnose`` prints) and tabulate accuracy per condition.

Signals: CrazyPAD motor logs have the four motor commands, roll and yaw; no
pitch and no body rates. The classifier uses the commands only, as each
motor's share of the mean (``rpm_rel_1..4``): roll and yaw carry estimator
offsets the simulator does not have. Controller logs (gyro rates, no logged
commands) get commands rebuilt by the firmware mixer (``monitor.logs.mixers``);
this experiment still scores the motor logs only, as before.
"""

from __future__ import annotations

import dataclasses
import json
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.config import to_mapping
from monitor.labels import label_from_mask
from monitor.model import Classifier
from monitor.vehicle import VehicleConfig, load_vehicle_with_sources
from offline.calibrate.fit import SteadyCalibration, calibrate_steady
from offline.crazypad.data import AIRFRAMES, DEFAULT_ROOT, CrazypadFlight, load_manifest, select
from offline.crazypad.mission import CRAZYPAD, batch_waypoints, sim_config
from offline.crazypad.real import FlightSummary, core_mask, read_flight
from offline.crazypad.simdata import Recipe, training_set
from offline.crazypad.vehicle import PROJECT_INDEX_OF_BITCRAZE
from offline.manifest import make_manifest, write_manifest

FEATURES = ("rpm_rel_1", "rpm_rel_2", "rpm_rel_3", "rpm_rel_4")
WINDOW = 60  # 3 s at 20 Hz; a CrazyPAD leg is airborne ~7.5 s
PAPER_REAL_ACCURACY = 0.7632  # Tong et al., real-flight accuracy of the calibrated model


def truth_label(f: CrazypadFlight) -> int:
    """The paper's label for a real flight: only cut or taped propellers are faults."""
    if f.fault_kind not in ("propeller_cut", "tape_on_propeller"):
        return 1
    mask = [False] * 4
    for k, bad in enumerate(f.faulty):
        if bad:
            mask[PROJECT_INDEX_OF_BITCRAZE[f"M{k + 1}"]] = True
    return label_from_mask(mask)


@dataclass
class RealFlight:
    flight: CrazypadFlight
    table: object  # FlightTable
    summary: FlightSummary


def load_real(vehicle: VehicleConfig, root: Path, log=print) -> list[RealFlight]:
    out = []
    flights = select(load_manifest(root))
    for i, f in enumerate(flights):
        tab = read_flight(f, vehicle, root)
        m = core_mask(tab)
        s = FlightSummary(
            f, int(m.sum()), tuple(map(float, np.nanmean(tab.motor_cmd[m], axis=0))), float(np.nanmean(tab.roll_rad[m]))
        )
        out.append(RealFlight(f, tab, s))
        if (i + 1) % 40 == 0:
            log(f"read {i + 1}/{len(flights)} flights")
    return out


def calibrate_airframes(nominal: VehicleConfig, real: list[RealFlight]) -> dict[str, SteadyCalibration]:
    out = {}
    for af in AIRFRAMES:
        fit = [r for r in real if r.flight.airframe == af and r.flight.role == "calibration"]
        held = [r for r in real if r.flight.airframe == af and r.flight.role == "holdout"]
        out[af] = calibrate_steady(
            af,
            nominal,
            np.array([r.summary.motor_cmd_mean for r in fit]),
            np.array([r.summary.motor_cmd_mean for r in held]),
            [r.flight.file for r in fit],
            [r.flight.file for r in held],
        )
    return out


def simulated_shares(vehicle: VehicleConfig, n: int = 4, seed: int = 7) -> np.ndarray:
    """(4,) mean command share per motor (PX4 order) of the healthy mission in the simulator."""
    from offline.sim.propeller import QuadraticPropeller
    from offline.sim.simulator import simulate

    log = simulate(vehicle, batch_waypoints(n), QuadraticPropeller.for_vehicle(vehicle), sim_config(), seed=seed)
    cmd = log.pwm_us[:, int(sim_config().log_rate_hz) :]  # after the start transient
    m = cmd.mean(axis=(0, 1))
    return m / m.mean()


def simulator_gain(nominal: VehicleConfig, cals: dict[str, SteadyCalibration], real: list[RealFlight]) -> dict:
    """RMS of (simulated - real) command shares on held-out healthy flights, nominal vs calibrated sim."""
    nom = simulated_shares(nominal)
    out = {}
    for af, cal in cals.items():
        held = np.array(
            [
                np.asarray(r.summary.motor_cmd_mean) / np.mean(r.summary.motor_cmd_mean)
                for r in real
                if r.flight.airframe == af and r.flight.role == "holdout"
            ]
        )
        cal_sh = simulated_shares(cal.calibrated)
        out[af] = {
            "holdout_flights": len(held),
            "share_rms_nominal_sim": float(np.sqrt(np.mean((held - nom) ** 2))),
            "share_rms_calibrated_sim": float(np.sqrt(np.mean((held - cal_sh) ** 2))),
            "real_holdout_shares_M1_M4": _bitcraze(held.mean(axis=0)),
            "nominal_sim_shares_M1_M4": _bitcraze(nom),
            "calibrated_sim_shares_M1_M4": _bitcraze(cal_sh),
        }
    return out


def _bitcraze(project4) -> list[float]:
    p = np.asarray(project4)
    return [round(float(p[PROJECT_INDEX_OF_BITCRAZE[f"M{k}"]]), 4) for k in range(1, 5)]


def write_vehicle(cal: SteadyCalibration, sources: dict[str, str], path: Path) -> Path:
    """The calibrated vehicle as a cited YAML (loadable by ``load_vehicle``) with provenance."""
    import yaml

    src = dict(sources)
    why = f"steady-state calibration on CrazyPAD {cal.airframe} healthy flights {', '.join(Path(f).name for f in cal.fit_files)}"
    for name in ("motor_efficiency", "cg_offset_frd_m", "mass_kg"):
        src[name] = why
    for f in dataclasses.fields(cal.calibrated):
        src.setdefault(f.name, "neutral default of monitor.vehicle.VehicleConfig (not calibrated)")
    data = to_mapping(cal.calibrated, src)
    data["provenance"] = make_manifest("crazypad-calibrated-vehicle", cal.to_dict(), None)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    load_vehicle_with_sources(path)  # the project's loader must read back what was written
    return path


def diagnose_real(model_paths: dict[str, Path], real: list[RealFlight], esc=None) -> list[dict]:
    """Every non-calibration flight through ``diagnose_table`` with the model of its airframe (key) or "*".

    All windows (hop 1); ``propwatch diagnose`` defaults to one every 10 steps, which averages the same windows.
    """
    from monitor.diagnose.engine import diagnose_table

    clfs = {k: Classifier(p) for k, p in model_paths.items()}
    rows = []
    for r in real:
        if r.flight.role == "calibration":
            continue
        d = diagnose_table(r.table, clfs.get(r.flight.airframe) or clfs["*"], hop=1, esc=esc)
        truth = truth_label(r.flight)
        pred = d.verdict["label"] if d.verdict else None
        rows.append(
            {
                "file": r.flight.file,
                "group": r.flight.group,
                "airframe": r.flight.airframe,
                "truth_label": truth,
                "label": pred,
                "windows": d.windows,
                "fault_probability": d.verdict["fault_probability"] if d.verdict else None,
                "reason": d.reason,
            }
        )
    return rows


GROUP_ORDER = (
    "healthy",
    "cut <=1 mm",
    "cut 1.5-2.5 mm",
    "cut 3-4.5 mm",
    "cut 5-8 mm",
    "tape M3",
    "tape M3+M4",
    "mass W1 near M3",
    "mass W1 near M3+M4",
    "mass W3 near M3",
    "string W2 near M3",
    "string W3 near M3",
)


def table_by_group(rows: list[dict]) -> dict[str, dict]:
    """Per condition: flights, exact-label accuracy, and how often any propeller is called faulty."""
    g = defaultdict(list)
    for r in rows:
        g[r["group"]].append(r)
    out = {}
    for name in GROUP_ORDER + tuple(sorted(set(g) - set(GROUP_ORDER))):
        rs = g.get(name)
        if not rs:
            continue
        ok = [r for r in rs if r["label"] is not None]
        out[name] = {
            "flights": len(rs),
            "diagnosed": len(ok),
            "accuracy": float(np.mean([r["label"] == r["truth_label"] for r in ok])) if ok else float("nan"),
            "called_faulty": float(np.mean([r["label"] != 1 for r in ok])) if ok else float("nan"),
            "M3_called_faulty": float(np.mean([r["label"] is not None and 2 in _props(r["label"]) for r in ok]))
            if ok
            else float("nan"),
        }
    allok = [r for r in rows if r["label"] is not None]
    out["all"] = {
        "flights": len(rows),
        "diagnosed": len(allok),
        "accuracy": float(np.mean([r["label"] == r["truth_label"] for r in allok])) if allok else float("nan"),
        "called_faulty": float(np.mean([r["label"] != 1 for r in allok])) if allok else float("nan"),
        "M3_called_faulty": float("nan"),
    }
    return out


def _props(label: int) -> tuple[int, ...]:
    from monitor.labels import LABEL_TABLE

    return LABEL_TABLE[label]


VARIANTS = {
    "nominal": "trained on the nominal simulation (one model)",
    "calibrated": "trained on the calibrated simulation, both airframes (one model, shipped)",
    "calibrated_own": "trained on the calibrated simulation of the flight's own airframe (one model per airframe)",
}


def format_markdown(report: dict) -> str:
    t = report["table"]
    head = (
        "| condition (real CrazyPAD motor logs) | flights | "
        + " | ".join(f"accuracy: {k}" for k in t)
        + " | called faulty: "
        + " / ".join(t)
        + " |"
    )
    lines = [head, "|" + "---|" * (3 + len(t))]
    first = next(iter(t.values()))
    for name in first:
        cells = [f"{100 * t[k].get(name, {}).get('accuracy', float('nan')):.1f} %" for k in t]
        faulty = " / ".join(f"{100 * t[k].get(name, {}).get('called_faulty', float('nan')):.0f} %" for k in t)
        lines.append(f"| {name} | {first[name]['flights']} | " + " | ".join(cells) + f" | {faulty} |")
    lines.append(
        "| paper (Tong et al., real flights, calibrated) | | "
        + " | ".join("" for _ in t)
        + f" {100 * PAPER_REAL_ACCURACY:.2f} % | |"
    )
    lines += ["", *(f"- {k}: {VARIANTS.get(k, k)}" for k in t)]
    return "\n".join(lines)


DEFAULT_RECIPE = Recipe(flights_per_label=20)


def run(
    out: Path,
    root: Path = DEFAULT_ROOT,
    vehicle_path: Path | None = None,
    recipe: Recipe = DEFAULT_RECIPE,
    epochs: int = 8,
    log=print,
) -> dict:
    from monitor.resources import shipped
    from offline.classifier.export import export_onnx
    from offline.classifier.train import TrainConfig, train

    vehicle_path = vehicle_path or shipped("crazyflie.yaml")
    loaded = load_vehicle_with_sources(vehicle_path)
    nominal = loaded.config
    out.mkdir(parents=True, exist_ok=True)
    log(f"reading real flights from {root}")
    real = load_real(nominal, root, log)
    cals = calibrate_airframes(nominal, real)
    for af, cal in cals.items():
        write_vehicle(cal, loaded.sources, out / f"crazyflie-{af}-calibrated.yaml")
        log(
            f"{af}: cause {cal.cause}; held-out RMS command error {cal.nominal_holdout_rms_cmd:.0f} -> "
            f"{cal.calibrated_holdout_rms_cmd:.0f}"
        )
    sim_gain = simulator_gain(nominal, cals, real)
    log(
        "simulator gain: "
        + json.dumps({k: {kk: round(vv, 4) for kk, vv in v.items() if kk.startswith("share_rms")} for k, v in sim_gain.items()})
    )
    cfg = TrainConfig(features=FEATURES, window=WINDOW, epochs=epochs, train_stride=4, test_fraction=0.2, seed=recipe.seed)
    trainings = [("nominal", [nominal]), ("calibrated", [cals[af].calibrated for af in AIRFRAMES])]
    trainings += [(f"calibrated-{af}", [cals[af].calibrated]) for af in AIRFRAMES]
    paths, sims = {}, {}
    for kind, vehicles in trainings:
        log(f"simulating the {kind} training set")
        ds = training_set(vehicles, recipe, f"crazypad-{kind}")
        log(f"training on {ds.n_flights} simulated flights ({kind})")
        m = train(ds, cfg, log=lambda s: None)
        log(f"{kind}: final train accuracy {100 * m.history[-1]['train_accuracy']:.1f} % (simulated windows)")
        sims[kind] = {"flights": ds.n_flights, "history": m.history, "sim_test_flights": m.test_flights}
        paths[kind] = export_onnx(
            m,
            out / f"crazyflie-classifier-{kind}.onnx",
            extra_metadata={
                "crazypad": {
                    "trained_on": kind,
                    "window_s": WINDOW / 20.0,
                    "signals": "motor commands only (shares of the mean)",
                    "airframes": [af for af in AIRFRAMES if kind in ("calibrated", f"calibrated-{af}")],
                }
            },
        )
    esc = nominal.esc
    results = {
        "nominal": diagnose_real({"*": paths["nominal"]}, real, esc),
        "calibrated": diagnose_real({"*": paths["calibrated"]}, real, esc),
        "calibrated_own": diagnose_real({af: paths[f"calibrated-{af}"] for af in AIRFRAMES}, real, esc),
    }
    report = {
        "split": {
            role: sorted(r.flight.file for r in real if r.flight.role == role)
            if role != "evaluation"
            else len([r for r in real if r.flight.role == role])
            for role in ("calibration", "holdout", "evaluation")
        },
        "features": list(FEATURES),
        "window_steps": WINDOW,
        "rate_hz": 20.0,
        "recipe": dataclasses.asdict(recipe),
        "epochs": epochs,
        "mission": dataclasses.asdict(CRAZYPAD),
        "calibration": {af: c.to_dict() for af, c in cals.items()},
        "simulator_gain": sim_gain,
        "training": sims,
        "table": {k: table_by_group(v) for k, v in results.items()},
        "flights": results,
        "paper_real_accuracy": PAPER_REAL_ACCURACY,
        "models": {k: str(p) for k, p in paths.items()},
    }
    report["markdown"] = format_markdown(report)
    write_manifest(
        out / "crazypad-report.json", make_manifest("crazypad-experiment", {"root": str(root)}, recipe.seed, report=report)
    )
    (out / "crazypad-report.md").write_text(report["markdown"] + "\n", encoding="utf-8")
    log(report["markdown"])
    return report
