"""``propwatch diagnose LOG [LOG...] [--json] [--report DIR]``.

Output with ``--json`` (stdout), for one LOG::

    {"log": PATH,
     "verdict": {"label": N, "faulty_propellers": [...], "fault_probability": [p1, p2, p3, p4],
                 "confidence": "confident" | "suspect" | "uncertain", "label_probability_of_verdict": p,
                 "agreeing_windows": share, "faulty_probability_required": 0.9} | null,
     "windows": n, "warnings": [...], "reason": null | "why there is no verdict",
     "propellers": [{"propeller": 1, "name": "M1", "fault_probability": p, "faulty": bool, "suspect": bool}, ...],
     "label_probability": [16 values] | null,
     "airborne_segments": [{"start_boot_s", "stop_boot_s", "steps"}, ...],
     "timeline": {"t_boot_s": [...], "fault_probability": [[p1..p4], ...], "label": [...]},
     "hop_steps": k,
     "envelope": {"airborne_mean_rpm", "trained_mean_rpm", "rpm_ratio", "large_attitude_fraction"},
     "decision": {"alerts": [{"t_boot_s", "level": "suspect" | "fault", "propellers", "text"}, ...],
                  "final": {...}}}

Confidence: a propeller is FAULTY only when the verdict's label has mean
probability >= 0.9 over the windows (``confident``); below that the verdict
is ``suspect`` (at least half the windows agree on its label) or
``uncertain``, and says the label probability and the share of windows that
agree. ``decision`` is the onboard daemon's own rule (monitor.decision: a
CUSUM whose thresholds follow alerts.false_alarms_per_hour) replayed over the
log: when in the flight it would have said suspect / fault, on which propeller.

For several LOGs: ``{"results": [one object as above per LOG, in order]}``;
a log that cannot be read appears as ``{"log": PATH, "error": "..."}``.
Propellers are in PX4 order; ``name`` is the vehicle's own numbering. Times are
seconds on the autopilot's boot clock; a timeline point is the end of its window.

Exit code: 0 every log got a confident verdict; 3 some log got a verdict that
is not confident (suspect or uncertain: no confident verdict); 1 some log got
no verdict at all (the reason says why: outside the model's envelope, no
airborne flight, ...); 2 some log could not be read (unknown format, missing
messages) or bad arguments. The highest applies: 2 > 1 > 3 > 0.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from monitor.diagnose.engine import Diagnosis, diagnose_table
from monitor.errors import PropwatchError
from monitor.esc import EscCurve
from monitor.logs import read_log
from monitor.model import Classifier, choose_esc
from monitor.vehicle import DEFAULT_VEHICLE, REPO_ROOT, load_vehicle

DEFAULT_MODEL = REPO_ROOT / "models" / "classifier.onnx"


def default_model(vehicle_yaml: str | None) -> Path:
    """The classifier shipped for a vehicle: ``models/NAME-classifier.onnx`` beside ``NAME.yaml``.

    A vehicle with its own shipped model (the Crazyflie) gets it without
    ``--model``; any other vehicle gets the paper quad's classifier, whose
    envelope checks then say whether the log fits it.
    """
    if vehicle_yaml:
        own = REPO_ROOT / "models" / f"{Path(vehicle_yaml).stem}-classifier.onnx"
        if own.is_file():
            return own
    return DEFAULT_MODEL


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="propwatch diagnose", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("logs", nargs="+", metavar="LOG", help=".tlog, .ulg, DataFlash .bin, or CSV (with --format)")
    p.add_argument(
        "--format",
        dest="fmt",
        default=None,
        help="log format: tlog, ulog, dataflash, or a CSV mapping name from monitor/formats.yaml (e.g. crazypad)",
    )
    p.add_argument(
        "--model",
        default=None,
        help="classifier ONNX file (default: models/NAME-classifier.onnx for --vehicle .../NAME.yaml when "
        "that file exists, else models/classifier.onnx)",
    )
    p.add_argument(
        "--vehicle",
        default=None,
        help="vehicle YAML whose ESC curve converts motor commands to RPM "
        "(default: the model's metadata vehicle.esc, else the paper's fit = models/vehicle.yaml)",
    )
    # Windows are 5 s long; at a 1 s hop consecutive ones share 4 s: a finer hop costs
    # inference time without adding information to a post-flight verdict.
    p.add_argument("--hop", type=int, default=20, help="classify one window every HOP grid steps (default 20 = 1 s)")
    p.add_argument("--json", action="store_true", help="print JSON to stdout")
    p.add_argument("--report", metavar="DIR", default=None, help="write PNG + HTML reports into DIR")
    return p.parse_args(argv)


def diagnose_file(path: str, clf: Classifier, esc: EscCurve, fmt: str | None, hop: int, vehicle=None):
    table = read_log(path, fmt=fmt, esc=esc, rate_hz=clf.info.sample_rate_hz, extras=False)
    return table, diagnose_table(table, clf, hop=hop, esc=esc, vehicle=vehicle)


def format_text(d: Diagnosis) -> str:
    lines = [f"== {d.source}"]
    if d.verdict is None:
        lines.append(f"no verdict: {d.reason}")
    else:
        faulty = d.verdict["faulty_propellers"]
        conf = d.verdict.get("confidence", "confident")
        lines.append(
            f"verdict: label {d.verdict['label']} ("
            + (
                "no faulty propeller"
                if not faulty
                else "faulty propeller(s) " + ", ".join(d.propellers[i - 1]["name"] for i in faulty)
            )
            + f"), from {d.windows} windows: {conf} (label probability "
            + f"{d.verdict.get('label_probability_of_verdict', float('nan')):.2f}, "
            + f"{100 * d.verdict.get('agreeing_windows', float('nan')):.0f} % of windows agree; marked FAULTY from "
            + f"{d.verdict.get('faulty_probability_required', float('nan')):.2f})"
        )
        for p in d.propellers:
            lines.append(
                f"  propeller {p['propeller']} ({p['name']}): P(faulty) = {p['fault_probability']:.3f}"
                + ("  <- FAULTY" if p["faulty"] else "  <- suspect" if p.get("suspect") else "")
            )
    if d.decision is not None:
        alerts = d.decision["alerts"]
        lines.append(
            "  in-flight rule: " + ("; ".join(f"{a['text']} at {a['t_boot_s']:.1f} s" for a in alerts) if alerts else "no alert")
        )
    if d.physics is not None:
        names = [p["name"] for p in d.propellers]
        eff = ", ".join(
            f"{n} {m:.2f}±{s:.2f}" for n, m, s in zip(names, d.physics.rotor_effectiveness, d.physics.rotor_effectiveness_std)
        )
        lines.append(f"  rotor effectiveness (fraction of nominal thrust, moment balance over {d.physics.windows} x 5 s): {eff}")
        sets = " or ".join(
            ("{" + ",".join(names[i - 1] for i in h["faulty_propellers"]) + "}" if h["faulty_propellers"] else "healthy")
            + f" p={h['probability']:.2f}"
            for h in d.physics.hypotheses
        )
        lines.append(("  physics cannot tell apart: " if d.physics.ambiguous else "  physics: ") + sets)
    for s in d.segments:
        lines.append(f"  airborne {s['start_boot_s']:.1f}-{s['stop_boot_s']:.1f} s boot time ({s['steps']} steps)")
    lines += [f"  warning: {w}" for w in d.warnings]
    return "\n".join(lines)


EXIT_NOT_CONFIDENT = 3
_EXIT_RANK = {0: 0, EXIT_NOT_CONFIDENT: 1, 1: 2, 2: 3}


def worse(a: int, b: int) -> int:
    """The exit code that says more is wrong: 2 > 1 > 3 > 0."""
    return a if _EXIT_RANK[a] >= _EXIT_RANK[b] else b


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.hop < 1:
        print("propwatch diagnose: --hop must be >= 1", file=sys.stderr)
        return 2
    clf = Classifier(args.model or default_model(args.vehicle))
    # The daemon's rule, so both convert commands identically: --vehicle, else the model's own ESC curve.
    esc = choose_esc(clf, args.vehicle or "")
    vehicle = load_vehicle(args.vehicle or DEFAULT_VEHICLE)  # geometry for the moment-balance evidence
    results, code = [], 0
    for path in args.logs:
        try:
            table, d = diagnose_file(path, clf, esc, args.fmt, args.hop, vehicle)
        except PropwatchError as exc:
            results.append({"log": path, "error": str(exc)})
            print(f"propwatch diagnose: error: {exc}", file=sys.stderr)
            code = worse(code, 2)
            continue
        if d.verdict is None:
            code = worse(code, 1)
        elif d.verdict.get("confidence") != "confident":
            code = worse(code, EXIT_NOT_CONFIDENT)
        if args.report:
            from monitor.diagnose.report import write_report

            write_report(d, table, Path(args.report))
        results.append(d.to_json())
        if not args.json:
            print(format_text(d))
    if args.json:
        out = results[0] if len(results) == 1 else {"results": results}
        json.dump(out, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    return code


if __name__ == "__main__":
    sys.exit(main())
