"""propwatch crazypad: the sim-to-real experiment on real Crazyflie flights.

    propwatch crazypad analyse   [--data DIR] [--json]              per-condition command shares, per airframe
    propwatch crazypad calibrate [--data DIR] [--out DIR] [--json]  steady-state calibration per airframe
    propwatch crazypad run --out DIR [--data DIR] [--flights-per-label N] [--epochs N] [--ship]

run calibrates, simulates, trains (nominal / calibrated / per airframe), diagnoses every held-out real flight
and writes crazypad-report.json and .md; --ship then copies the both-airframes calibrated model to
models/crazyflie-classifier.onnx with its manifest.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError
from monitor.resources import shipped
from monitor.vehicle import load_vehicle, load_vehicle_with_sources
from offline.crazypad.data import DEFAULT_ROOT, load_manifest, select

DEFAULT_VEHICLE = shipped("crazyflie.yaml")
SHIPPED_MODEL = shipped("crazyflie-classifier.onnx")
SUBCOMMANDS = {
    "analyse": "each airframe's per-condition command shares, healthy against cut propellers",
    "calibrate": "the steady-state calibration of each airframe (writes a vehicle YAML per airframe with --out)",
    "run": "calibrate, simulate, train and diagnose every held-out real flight; --ship installs the model",
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="propwatch crazypad", description=__doc__.split(": ", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = p.add_subparsers(dest="cmd", required=True, metavar="{analyse,calibrate,run}")
    for name, help_ in SUBCOMMANDS.items():
        s = sub.add_parser(name, help=help_, description=help_)
        s.add_argument("--data", default=str(DEFAULT_ROOT), help="CrazyPAD folder (default: ../shared/data/crazypad)")
        s.add_argument("--vehicle", default=str(DEFAULT_VEHICLE), help="nominal vehicle YAML")
        if name != "run":
            s.add_argument("--json", action="store_true", help="JSON on stdout")
        if name != "analyse":
            s.add_argument("--out", required=name == "run", default=None, help="output folder")
        if name == "run":
            s.add_argument(
                "--flights-per-label", type=int, default=20, help="simulated flights per label for training (default 20)"
            )
            s.add_argument("--epochs", type=int, default=8, help="training epochs (default 8)")
            s.add_argument("--seed", type=int, default=0, help="seed of simulation and training (default 0)")
            s.add_argument("--ship", action="store_true", help=f"copy the calibrated model to {SHIPPED_MODEL}")
    return p


def _root(args) -> Path:
    root = Path(args.data)
    if not (root / "manifest.csv").is_file():
        raise LogFormatError(f"{root}: no CrazyPAD manifest.csv here (see ../shared/data/crazypad/README.md)")
    return root


def analyse(root: Path, vehicle_path: str) -> dict:
    from offline.calibrate.fit import calibrate_steady, equivalent_speed_ratios
    from offline.crazypad.real import summarise
    from offline.crazypad.vehicle import bitcraze_order

    v = load_vehicle(vehicle_path)
    groups: dict[tuple[str, str], list] = defaultdict(list)
    for f in select(load_manifest(root)):
        groups[(f.group, f.airframe)].append(summarise(f, v, root))
    # Each airframe's own calibration (healthy calibration flights only), to express every
    # condition as the rotor speed scale it would take in the model.
    cal = {}
    for af in {a for _, a in groups}:
        fit = np.array([r.motor_cmd_mean for r in groups.get(("healthy", af), []) if r.flight.role == "calibration"])
        cal[af] = calibrate_steady(af, v, fit, fit, [], []).calibrated if len(fit) else None
    out = {}
    for (group, af), rows in sorted(groups.items()):
        sh = np.array([r.shares_bitcraze for r in rows])
        out[f"{group} / {af}"] = {
            "flights": len(rows),
            "shares_M1_M4_mean": sh.mean(axis=0).round(4).tolist(),
            "shares_M1_M4_std": sh.std(axis=0).round(4).tolist(),
            "mean_cmd": round(float(np.mean([r.mean_cmd for r in rows])), 1),
        }
        if cal[af] is not None:
            ratio = equivalent_speed_ratios(cal[af], np.array([r.motor_cmd_mean for r in rows]))
            out[f"{group} / {af}"]["thrust_factor_M1_M4"] = [round(float(x) ** 2, 3) for x in bitcraze_order(ratio)]
    return out


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    root = _root(args)
    if args.cmd == "analyse":
        res = analyse(root, args.vehicle)
        if args.json:
            json.dump(res, sys.stdout, indent=2)
            print()
        else:
            print(
                f"{'condition / airframe':30s} flights  command share M1..M4 (core phases)"
                "   thrust factor M1..M4 vs own calibrated airframe"
            )
            for k, r in res.items():
                tf = "  ".join(f"{x:.2f}" for x in r.get("thrust_factor_M1_M4", []))
                print(f"{k:30s} {r['flights']:5d}  " + "  ".join(f"{x:.3f}" for x in r["shares_M1_M4_mean"]) + f"    {tf}")
        return 0
    if args.cmd == "calibrate":
        from offline.crazypad.experiment import calibrate_airframes, load_real, write_vehicle

        loaded = load_vehicle_with_sources(args.vehicle)
        cals = calibrate_airframes(loaded.config, load_real(loaded.config, root, log=lambda s: None))
        if args.out:
            for af, c in cals.items():
                write_vehicle(c, loaded.sources, Path(args.out) / f"crazyflie-{af}-calibrated.yaml")
        res = {af: c.to_dict() for af, c in cals.items()}
        if args.json:
            json.dump(res, sys.stdout, indent=2)
            print()
        else:
            for af, c in res.items():
                print(
                    f"{af}: cause {c['cause']} ({c['why']}); held-out RMS command error "
                    f"{c['holdout_rms_cmd']['nominal']} -> {c['holdout_rms_cmd']['calibrated']}"
                )
        return 0
    from offline.crazypad.experiment import run
    from offline.crazypad.simdata import Recipe

    out = Path(args.out)
    report = run(
        out, root, Path(args.vehicle), Recipe(flights_per_label=args.flights_per_label, seed=args.seed), epochs=args.epochs
    )
    if args.ship:
        ship(Path(report["models"]["calibrated"]), out / "crazypad-report.json")
    return 0


def ship(model: Path, report_json: Path) -> Path:
    """Copy the model to models/ with a manifest beside it (the experiment's report manifest)."""
    shutil.copyfile(model, SHIPPED_MODEL)
    manifest = json.loads(report_json.read_text(encoding="utf-8"))
    rep = manifest.pop("report")
    manifest["shipped"] = {
        "model": SHIPPED_MODEL.name,
        "variant": "calibrated (both airframes)",
        "table": rep["table"],
        "calibration": rep["calibration"],
        "split": rep["split"],
        "recipe": rep["recipe"],
        "features": rep["features"],
        "window_steps": rep["window_steps"],
    }
    from offline.crazypad.card import write_card
    from offline.manifest import write_manifest

    path = write_manifest(SHIPPED_MODEL.with_suffix(".manifest.json"), manifest)
    write_card(path)  # the card comes from the manifest, never by hand
    return path
