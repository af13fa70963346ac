"""``propwatch diagnose LOG [LOG...] [--json] [--report DIR]``.

Output with ``--json`` (stdout), for one LOG::

    {"log": PATH,
     "verdict": {"label": N, "faulty_propellers": [...], "fault_probability": [p1, p2, p3, p4]} | null,
     "windows": n, "warnings": [...], "reason": null | "why there is no verdict",
     "propellers": [{"propeller": 1, "name": "M1", "fault_probability": p, "faulty": bool}, ...],
     "label_probability": [16 values] | null,
     "airborne_segments": [{"start_boot_s", "stop_boot_s", "steps"}, ...],
     "timeline": {"t_boot_s": [...], "fault_probability": [[p1..p4], ...], "label": [...]},
     "hop_steps": k,
     "envelope": {"airborne_mean_rpm", "trained_mean_rpm", "rpm_ratio", "large_attitude_fraction"}}

For several LOGs: ``{"results": [one object as above per LOG, in order]}``;
a log that cannot be read appears as ``{"log": PATH, "error": "..."}``.
Propellers are in PX4 order; ``name`` is the vehicle's own numbering. Times are
seconds on the autopilot's boot clock; a timeline point is the end of its window.

Exit code: 0 every log got a verdict; 1 some log got no verdict (the reason
says why: outside the model's envelope, no airborne flight, ...); 2 some log
could not be read (unknown format, missing messages, damaged beyond reading,
larger or longer than ``--max-seconds`` allows, messages that stop advancing
time) or bad arguments. Whatever a reader raises ends in one of these codes.
With ``--json`` stdout holds only the JSON: anything a library prints while
reading goes to stderr (at most a few lines, then a count).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

from monitor.diagnose.engine import Diagnosis, diagnose_table
from monitor.errors import PropwatchError
from monitor.esc import EscCurve
from monitor.logs import read_raw, to_flight_table
from monitor.logs.guards import DEFAULT_MAX_SECONDS, check_size, check_time_advances
from monitor.model import Classifier, choose_esc
from monitor.vehicle import REPO_ROOT

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
    p.add_argument(
        "--max-seconds",
        type=float,
        default=DEFAULT_MAX_SECONDS,
        help=f"longest log accepted, in seconds of its own clock (default {DEFAULT_MAX_SECONDS:g} = 3 h); "
        "also bounds the file size read (1 MB per second)",
    )
    p.add_argument("--json", action="store_true", help="print JSON to stdout")
    p.add_argument("--report", metavar="DIR", default=None, help="write PNG + HTML reports into DIR")
    return p.parse_args(argv)


def diagnose_file(path: str, clf: Classifier, esc: EscCurve, fmt: str | None, hop: int, max_seconds: float = DEFAULT_MAX_SECONDS):
    check_size(path, max_seconds)
    raw = read_raw(path, fmt, extras=False)
    streams = {k: getattr(raw, k) for k in ("motor_cmd", "attitude_rad", "rates_rad_s")}
    check_time_advances(streams, path, max_seconds)
    table = to_flight_table(raw, esc=esc, rate_hz=clf.info.sample_rate_hz)
    return table, diagnose_table(table, clf, hop=hop, esc=esc)


class _PrintTrap(io.TextIOBase):
    """Stands in for stdout while logs are read: libraries' prints go to stderr, a few lines then a count."""

    KEEP = 5

    def __init__(self) -> None:
        self.lines = 0

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        for line in text.splitlines():
            if line.strip():
                self.lines += 1
                if self.lines <= self.KEEP:
                    print(f"propwatch diagnose: (reader) {line}", file=sys.stderr)
        return len(text)

    def report(self) -> None:
        if self.lines > self.KEEP:
            print(f"propwatch diagnose: (reader) ... {self.lines - self.KEEP} more line(s) not shown", file=sys.stderr)
        self.lines = 0


def format_text(d: Diagnosis) -> str:
    lines = [f"== {d.source}"]
    if d.verdict is None:
        lines.append(f"no verdict: {d.reason}")
    else:
        faulty = d.verdict["faulty_propellers"]
        lines.append(
            f"verdict: label {d.verdict['label']} ("
            + (
                "no faulty propeller"
                if not faulty
                else "faulty propeller(s) " + ", ".join(d.propellers[i - 1]["name"] for i in faulty)
            )
            + f"), from {d.windows} windows"
        )
        for p in d.propellers:
            lines.append(
                f"  propeller {p['propeller']} ({p['name']}): P(faulty) = {p['fault_probability']:.3f}"
                + ("  <- FAULTY" if p["faulty"] else "")
            )
    for s in d.segments:
        lines.append(f"  airborne {s['start_boot_s']:.1f}-{s['stop_boot_s']:.1f} s boot time ({s['steps']} steps)")
    lines += [f"  warning: {w}" for w in d.warnings]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.hop < 1:
        print("propwatch diagnose: --hop must be >= 1", file=sys.stderr)
        return 2
    if not 0 < args.max_seconds <= 7 * 86400:
        print("propwatch diagnose: --max-seconds must be in (0, 604800]", file=sys.stderr)
        return 2
    clf = Classifier(args.model or default_model(args.vehicle))
    # The daemon's rule, so both convert commands identically: --vehicle, else the model's own ESC curve.
    esc = choose_esc(clf, args.vehicle or "")
    results, code = [], 0
    trap = _PrintTrap()
    for path in args.logs:
        try:
            with contextlib.redirect_stdout(trap):
                table, d = diagnose_file(path, clf, esc, args.fmt, args.hop, args.max_seconds)
        except PropwatchError as exc:
            results.append({"log": path, "error": str(exc)})
            print(f"propwatch diagnose: error: {exc}", file=sys.stderr)
            code = 2
            continue
        except Exception as exc:  # noqa: BLE001 - a reader's own failure (struct.error, pymavlink's bare
            # exceptions, MemoryError...) on input it did not expect: still "could not be read", never a traceback.
            msg = f"{path}: cannot read: {type(exc).__name__}: {exc}"
            results.append({"log": path, "error": msg})
            print(f"propwatch diagnose: error: {msg}", file=sys.stderr)
            code = 2
            continue
        finally:
            trap.report()
        if d.verdict is None:
            code = max(code, 1)
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
