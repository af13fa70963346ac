"""``propwatch calibrate MEASURED [MEASURED...] --vehicle models/vehicle.yaml [--json] [--out calibrated.yaml] [--report DIR]``

Reads measured flights in any format diagnose reads (--format for CSV
mappings), plus the simulator's .npz; fits the candidate model terms and
names the cause; writes the calibrated vehicle and a report with plots.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from monitor.flight import FlightTable
from monitor.logs import read_log
from monitor.vehicle import DEFAULT_VEHICLE, VehicleConfig, load_vehicle_with_sources
from offline.calibrate.terms import TERMS


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="propwatch calibrate", description=__doc__.split("\n\n")[1].replace("\n", " "))
    p.add_argument("measured", nargs="+", type=Path, help="measured flight logs (.tlog, .ulg, DataFlash .bin, CSV, sim .npz)")
    p.add_argument("--vehicle", type=Path, default=DEFAULT_VEHICLE, help="nominal vehicle YAML (default models/vehicle.yaml)")
    p.add_argument("--format", default=None, help="log format or CSV mapping name (default: detect)")
    p.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    p.add_argument("--out", type=Path, default=None, help="write the calibrated vehicle YAML here")
    p.add_argument("--report", type=Path, default=None, help="write plots and tables into this directory")
    p.add_argument("--terms", default=",".join(TERMS), help=f"candidate terms, comma-separated (default all: {','.join(TERMS)})")
    return p.parse_args(argv)


def read_measured(path: Path, fmt: str | None, vehicle: VehicleConfig) -> list[FlightTable]:
    if path.suffix == ".npz" and fmt is None:
        from offline.sim.io_npz import read_npz

        log, _ = read_npz(path)
        return [log.to_flight_table(i, source=f"{path}[{i}]") for i in range(len(log))]
    return [read_log(path, fmt, esc=vehicle.esc)]


def summary(r) -> str:
    """Plain-text summary of an ``offline.calibrate.calibrate.CalibrationResult``."""
    lines = [
        f"cause: {r.cause or 'none (no discrepancy stands out above the noise)'}"
        + (f"  (confidence {r.confidence:.3f})" if r.cause else "")
    ]
    for f in r.findings:
        params = ", ".join(f"{k}={v:.4g}±{f['std'][k]:.2g}" for k, v in f["params"].items())
        lines.append(
            f"  {f['effect']}: {params}; held-out residual {f['residual_rms_before']:.4g} -> "
            f"{f['residual_rms_after']:.4g}; BIC gain {f['score']:.1f}"
        )
    lines.append("candidates (first round; every verdict with the gate that decided it):")
    for n, c in sorted(r.candidates.items(), key=lambda kv: -kv[1]["verdict"]["heldout_bic_gain"]):
        v = c["verdict"]
        lines.append(f"  {n}: {'named' if v['named'] else 'not named'} [{v['decided_by']}] {v['why']}")
    lines += [f"note: {n}" for n in r.notes]
    g = r.gain
    lines.append(
        f"gain: held-out residual RMS {g['heldout_residual_rms_before']:.4g} -> {g['heldout_residual_rms_after']:.4g} "
        f"({g['heldout_residual_reduction_pct']:.1f} % lower); steady-state command error "
        f"{g['steady_state_cmd_error_rms_before']} -> {g['steady_state_cmd_error_rms_after']}"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    loaded = load_vehicle_with_sources(args.vehicle)
    terms = [t.strip() for t in args.terms.split(",") if t.strip()]
    unknown = [t for t in terms if t not in TERMS]
    if unknown:
        print(f"propwatch calibrate: unknown term(s) {', '.join(unknown)} (known: {', '.join(TERMS)})", file=sys.stderr)
        return 2
    tables = [t for p in args.measured for t in read_measured(p, args.format, loaded.config)]
    from offline.calibrate.calibrate import calibrate_vehicle  # scipy: only once there is work to do

    result = calibrate_vehicle(tables, loaded.config, terms)
    if args.out:
        from offline.calibrate.writer import write_calibrated

        write_calibrated(args.out, result, loaded.sources, str(args.vehicle))
    if args.report:
        from offline.calibrate.report import write_report

        write_report(args.report, result)
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
    else:
        print(summary(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
