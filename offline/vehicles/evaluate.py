"""Vehicle memory on a same-airframe fleet: each later flight judged against its vehicle's 3 healthy references.

    python -m offline.vehicles.evaluate --fleet DIR [--nominal] [--json OUT.json] [--whole-flight]
    python -m offline.vehicles.calibrate --fleet DIR     (the thresholds of monitor/memory/thresholds.py)

DIR is ``offline.evalsim`` set ``vehicles`` or ``offline.vehicles.ours.write_fleet``'s output (truth JSON beside each
log, ``airframe_id`` and ``reference`` in it). Rows: vehicle memory (``propwatch diagnose --baseline``'s judgement,
through time unless ``--whole-flight``; flights damaged in the air, truth ``fault_onset_boot_s``, counted apart);
the omega^2-share reference (flight-mean share minus the mean of the vehicle's references, argmax: always one
propeller, never healthy); with ``--nominal`` today's nominal verdict (``propwatch diagnose`` without a baseline).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from monitor.memory.judge import judge
from monitor.memory.normal import normal_of
from monitor.memory.summary import FlightSummary
from monitor.memory.through_time import judge_through_time

REFERENCES = 3
CLAIM = 0.06  # the bar: losses at least this are to be named exactly


def load_fleet(fleet: Path, esc=None, cache: bool = True, marks: bool = False) -> dict[str, list[dict]]:
    """{airframe_id: [flight dicts in order]}, each with truth, loss, the summary (cached in DIR/memory-summaries.json)
    and, with ``marks``, its 2-s block marks (each log read again) for judging it through time."""
    from monitor.logs import read_log
    from monitor.memory.summary import accumulate
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

    esc = esc or load_vehicle(DEFAULT_VEHICLE).esc
    cache_path = fleet / "memory-summaries.json"
    cached = json.loads(cache_path.read_text()) if cache and cache_path.is_file() else {}
    by: dict[str, list[dict]] = {}
    for tj in sorted(fleet.glob("*.json")):
        if tj.name in ("manifest.json", cache_path.name):
            continue
        t = json.loads(tj.read_text())
        acc = None
        if tj.stem not in cached or marks:
            acc = accumulate(read_log(fleet / t["file"], esc=esc, rate_hz=20.0, extras=False))
            cached[tj.stem] = acc.summary.to_dict()
        fp = list(t.get("faulty_propellers") or [])
        loss = float(1.0 - min(t["thrust_factor_at_hover"][k - 1] for k in fp)) if fp else 0.0
        ref = bool(t.get("reference")) or t.get("nuisance") == "reference"
        by.setdefault(t["airframe_id"], []).append(
            {"name": tj.stem, "file": str(fleet / t["file"]), "faulty": fp, "loss": loss, "reference": ref,
             "summary": FlightSummary.from_dict(cached[tj.stem], tj.stem), "onset_boot_s": t.get("fault_onset_boot_s")}
            | ({"marks": acc.marks} if marks else {})
        )  # fmt: skip
    if cache:
        cache_path.write_text(json.dumps(cached))
    return by


def later_flights(by: dict[str, list[dict]]):
    """(refs, later flight) pairs: each vehicle's first ``REFERENCES`` reference flights against each later one."""
    for flights in by.values():
        refs = [f for f in flights if f["reference"]][:REFERENCES]
        for f in flights:
            if not f["reference"]:
                yield refs, f


def score(by) -> list[dict]:
    """Each later flight's judgement (through time where its marks were read) and the share reference."""
    rows = []
    for refs, f in later_flights(by):
        normal = normal_of([r["summary"] for r in refs])
        v = judge_through_time(normal, f["summary"], f["marks"]) if "marks" in f else judge(normal, f["summary"])
        ref_mean = np.mean([r["summary"].mean_share() for r in refs], axis=0)
        share_ref = int(np.argmax(f["summary"].mean_share() - ref_mean)) + 1
        rows.append(
            {"name": f["name"], "file": f["file"], "faulty": f["faulty"], "loss": f["loss"], "memory": v, "share_reference": share_ref,
             "refs": [r["file"] for r in refs], "in_air": f.get("onset_boot_s") is not None}
        )  # fmt: skip
    return rows


def outcome(faulty: list[int], label_rotors: list[int], confidence: str) -> str:
    """right (confident, exact) | wrong (confident, not exact) | unsure (any other verdict)."""
    if confidence != "confident":
        return "unsure"
    return "right" if sorted(label_rotors) == sorted(faulty) else "wrong"


