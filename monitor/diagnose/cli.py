"""Diagnose flight logs: which propeller is damaged, how sure, and what to do next.

Exit 0 confident, 3 not sure, 1 no verdict, 2 unreadable. More: docs/diagnose-json.md.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import textwrap
from pathlib import Path

from monitor.decision.rotor_share import BASELINE_S
from monitor.diagnose.engine import Diagnosis, default_model, diagnose_file, round_floats
from monitor.diagnose.memory_adapter import judge_flight, log_date, log_vehicle_id
from monitor.diagnose.verdict import POSITION, flight_seconds, set_words, verdict_of
from monitor.errors import PropwatchError
from monitor.logs.guards import DEFAULT_MAX_SECONDS
from monitor.memory.baseline import BASELINE_FILE, VehicleBaseline, is_vehicle_baseline
from monitor.model import Classifier, choose_esc
from monitor.progress import bar
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

BIG_LOG_BYTES = 1_000_000  # a single log this large takes seconds to read: show a bar


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="propwatch diagnose", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("logs", nargs="+", metavar="LOG", help=".tlog, .ulg, DataFlash .bin, or CSV with --format")
    p.add_argument(
        "--format",
        dest="fmt",
        default=None,
        help="tlog, ulog, dataflash, or a CSV mapping (e.g. crazypad)",
    )
    p.add_argument(
        "--model",
        default=None,
        metavar="ONNX",
        help="classifier (default: the vehicle's own, else the paper quad's)",
    )
    p.add_argument(
        "--vehicle",
        default=None,
        metavar="YAML|DIR",
        help="vehicle YAML (ESC curve), or a folder written by propwatch adapt (with --model, it declares the "
        "airframe: without either, physics judges alone)",
    )
    # Windows are 5 s long; at a 1 s hop consecutive ones share 4 s: a finer hop costs
    # inference time without adding information to a post-flight verdict.
    p.add_argument("--hop", type=int, default=20, help="one 5-s stretch every HOP x 50 ms (default 20)")
    p.add_argument(
        "--max-seconds",
        type=float,
        default=DEFAULT_MAX_SECONDS,
        metavar="S",
        help=f"longest log accepted in s (default {DEFAULT_MAX_SECONDS:g})",
    )
    p.add_argument(
        "--baseline",
        metavar="B.json",
        default=None,
        help="compare with this vehicle's healthy flights",
    )
    p.add_argument("--json", action="store_true", help="print JSON (for programs) to stdout")
    p.add_argument(
        "--report",
        metavar="DIR",
        default=None,
        help="write a picture (PNG) and page (HTML) per log into DIR",
    )
    return p.parse_args(argv)


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


def _sets_text(hypotheses: list[dict], names: list[str]) -> str:
    """Hypothesis sets in plain words with their probabilities: ``propeller 3 (front-left) 99 % or propellers
    1+2+3 1 %``."""
    return " or ".join(
        set_words(h["faulty_propellers"], names) + (f" {100 * h['probability']:.0f} %" if "probability" in h else "")
        for h in hypotheses
    )


def in_flight_summary(decision: dict) -> str:
    """The in-flight rule's alerts, or what its silence means: "no alert" only after the omega^2 shares were tested
    against the flight's learnt baseline; before that (a log shorter than its 10 s of baseline, or held throughout)
    the rule has no verdict either way."""
    alerts = decision["alerts"]
    if alerts:
        return "; ".join(f"{a['text']} at {a['t_boot_s']:.1f} s" for a in alerts)
    final = decision["final"]
    tested = final.get("tested_s", 0.0)
    if tested > 0:
        return f"no alert ({tested:.1f} s of flight tested against its baseline)"
    return (
        f"no verdict: no window got past the flight's {BASELINE_S:.0f}-s baseline "
        f"({final['windows']} windows, {final['held_windows']} held)"
    )


STATUS_WORD = {"replace": "REPLACE", "inspect": "INSPECT", "ok": "ok", "not judged": "not judged"}
TEXT_WIDTH = 110  # a long sentence continues on the next line, indented four spaces


def format_text(d: Diagnosis, result: dict | None = None) -> str:
    """The verdict in a pilot's words (``render_text``). ``result``: the ``--json`` object when the caller has it
    (with its ``baseline``), else ``d.to_json()``."""
    return render_text(result if result is not None else d.to_json())


def render_text(result: dict) -> str:
    """One diagnosis (a ``--json`` object) as text, from its ``Verdict`` (``monitor.diagnose.verdict``): headline,
    next step, why, evidence, per-propeller status. Label numbers, windows and the set rule stay in ``--json``."""
    v = verdict_of(result)
    lines = [f"== {result['log']}", v.headline]
    if v.why:
        lines.append(f"  why not sure: {v.why}")
    lines.append(f"  next step: {v.next_step}")
    if v.compared_with:
        lines.append(f"  compared {v.compared_with}")
    if v.state not in ("no verdict", "unreadable"):
        lines.append(
            "  propellers: " + ", ".join(f"{v.names[i - 1]} {POSITION[i]} {STATUS_WORD[v.status(i)]}" for i in range(1, 5))
        )
    lines += [f"  evidence: {e}" for e in v.evidence]
    hyps = result.get("hypotheses")
    if len(v.sets) > 1 and hyps:
        lines.append("  possible: " + _sets_text(hyps, list(v.names)))
    for s in result.get("airborne_segments") or []:
        a, b = flight_seconds(s["start_boot_s"], v.takeoff_boot_s), flight_seconds(s["stop_boot_s"], v.takeoff_boot_s)
        lines.append(f"  airborne {a:.0f}-{b:.0f} s after take-off ({b - a:.0f} s)")
    lines += [f"  warning: {w}" for w in result.get("warnings") or []]
    return "\n".join(textwrap.fill(ln, TEXT_WIDTH, subsequent_indent="    ", break_on_hyphens=False) for ln in lines)


def memory_text(b: dict, names=("1", "2", "3", "4")) -> str:
    """The vehicle-memory comparison in two lines, rotors by the vehicle's own names: what the flight was compared
    with (and what does not tie the log to it), and what it showed."""
    caveats = "".join(f"\n    caveat: {c}" for c in b.get("caveats") or ())
    if "deviation_sigma" not in b:
        return f"  vehicle memory: {b['compared_with_text']}: {b['note']}{caveats}"
    dev = ", ".join(f"{names[i]}: {x:+.1f}" for i, x in enumerate(b["deviation_sigma"]))
    return (
        f"  vehicle memory: {b['compared_with_text']}{caveats}\n"
        f"    each rotor's share against its normal (spreads) {dev}; {b['rule']}"
    )


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
    if not 0 < args.max_seconds <= 7 * 86400:
        print("propwatch diagnose: --max-seconds must be in (0, 604800]", file=sys.stderr)
        return 2
    memory = None
    declared = bool(args.vehicle or args.model)  # the log is said to be of the model's airframe: the network may speak
    if args.vehicle and Path(args.vehicle).is_dir():
        # A `propwatch adapt` folder: its calibrated vehicle, its model, its airframe's healthy baseline.

        folder = Path(args.vehicle)
        args.vehicle = str(folder / "vehicle.yaml")
        args.model = args.model or str(folder / "classifier.onnx")
        if not is_vehicle_baseline(folder / BASELINE_FILE):
            print(
                f"propwatch diagnose: error: {folder / BASELINE_FILE}: an adapt baseline from before vehicle memory "
                "(no 'format'): run propwatch adapt again, or propwatch baseline learn on the vehicle's healthy logs",
                file=sys.stderr,
            )
            return 2
        memory = VehicleBaseline.load(folder / BASELINE_FILE)
    if args.baseline:
        try:
            memory = VehicleBaseline.load(args.baseline)
        except PropwatchError as exc:
            print(f"propwatch diagnose: error: {exc}", file=sys.stderr)
            return 2
    clf = Classifier(args.model or default_model(args.vehicle))
    # The daemon's rule, so both convert commands identically: --vehicle, else the model's own ESC curve.
    esc = choose_esc(clf, args.vehicle or "")
    vehicle = load_vehicle(args.vehicle or DEFAULT_VEHICLE)  # geometry for the moment-balance evidence
    results, code = [], 0
    # Several or long logs: a bar in bytes read (rate and ETA), on a terminal only; reading dominates the time.
    sizes = [Path(p).stat().st_size if Path(p).is_file() else 0 for p in args.logs]
    progress = bar(sum(sizes), "B", "diagnose", unit_scale=True) if len(args.logs) > 1 or sum(sizes) > BIG_LOG_BYTES else None
    trap = _PrintTrap()
    for path, size in zip(args.logs, sizes):
        if progress is not None:
            progress.set_postfix_str(Path(path).name)
        try:
            with contextlib.redirect_stdout(trap):
                table, d = diagnose_file(path, clf, esc, args.fmt, args.hop, vehicle, args.max_seconds, declared)
        except PropwatchError as exc:
            results.append({"log": path, "error": str(exc)})
            print(f"propwatch diagnose: error: {exc}", file=sys.stderr)
            code = worse(code, 2)
            if progress is not None:
                progress.update(size)
            continue
        except Exception as exc:  # noqa: BLE001 - a reader's own failure (struct.error, pymavlink's bare
            # exceptions, MemoryError...) on input it did not expect: still "could not be read", never a traceback.
            msg = f"{path}: cannot read: {type(exc).__name__}: {exc}"
            results.append({"log": path, "error": msg})
            print(f"propwatch diagnose: error: {msg}", file=sys.stderr)
            code = worse(code, 2)
            continue
        finally:
            trap.report()
        res_baseline = None
        if memory is not None:
            try:
                res_baseline = judge_flight(d, table, memory, log_vehicle_id(path, args.fmt), log_date(path, args.fmt, table))
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

            page = write_report(d, table, Path(args.report), d.to_json() | {"baseline": res_baseline})
            print(f"report: {page} and {page.with_suffix('.png')}", file=sys.stderr)
        res = d.to_json()
        if res_baseline is not None:
            res["baseline"] = res_baseline
        res["summary"] = verdict_of(res).to_json()  # what every rendering states (monitor.diagnose.verdict)
        results.append(res)
        if progress is not None:
            progress.update(size)
        if not args.json:
            print(format_text(d, res))
            if memory is not None:
                print(memory_text(res["baseline"], [p["name"] for p in res.get("propellers") or []] or ("1", "2", "3", "4")))
    if progress is not None:
        progress.close()
    if args.json:
        out = results[0] if len(results) == 1 else {"results": results}
        sys.stdout.write(json.dumps(round_floats(out), allow_nan=False))  # one shot: the C encoder, same text
        sys.stdout.write("\n")
    return code


if __name__ == "__main__":
    sys.exit(main())
