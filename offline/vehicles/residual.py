"""The simulation's residual before and after calibration, on held-out flights of each quirky airframe.

    python -m offline.vehicles.residual --fleet DIR [--cache out/localise/cal] [--json OUT.json]

Per airframe of a same-airframe fleet (``offline.vehicles.evaluate``): ``propwatch calibrate``'s fit on its first
2 healthy references; then, on the held-out third reference and on its healthy later flights (new payload, wind and
routes), the equation-error residual of ``offline.calibrate.physics.residuals`` (the same signals, filters and valid
samples as the fit), per signal RMS, with the nominal vehicle and with the calibrated one. "ratio" is the pooled RMS
of the calibrated model in units of the nominal's per-signal RMS (``offline.calibrate.fit.combined_rms``: 1 = no
change, below 1 better); "worse" lists the signals whose RMS rose by more than ``MAX_SIGNAL_WORSENING`` (the fit's
own consistency margin).

Beside it, the hover omega^2 shares the vehicle-memory judgement compares (``offline.vehicles.calibrated``): the RMS
error over the 4 rotors between each held-out flight's share intercept and the prediction of the nominal vehicle,
of the calibrated one, and of the 2 references' own mean (the history).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from monitor.memory.normal import normal_of
from monitor.vehicle import DEFAULT_VEHICLE, VehicleConfig, load_vehicle
from offline.calibrate.cli import read_measured
from offline.calibrate.fit import MAX_SIGNAL_WORSENING, combined_rms, rms_by_signal
from offline.calibrate.physics import residuals
from offline.calibrate.prepare import prepare
from offline.vehicles.calibrated import calibrated_vehicle, hover_shares
from offline.vehicles.evaluate import load_fleet
from offline.vehicles.localise import DEFAULT_CACHE

CALIBRATION_FLIGHTS = 2
SHOWN = ("roll_accel_rad_s2", "pitch_accel_rad_s2", "yaw_accel_rad_s2", "accel_d_m_s2")


def residual_rms(files: list[str], vehicles: dict[str, VehicleConfig], nominal: VehicleConfig) -> dict[str, dict[str, float]]:
    """{vehicle name: per-signal RMS} of the equation error over ``files``' airborne segments."""
    segs = prepare([t for f in files for t in read_measured(Path(f), None, nominal)], nominal)
    masks = [s.valid for s in segs]
    return {name: rms_by_signal([residuals(s, v) for s in segs], masks) for name, v in vehicles.items()}


def compare(rms: dict[str, dict[str, float]]) -> dict:
    before, after = rms["nominal"], rms["calibrated"]
    return {
        "nominal": before,
        "calibrated": after,
        "ratio": combined_rms(after, before),
        "worse": sorted(s for s in before if after[s] > MAX_SIGNAL_WORSENING * before[s]),
    }


def airframe(flights: list[dict], nominal: VehicleConfig, cache: Path | None) -> dict:
    refs = [f for f in flights if f["reference"]]
    fit, held = refs[:CALIBRATION_FLIGHTS], refs[CALIBRATION_FLIGHTS]
    later = [f for f in flights if not f["reference"] and not f["faulty"]]
    calibrated, result = calibrated_vehicle([f["file"] for f in fit], nominal, cache)
    vehicles = {"nominal": nominal, "calibrated": calibrated}
    history = normal_of([f["summary"] for f in fit])
    predicted = {
        "nominal": hover_shares(nominal, nominal.esc),
        "calibrated": hover_shares(calibrated, nominal.esc),
        "history": history.intercept,
    }
    share_error = {
        k: float(np.sqrt(np.mean([np.mean((history.intercept_of(f["summary"]) - p) ** 2) for f in [held] + later])))
        for k, p in predicted.items()
    }
    return {
        "calibrated_on": [f["name"] for f in fit],
        "named": result["named"],
        "params": result["params"],
        "held_out_reference": {"flight": held["name"], **compare(residual_rms([held["file"]], vehicles, nominal))},
        "healthy_later": {
            "flights": [f["name"] for f in later],
            **compare(residual_rms([f["file"] for f in later], vehicles, nominal)),
        },
        "share_error_rms": share_error,
    }


def format_table(per: dict[str, dict]) -> str:
    head = " | ".join(f"{s} nom -> cal" for s in SHOWN)
    lines = [
        f"| airframe | named (2 refs) | held-out ref: {head} | ratio | worse | later healthy: ratio | worse | "
        "hover share error x1e-3: nominal / calibrated / 2-flight history |",
        "|---" * (len(SHOWN) + 7) + "|",
    ]

    def row(name: str, r: dict) -> str:
        h, lt, se = r["held_out_reference"], r["healthy_later"], r["share_error_rms"]
        cells = " | ".join(f"{h['nominal'][s]:.3g} -> {h['calibrated'][s]:.3g}" for s in SHOWN)
        return (
            f"| {name} | {', '.join(r['named']) or '-'} | {cells} | {h['ratio']:.3f} | {', '.join(h['worse']) or '-'} | "
            f"{lt['ratio']:.3f} | {', '.join(lt['worse']) or '-'} | "
            f"{1e3 * se['nominal']:.1f} / {1e3 * se['calibrated']:.1f} / {1e3 * se['history']:.1f} |"
        )

    lines += [row(name, r) for name, r in per.items()]
    med = {
        "named": [],
        "held_out_reference": {
            "nominal": {s: float(np.median([r["held_out_reference"]["nominal"][s] for r in per.values()])) for s in SHOWN},
            "calibrated": {s: float(np.median([r["held_out_reference"]["calibrated"][s] for r in per.values()])) for s in SHOWN},
            "ratio": float(np.median([r["held_out_reference"]["ratio"] for r in per.values()])),
            "worse": [f"{sum(bool(r['held_out_reference']['worse']) for r in per.values())} of {len(per)} airframes"],
        },
        "healthy_later": {
            "ratio": float(np.median([r["healthy_later"]["ratio"] for r in per.values()])),
            "worse": [f"{sum(bool(r['healthy_later']['worse']) for r in per.values())} of {len(per)} airframes"],
        },
        "share_error_rms": {
            k: float(np.median([r["share_error_rms"][k] for r in per.values()])) for k in ("nominal", "calibrated", "history")
        },
    }
    lines.append(row("**median**", med))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m offline.vehicles.residual", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--fleet", required=True, type=Path, help="a same-airframe fleet folder (truth JSON beside each log)")
    p.add_argument("--cache", type=Path, default=DEFAULT_CACHE, help=f"calibrated vehicles cached here (default {DEFAULT_CACHE})")
    p.add_argument("--json", type=Path, default=None, help="write every airframe's per-signal RMS here")
    args = p.parse_args(argv)
    if not args.fleet.is_dir():
        print(f"python -m offline.vehicles.residual: --fleet {args.fleet}: not a folder", file=sys.stderr)
        return 2
    nominal = load_vehicle(DEFAULT_VEHICLE)
    per = {af: airframe(fl, nominal, args.cache) for af, fl in load_fleet(args.fleet).items()}
    print(f"{args.fleet}: {len(per)} airframes, calibrated on {CALIBRATION_FLIGHTS} references each")
    print(format_table(per))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(per, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
