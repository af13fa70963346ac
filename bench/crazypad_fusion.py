"""The verdict of an adapted airframe on every real CrazyPAD motor log: classifier, baseline, and both fused.

    nice python -m bench.crazypad_fusion [--root ../shared/data/crazypad] [--json out.json] [--write-card]

Per airframe (E8, E9) the healthy baseline (``offline.adapt.share_rule``) is built from its healthy logs with an
even number (the CrazyPAD split, ``offline/crazypad/data.py``), exactly as ``propwatch adapt`` stores it;
every other log is scored four ways, per condition. Motor logs (logged commands) and controller logs
(commands rebuilt by the firmware mixer, ``monitor/logs/mixers.py``) each get their own baseline per
airframe, from their own even-numbered healthy logs:

- nominal: the classifier trained on the nominal simulation, figures stored in the shipped manifest
  (``models/crazyflie-classifier.manifest.json``, ``shipped.table.nominal``; no model file ships, so not re-run);
- adapted classifier: ``models/crazyflie-classifier.onnx`` (calibrated simulation) as ``propwatch diagnose``
  runs it (hop 20);
- baseline only: the rotor with the largest deviation when it is beyond 3 spreads, else healthy;
- fused: ``offline.adapt.share_rule.fuse``;
- verdict: what ``propwatch diagnose LOG --vehicle DIR`` now says of an airframe adapted on CrazyPAD logs, whose
  baseline carries ``cg_damage_separable: false`` (``offline/crazypad/evidence.py``): a fused fault becomes an
  imbalance near its rotors (``offline.adapt.share_rule.cg_or_damage``), no propeller called faulty. "Imbalance located"
  = the imbalance's rotors are the damaged ones (cuts, tape) or the ones the mass hangs near (masses, strings).

Exact = the paper's label (cuts and tape are faults of their rotors; masses and strings are healthy).
"Called a fault" = any propeller named. No constant of the fusion is fitted on a fault flight (see
``offline.adapt.share_rule.fuse``), so every condition is scored as if left out. The constant k = 3 spreads is
checked here on the healthy calibration flights only: each against the baseline of the other calibration
flights of its airframe. ``--write-card`` stores the table in the shipped manifest and rewrites the card
from it (the motor-log table). About two minutes.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from bench import REPO
from monitor.diagnose.engine import diagnose_table  # noqa: E402
from monitor.labels import LABEL_TABLE, label_from_mask  # noqa: E402
from monitor.model import Classifier  # noqa: E402
from monitor.vehicle import load_vehicle  # noqa: E402
from offline.adapt.share_rule import OUTLIER_SPREADS, baseline_from_tables, cg_or_damage, fuse  # noqa: E402
from offline.crazypad.data import AIRFRAMES, DEFAULT_ROOT, load_manifest, select  # noqa: E402
from offline.crazypad.evidence import CG_DAMAGE_SEPARABLE, CG_OFFSET_KINDS  # noqa: E402
from offline.crazypad.experiment import GROUP_ORDER, truth_label  # noqa: E402
from offline.crazypad.real import read_flight  # noqa: E402
from offline.crazypad.vehicle import PROJECT_INDEX_OF_BITCRAZE  # noqa: E402

MODEL = REPO / "models" / "crazyflie-classifier.onnx"
MANIFEST = REPO / "models" / "crazyflie-classifier.manifest.json"
METHODS = ("classifier", "baseline", "baseline_t", "fused", "verdict")
HOP = 20  # propwatch diagnose's default


def baseline_label(dev: np.ndarray, spreads: float = OUTLIER_SPREADS) -> int:
    k = int(np.argmax(dev))
    if dev[k] <= spreads:
        return 1
    return label_from_mask([i == k for i in range(4)])


KINDS = ("motor", "controller")


def location_label(f) -> int:
    """Where the condition sits: the damaged rotors (cuts, tape), the rotors a mass hangs near (masses, strings;
    "near M3+M4" in the group name), none (healthy); as a label of PX4 rotors."""
    if f.fault_kind not in CG_OFFSET_KINDS:
        return truth_label(f)
    near = f.group.split(" near ")[1].split("+")
    mask = [False] * 4
    for m in near:
        mask[PROJECT_INDEX_OF_BITCRAZE[m]] = True
    return label_from_mask(mask)


def shipped_verdict(fused_label: int) -> tuple[int, list[int]]:
    """(label, imbalance rotors) of ``diagnose --vehicle DIR`` on a CrazyPAD-adapted airframe."""
    if CG_DAMAGE_SEPARABLE is False and LABEL_TABLE[fused_label]:
        v = cg_or_damage(fused_label, ["M1", "M3", "M4", "M2"])
        return v["label"], v["imbalance_rotors"]
    return fused_label, []


def kind(f) -> str:
    """Motor logs (logged commands) and controller logs (commands rebuilt by the firmware mixer) differ per
    airframe by their own static offsets: each kind gets its own baseline, as two `propwatch adapt` runs would."""
    return "motor" if f.has_motor_commands else "controller"


def healthy_leave_one_out(flights, tables) -> dict:
    """Each healthy calibration flight against the baseline of the other calibration flights of its airframe."""
    out = {}
    for af, k in [(af, k) for af in AIRFRAMES for k in KINDS]:
        cal = [f for f in flights if f.airframe == af and kind(f) == k and f.role == "calibration"]
        for f in cal:
            rest = [g for g in cal if g is not f]
            base = baseline_from_tables([tables[g.file] for g in rest], [g.file for g in rest])
            out[f.file] = [round(float(x), 2) for x in base.compare(tables[f.file])["deviation_spreads"]]
    return out


def score(args) -> dict:
    vehicle = load_vehicle(REPO / "models" / "crazyflie.yaml")
    clf = Classifier(MODEL)
    flights = [f for f in select(load_manifest(args.root), motor_only=False) if kind(f) in args.logs]
    tables = {f.file: read_flight(f, vehicle, args.root) for f in flights}
    loo = healthy_leave_one_out(flights, tables)
    rows = []
    for af, k in [(af, k) for af in AIRFRAMES for k in args.logs]:
        cal = [f for f in flights if f.airframe == af and kind(f) == k and f.role == "calibration"]
        base = baseline_from_tables([tables[f.file] for f in cal], [f.file for f in cal])
        for f in flights:
            if f.airframe != af or kind(f) != k or f.role == "calibration":
                continue
            d = diagnose_table(tables[f.file], clf, hop=HOP, esc=vehicle.esc)
            seen = base.compare(tables[f.file])
            dev = np.asarray(seen["deviation_spreads"])
            row = {
                "file": f.file,
                "airframe": af,
                "logs": k,
                "group": f.group,
                "truth": truth_label(f),
                "location": location_label(f),
                "deviation_spreads": dev.tolist(),
            }
            row["baseline"] = baseline_label(dev)
            row["t_spreads_required"] = seen["t_spreads_required"]
            k_t = seen["t_spreads_required"]  # None for a one-flight baseline: no t rule
            row["baseline_t"] = None if k_t is None else baseline_label(dev, k_t)
            if d.verdict is None:
                row.update(classifier=None, fused=None, verdict=None, imbalance=None, reason=d.reason)
            else:
                row["classifier"] = d.verdict["label"]
                conf = d.verdict["confidence"] == "confident"
                row["fused"] = fuse(dev, d.label_probability, d.verdict["label"], conf)["label"]
                row["verdict"], row["imbalance"] = shipped_verdict(row["fused"])
            rows.append(row)
    return {"rows": rows, "healthy_leave_one_out": loo}


def table(rows: list[dict]) -> dict:
    by = defaultdict(list)
    for r in rows:
        by[r["group"]].append(r)
    for name, pick in (
        ("cuts >= 3 mm", lambda r: r["group"] in ("cut 3-4.5 mm", "cut 5-8 mm")),
        ("tape", lambda r: r["group"].startswith("tape")),
        ("masses", lambda r: r["group"].startswith("mass")),
        ("strings", lambda r: r["group"].startswith("string")),
    ):
        by[name] = [r for r in rows if pick(r)]
    order = [g for g in GROUP_ORDER if g in by] + ["cuts >= 3 mm", "tape", "masses", "strings"]
    out = {}
    for g in order:
        rs = by[g]
        out[g] = {"flights": len(rs)}
        for m in METHODS:
            out[g][m] = {
                "exact": sum(r[m] == r["truth"] for r in rs),
                "called_fault": sum(r[m] is not None and r[m] != 1 for r in rs),
            }
        loc = [r for r in rs if r["location"] != 1]
        out[g]["verdict"]["imbalance_located"] = sum(
            bool(r["imbalance"]) and sorted(r["imbalance"]) == sorted(LABEL_TABLE[r["location"]]) for r in loc
        )
        out[g]["verdict"]["imbalance_any"] = sum(bool(r["imbalance"]) for r in rs)
    return out


def nominal_stored() -> dict:
    """The nominal-simulation model's per-condition exact accuracy and called-faulty rate, as stored at ship time."""
    man = json.loads(MANIFEST.read_text())
    return man["shipped"]["table"].get("nominal", {})


