"""``propwatch diagnose LOG [LOG...] [--json] [--report DIR]``.

Numbering, one for every output (text, HTML, PNG, JSON): propellers are in PX4
quad-X order (1 front-right CCW, 2 rear-left CCW, 3 front-left CW, 4 rear-right
CW); ``label`` is 1..16 over PX4 rotor sets (1 none, 2-5 rotor 1..4 alone, 6-11
pairs, 12-15 triples, 16 all; monitor/labels.py). Each rotor is shown by the
vehicle's own name with its PX4 number beside it, e.g. CrazyPAD's
``M3 (PX4 rotor 2)``.

Output with ``--json`` (stdout), for one LOG (every key: docs/diagnose-json.md)::

    {"log": PATH,
     "verdict": {"label": N, "faulty_propellers": [PX4 numbers], "faulty_names": [...],
                 "fault_probability": [p1, p2, p3, p4],
                 "confidence": "confident" | "ambiguous" | "suspect" | "uncertain",
                 "label_probability_of_verdict": p,
                 "agreeing_windows": share, "faulty_probability_required": 0.9} | null,
     "windows": n, "warnings": [...], "reason": null | "why there is no verdict",
     "propellers": [{"propeller": 1, "px4_rotor": 1, "name": "M1", "fault_probability": p, "faulty": bool,
                     "suspect": bool}, ...],
     "label_probability": [16 values] | null,
     "airborne_segments": [{"start_boot_s", "stop_boot_s", "steps"}, ...],
     "timeline": {"t_boot_s": [...], "fault_probability": [[p1..p4], ...], "label": [...]},
     "hop_steps": k,
     "envelope": {"airborne_mean_rpm", "trained_mean_rpm", "rpm_ratio", "rpm_z", "large_attitude_fraction"},
     "decision": {"alerts": [{"t_boot_s", "level": "suspect" | "fault", "propellers", "text"}, ...],
                  "final": {...}},
     "hypotheses": [{"faulty_propellers": [...], "probability": p}, ...] | null,
     "hypothesis_rule": {"score", "threshold", "coverage", "calibration_flights"} | null,
     "rotor_effectiveness": [4 values] | null, "rotor_effectiveness_std": [4 values] | null,
     "baseline": {"basis", "shares", "deviation_spreads", "rotors_beyond_3_spreads", "t_spreads_required",
                  "rotors_beyond_t_spreads", "verdict",
                  "fusion": {"rule", "classifier_label", "classifier_confidence", "spreads_required"}}}
                  (--vehicle DIR only; there ``verdict`` is the classifier fused with the airframe's baseline,
                  monitor.baseline.fuse: a rotor beyond 3 healthy spreads is named, none is healthy unless
                  the classifier alone is confident; where the baseline says a CG offset and damage look alike
                  (cg_damage_separable false) a fault becomes an imbalance: "imbalance_rotors",
                  "imbalance_names" in ``verdict``, no faulty propeller, both causes in ``hypotheses``)

Confidence: a model shipped with a conformal rule (``classifier.sets.json``,
monitor/decision/hypotheses.py) gives a set of hypotheses: every propeller set whose
score (the classifier's mean label probability times the moment balance's
likelihood) reaches the threshold that held the truth in 95 % of randomised
calibration flights. One set: ``confident``, its propellers FAULTY. More:
``ambiguous`` (physics cannot tell them apart), the most probable set's
propellers only ``suspect``. A model without a rule is ``confident`` when the
label's mean probability is >= 0.9, else ``suspect`` (at least half the
windows agree on its label) or ``uncertain``. ``decision`` is the onboard daemon's own rule (monitor.decision: a
CUSUM whose thresholds follow alerts.false_alarms_per_hour) replayed over the
log: when in the flight it would have said suspect / fault, on which propeller. Where it reached fault level,
the verdict is its answer (``verdict.source`` "in-flight change", ``verdict.change_boot_s``; the whole flight's
verdict in ``verdict.whole_flight``): a propeller damaged mid-flight is outvoted in a whole-flight mean by the
healthy part before it, while the rule tests the flight against its own start.

For several LOGs: ``{"results": [one object as above per LOG, in order]}``;
a log that cannot be read appears as ``{"log": PATH, "error": "..."}``.
Times are seconds on the autopilot's boot clock; a timeline point is the end of
its window. Floats are rounded to 6 decimals.

Exit code: 0 every log got a confident verdict; 3 some log got a verdict that
is not confident (ambiguous, suspect or uncertain: no confident verdict); 1 some log got
no verdict at all (the reason says why: outside the model's envelope, no
airborne flight, ...); 2 some log could not be read (unknown format, missing
messages, damaged beyond reading, larger or longer than ``--max-seconds``
allows, messages that stop advancing time) or bad arguments. The highest
applies: 2 > 1 > 3 > 0. Whatever a reader raises ends in one of these codes.
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

from monitor.decision.rotor_share import BASELINE_S
from monitor.diagnose.engine import Diagnosis, diagnose_table, name_verdict, round_floats
from monitor.diagnose.memory import judge_flight, log_vehicle_id
from monitor.diagnose.verdict import POSITION, flight_seconds, set_words, verdict_of
from monitor.errors import PropwatchError
from monitor.esc import EscCurve
from monitor.logs import read_raw, to_flight_table
from monitor.logs.guards import DEFAULT_MAX_SECONDS, check_size, check_time_advances
from monitor.memory.baseline import VehicleBaseline, is_vehicle_baseline
from monitor.model import Classifier, choose_esc
from monitor.progress import bar
from monitor.resources import shipped
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

DEFAULT_MODEL = shipped("classifier.onnx")
BIG_LOG_BYTES = 1_000_000  # a single log this large takes seconds to read: show a bar


def default_model(vehicle_yaml: str | None) -> Path:
    """The classifier shipped for a vehicle: ``models/NAME-classifier.onnx`` beside ``NAME.yaml``.

    A vehicle with its own shipped model (the Crazyflie) gets it without
    ``--model``; any other vehicle gets the paper quad's classifier, whose
    envelope checks then say whether the log fits it.
    """
    if vehicle_yaml:
        own = shipped(f"{Path(vehicle_yaml).stem}-classifier.onnx")
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
        "(default: the model's metadata vehicle.esc, else the paper's fit = models/vehicle.yaml), or a "
        "`propwatch adapt` output folder: its vehicle.yaml, classifier.onnx and healthy baseline",
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
    p.add_argument(
        "--baseline",
        metavar="B.json",
        default=None,
        help="judge each log against this vehicle's healthy history (propwatch baseline learn); wins over --vehicle DIR's",
    )
    p.add_argument("--json", action="store_true", help="print JSON to stdout")
    p.add_argument(
        "--report",
        metavar="DIR",
        default=None,
        help="write a PNG + HTML report per log into DIR (their paths are printed on stderr)",
    )
    return p.parse_args(argv)


def diagnose_file(
    path: str, clf: Classifier, esc: EscCurve, fmt: str | None, hop: int, vehicle=None, max_seconds: float = DEFAULT_MAX_SECONDS
):
    check_size(path, max_seconds)
    raw = read_raw(path, fmt, extras=False)
    streams = {k: getattr(raw, k) for k in ("motor_cmd", "attitude_rad", "rates_rad_s")}
    check_time_advances(streams, path, max_seconds)
    table = to_flight_table(raw, esc=esc, rate_hz=clf.info.sample_rate_hz)
    return table, diagnose_table(table, clf, hop=hop, esc=esc, vehicle=vehicle)


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


STATUS_WORD = {"replace": "REPLACE", "inspect": "INSPECT", "ok": "ok"}


def format_text(d: Diagnosis, baseline=None, result: dict | None = None) -> str:
    """The verdict in a pilot's words (``render_text``). ``result``: the ``--json`` object when the caller has it
    (with ``baseline``), else ``d.to_json()``; ``baseline`` is no longer read (the fused verdict is in ``d``)."""
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
    return "\n".join(lines)


def fuse_verdict(d: Diagnosis, comparison: dict, motor_names, cg_damage_separable: bool | None = None) -> None:
    """Replace the classifier's verdict by the fusion with the airframe's healthy baseline (``monitor.baseline.fuse``).

    Adds ``comparison["fusion"]`` (the rule that decided and what the classifier alone said). Nothing changes
    where there is no verdict or the baseline was not compared (another basis). Where the airframe's flights
    were measured not to tell a CG offset from damage (``cg_damage_separable`` False), a fault verdict becomes
    an ambiguous imbalance with both explanations as hypotheses (``monitor.baseline.cg_or_damage``).
    """
    from monitor.baseline import OUTLIER_SPREADS, cg_or_damage, fuse
    from monitor.labels import LABEL_TABLE

    if d.verdict is None or d.label_probability is None or "deviation_spreads" not in comparison:
        return
    v = d.verdict
    if v.get("source") == "in-flight change":
        # The flight against its own start already answers; the whole-flight shares against the airframe's
        # healthy flights mix the time before the change in. Where this airframe's flights do not tell a CG
        # offset from damage, a change is worded as an imbalance all the same (a mass that shifted in flight).
        comparison["fusion"] = {
            "rule": "in-flight change: the in-flight rule's verdict stands (baseline not fused)",
            "classifier_label": v["whole_flight"]["label"],
            "classifier_confidence": v["whole_flight"]["confidence"],
            "spreads_required": OUTLIER_SPREADS,
        }
        label = v["label"]
    else:
        f = fuse(comparison["deviation_spreads"], d.label_probability, v["label"], v.get("confidence") == "confident")
        comparison["fusion"] = {
            "rule": f["rule"],
            "classifier_label": v["label"],
            "classifier_confidence": v.get("confidence"),
            "spreads_required": OUTLIER_SPREADS,
        }
        label = f["label"]
        name_verdict(d, label, f["confidence"], motor_names)
    if cg_damage_separable is False and LABEL_TABLE[label]:
        imb = cg_or_damage(label, motor_names)
        d.hypotheses, d.hypothesis_rule = imb.pop("hypotheses"), None
        name_verdict(d, imb["label"], imb["confidence"], motor_names)
        v.update(imb)
        comparison["fusion"]["rule"] += "; CG offset and damage look alike on this airframe: an imbalance, no fault named"
        for p in d.propellers:
            p["suspect"] = p["propeller"] in imb["imbalance_rotors"]


def memory_text(b: dict) -> str:
    """The vehicle-memory comparison in two lines: what the flight was compared with, and what it showed."""
    if "deviation_sigma" not in b:
        return f"  vehicle memory: {b['compared_with_text']}: {b['note']}"
    dev = ", ".join(f"{i + 1}: {x:+.1f}" for i, x in enumerate(b["deviation_sigma"]))
    return f"  vehicle memory: {b['compared_with_text']}\n    each rotor's share against its normal (spreads) {dev}; {b['rule']}"


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
    baseline = memory = None
    if args.vehicle and Path(args.vehicle).is_dir():
        # A `propwatch adapt` folder: its calibrated vehicle, its model, its airframe's healthy baseline.
        from monitor.baseline import BASELINE_FILE, HealthyBaseline

        folder = Path(args.vehicle)
        args.vehicle = str(folder / "vehicle.yaml")
        args.model = args.model or str(folder / "classifier.onnx")
        if is_vehicle_baseline(folder / BASELINE_FILE):
            memory = VehicleBaseline.load(folder / BASELINE_FILE)
        else:  # an adapt folder written before vehicle memory: its fused classifier-and-shares baseline
            baseline = HealthyBaseline.load(folder / BASELINE_FILE)
    if args.baseline:
        try:
            memory, baseline = VehicleBaseline.load(args.baseline), None
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
                table, d = diagnose_file(path, clf, esc, args.fmt, args.hop, vehicle, args.max_seconds)
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
        if baseline is not None:
            res_baseline = baseline.compare(table)
            fuse_verdict(d, res_baseline, table.motor_names, baseline.cg_damage_separable)
        if memory is not None:
            try:
                res_baseline = judge_flight(d, table, memory, log_vehicle_id(path, args.fmt))
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
            print(format_text(d, baseline, res))
            if baseline is not None and "deviation_spreads" in res["baseline"]:
                b = res["baseline"]
                print(
                    "  vs this airframe's healthy baseline (spreads): "
                    + ", ".join(f"{x:+.1f}" for x in b["deviation_spreads"])
                    + f" -> {b['verdict']}"
                )
            if memory is not None:
                print(memory_text(res["baseline"]))
            if baseline is not None and "fusion" in res["baseline"]:
                f = res["baseline"]["fusion"]
                print(f"  verdict from the baseline and the classifier (label {f['classifier_label']} alone): {f['rule']}")
    if progress is not None:
        progress.close()
    if args.json:
        out = results[0] if len(results) == 1 else {"results": results}
        json.dump(round_floats(out), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    return code


if __name__ == "__main__":
    sys.exit(main())