def table(rows: list[dict], nominal: dict | None = None) -> dict:
    def block(sel, verdict_of) -> dict:
        out = {"flights": len(sel), "right": 0, "wrong": 0, "unsure": 0, "marked_faulty": 0}
        for r in sel:
            rotors, conf = verdict_of(r)
            out[outcome(r["faulty"], rotors, conf)] += 1
            out["marked_faulty"] += bool(rotors) and conf == "confident"
        return out

    groups = {
        "singles >= 6 %": [r for r in rows if len(r["faulty"]) == 1 and r["loss"] >= CLAIM and not r.get("in_air")],
        "singles 3-6 %": [r for r in rows if len(r["faulty"]) == 1 and r["loss"] < CLAIM and not r.get("in_air")],
        "in-air singles >= 6 %": [r for r in rows if len(r["faulty"]) == 1 and r["loss"] >= CLAIM and r.get("in_air")],
        "in-air singles 3-6 %": [r for r in rows if len(r["faulty"]) == 1 and r["loss"] < CLAIM and r.get("in_air")],
        "healthy": [r for r in rows if not r["faulty"]],
    }
    groups = {g: sel for g, sel in groups.items() if sel or not g.startswith("in-air")}
    res = {}
    for g, sel in groups.items():
        res[g] = {
            "vehicle memory": block(sel, lambda r: (r["memory"]["faulty_propellers"], r["memory"]["confidence"])),
            "omega2-share reference": block(sel, lambda r: ([r["share_reference"]], "confident")),
        }
        if nominal is not None:
            res[g]["nominal diagnose"] = block(sel, lambda r: nominal[r["name"]])
    return res


def nominal_verdicts(rows: list[dict]) -> dict:
    """{flight name: (faulty propellers, confidence)} of today's nominal diagnose."""
    return {n: (list(v["faulty_propellers"]), v["confidence"]) for n, v in nominal_verdict_dicts(rows).items()}


def nominal_verdict_dicts(rows: list[dict]) -> dict:
    """{flight name: today's nominal diagnose verdict} (``propwatch diagnose`` without a baseline; hypotheses kept)."""
    from monitor.diagnose.engine import DEFAULT_MODEL, diagnose_file
    from monitor.model import Classifier, choose_esc
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

    clf = Classifier(DEFAULT_MODEL)
    esc, vehicle = choose_esc(clf, ""), load_vehicle(DEFAULT_VEHICLE)
    out = {}
    for r in rows:
        _, d = diagnose_file(r["file"], clf, esc, None, 20, vehicle)
        v = dict(d.verdict or {"faulty_propellers": [], "confidence": "no verdict"})
        v["faulty_propellers"] = list(v["faulty_propellers"])
        v.setdefault("confidence", "confident")
        out[r["name"]] = v
    return out


def format_table(res: dict) -> str:
    lines = [
        "| flights | rule | n | confident exact | confident wrong | not confident | marked FAULTY |",
        "|---|---|---|---|---|---|---|",
    ]
    for g, rules in res.items():
        for rule, b in rules.items():
            n = max(b["flights"], 1)
            lines.append(
                f"| {g} | {rule} | {b['flights']} | {b['right']} ({100 * b['right'] / n:.1f} %) | {b['wrong']} | {b['unsure']} | "
                f"{b['marked_faulty']} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m offline.vehicles.evaluate", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--fleet", required=True, type=Path, help="a same-airframe fleet folder (truth JSON beside each log)")
    p.add_argument("--nominal", action="store_true", help="also today's nominal diagnose verdict (slower)")
    p.add_argument("--json", type=Path, default=None, help="write the table and every row here")
    p.add_argument(
        "--whole-flight",
        action="store_true",
        help="judge each flight's mean only, not through time (the logs are not read again)",
    )
    args = p.parse_args(argv)
    rows = score(load_fleet(args.fleet, marks=not args.whole_flight))
    res = table(rows, nominal_verdicts(rows) if args.nominal else None)
    print(f"{args.fleet}: {len(rows)} later flights")
    print(format_table(res))
    if args.json:
        args.json.write_text(
            json.dumps({"table": res, "rows": [{k: v for k, v in r.items()} for r in rows]}, indent=1, default=float)
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