def markdown(t: dict, nominal: dict) -> str:
    def cell(x, n):
        return f"{x}/{n} ({100 * x / n:.0f} %)" if n else "-"

    def nom(g):
        s = nominal.get(g)
        if not s:
            return "-"
        return f"{100 * s['accuracy']:.0f} % / {100 * s['called_faulty']:.0f} %"

    head = "| condition | flights | nominal sim (stored): exact / called a fault | " + " | ".join(
        f"{m}: exact | {m}: called a fault"
        for m in ("adapted classifier", "baseline only", "baseline t rule", "fused", "verdict")
    )
    lines = [head + " | verdict: imbalance located | verdict: any imbalance |", "|---|---|---|" + "---|---|" * 5 + "---|---|"]
    for g, s in t.items():
        n = s["flights"]
        cells = [c for m in METHODS for c in (cell(s[m]["exact"], n), cell(s[m]["called_fault"], n))]
        cells += [cell(s["verdict"]["imbalance_located"], n), cell(s["verdict"]["imbalance_any"], n)]
        lines.append(f"| {g} | {n} | {nom(g)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=DEFAULT_ROOT)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--write-card", action="store_true", help="store the table in the shipped manifest, rewrite the card")
    ap.add_argument("--logs", nargs="+", choices=KINDS, default=list(KINDS), help="which CrazyPAD log kinds to score")
    args = ap.parse_args(argv)
    res = score(args)
    tables = {k: table([r for r in res["rows"] if r["logs"] == k]) for k in args.logs}
    worst = max(max(abs(x) for x in v) for v in res["healthy_leave_one_out"].values())
    for k, tk in tables.items():
        what = "logged motor commands" if k == "motor" else "commands rebuilt by the firmware mixer; nominal column: motor logs"
        print(f"\n{k} logs ({what}):\n" + markdown(tk, nominal_stored()))
    print(
        f"\nk = {OUTLIER_SPREADS:g} spreads; healthy calibration flights, each against the others of its airframe: "
        f"largest |deviation| {worst:.2f} spreads over {len(res['healthy_leave_one_out'])} flights"
    )
    if args.json:
        args.json.write_text(json.dumps({"tables": tables, **res}, indent=1))
    if args.write_card:
        from offline.crazypad.card import write_card
        from offline.manifest import git_revision, write_manifest

        man = json.loads(MANIFEST.read_text())
        man["shipped"]["fusion"] = {
            # Lists of rows: the manifest's keys are sorted on writing, the rows keep the report's order.
            "tables_by_log_kind": {k: [{"condition": g, **row} for g, row in tk.items()] for k, tk in tables.items()},
            "outlier_spreads": OUTLIER_SPREADS,
            "t_spreads_required_by_baseline": sorted(
                {(r["airframe"], r["logs"], r["t_spreads_required"]) for r in res["rows"] if r["t_spreads_required"]}
            ),
            "healthy_calibration_max_deviation_spreads": worst,
            "hop_steps": HOP,
            "git_revision": git_revision(),
            "bench": "bench/crazypad_fusion.py",
        }
        write_manifest(MANIFEST, man)
        print(f"card: {write_card(MANIFEST)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
