"""The Crazyflie classifier's card, written from its manifest (never by hand).

``card_markdown(manifest)`` reads only ``manifest["shipped"]`` (what ``propwatch crazypad
run --ship`` stores beside the model): calibration per airframe, split, recipe, features and the
per-condition table of every trained variant. Every figure in the card comes from there.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from offline.crazypad.vehicle import PROJECT_INDEX_OF_BITCRAZE

PAPER_REAL_ACCURACY = 0.7632  # Tong et al., real-flight accuracy of their calibrated model (labels 1-5, own quad)
VARIANT_TITLES = {
    "nominal": "nominal sim",
    "calibrated": "calibrated sim (shipped)",
    "calibrated_own": "calibrated, own airframe",
}


def _pct(v) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{100 * v:.1f} %"


def _bitcraze(project4) -> str:
    return ", ".join(f"M{k} {project4[PROJECT_INDEX_OF_BITCRAZE[f'M{k}']]:.3f}" for k in range(1, 5))


def card_markdown(manifest: dict, model_name: str = "crazyflie-classifier.onnx") -> str:
    s = manifest["shipped"]
    table, cal, split, recipe = s["table"], s["calibration"], s["split"], s["recipe"]
    variants = [v for v in VARIANT_TITLES if v in table] + [v for v in table if v not in VARIANT_TITLES]
    shipped = "calibrated" if "calibrated" in table else variants[0]
    n_fit = len(split["calibration"])
    n_hold = len(split["holdout"])
    lines = [
        f"# propwatch Crazyflie classifier card (`models/{model_name}`)",
        "",
        "Written by `offline/crazypad/card.py` from `crazyflie-classifier.manifest.json` (built by `make crazypad`,",
        f"`propwatch crazypad run --ship`; git revision {manifest.get('git_revision', 'unknown')}, seed {manifest.get('seed')}).",
        "Same contract as `models/classifier.onnx` (16 labels, `fault_probability` per propeller in PX4 order).",
        "",
        f"**Inputs.** {', '.join(f'`{f}`' for f in s['features'])} at 20 Hz, window {s['window_steps']} steps.",
        "",
        "**Calibration** (steady-state view of `offline/calibrate/fit.py`, per airframe, healthy flights with an even",
        "log number; held-out = odd):",
        "",
        "| airframe | cause | calibrated motor efficiency | held-out RMS command error, nominal -> calibrated |",
        "|---|---|---|---|",
    ]
    for af, c in sorted(cal.items()):
        eff = c["calibrated_terms"]["motor_efficiency"]
        h = c["holdout_rms_cmd"]
        lines.append(f"| {af} | {c['cause']} | {_bitcraze(eff)} | {h['nominal']} -> {h['calibrated']} |")
    first = next(iter(cal.values()), {})
    if first.get("cannot_separate"):  # the motor logs carry no body rates: what the steady view cannot tell apart
        lines += [
            "",
            "The motor logs carry no body rates, so this view cannot separate "
            + "; ".join(" from ".join(f"`{t}`" for t in pair) for pair in first["cannot_separate"])
            + ", and cannot see "
            + ", ".join(f"`{t}`" for t in first["not_observable"])
            + ".",
        ]
    lines += [
        "",
        f"**Training.** Simulated CrazyPAD missions only, labels {recipe['labels'][0]}-{recipe['labels'][-1]}, "
        f"{recipe['flights_per_label']} flights per label, thrust loss {recipe['thrust_loss']} of a cut rotor, healthy "
        f"rotors +-{recipe['healthy_jitter']}, command noise {recipe['cmd_noise']} of the share per sample, seed "
        f"{recipe['seed']}.",
        "",
        f"**Real-flight accuracy** (exact label; {n_fit} healthy flights calibrate, {n_hold} healthy flights and "
        f"{split['evaluation']} fault/mass flights are only scored; a mass or string flight counts as correct when "
        "called healthy):",
        "",
        "| condition | flights | "
        + " | ".join(f"accuracy: {VARIANT_TITLES.get(v, v)}" for v in variants)
        + " | called faulty (shipped) |",
        "|---|---|" + "---|" * len(variants) + "---|",
    ]
    from offline.crazypad.experiment import GROUP_ORDER

    order = [g for g in GROUP_ORDER + ("all",) if g in table[shipped]]
    order += [g for g in table[shipped] if g not in order]
    for group in order:
        row = table[shipped][group]
        cells = [_pct(table[v].get(group, {}).get("accuracy")) for v in variants]
        lines.append(f"| {group} | {row['flights']} | " + " | ".join(cells) + f" | {_pct(row.get('called_faulty'))} |")
    lines += fusion_lines(s.get("fusion"))
    lines += [
        "",
        f"The paper's real-flight figure ({100 * PAPER_REAL_ACCURACY:.2f} %, Tong et al.) is on labels 1-5 of its own",
        "quadrotor; it is not like-for-like with any row above.",
    ]
    return "\n".join(lines) + "\n"


def fusion_lines(fusion: dict | None) -> list[str]:
    """The verdict of an adapted airframe (``diagnose --vehicle DIR``): classifier, baseline and both fused, as
    ``bench/crazypad_fusion.py --write-card`` stored them (absent in manifests written before it)."""
    if not fusion:
        return []
    k = fusion["outlier_spreads"]
    lines = [
        "",
        f"**With the airframe's healthy baseline, older share rule** (what `propwatch diagnose LOG --vehicle DIR` said before "
        "vehicle memory, `offline/adapt/share_rule.py`; vehicle memory's figures: docs/VEHICLE_MEMORY.md; "
        f"`{fusion['bench']}`, git "
        f"revision {fusion['git_revision']}): per airframe and log kind, the baseline of its even-numbered healthy logs; "
        f"baseline only = the rotor furthest above its healthy share when beyond {k:g} spreads, else healthy; fused = "
        f"`offline.adapt.share_rule.fuse` (rotors beyond {k:g} spreads, the classifier choosing among several; none: healthy "
        "unless the classifier alone is confident). No constant is fitted on a fault flight; the healthy calibration "
        "flights, each against the others of its airframe, reach "
        f"{fusion['healthy_calibration_max_deviation_spreads']:.2f} spreads. Cells: exact / called a propeller fault.",
    ]
    methods = (("classifier", "adapted classifier"), ("baseline", "baseline only"), ("fused", "fused"))
    tables = fusion["tables_by_log_kind"].values()
    if all("baseline_t" in row for t in tables for row in t):  # absent in manifests written before it
        ks = ", ".join(f"{af} {kind} {k:.1f}" for af, kind, k in fusion.get("t_spreads_required_by_baseline", []))
        lines[-1] += (
            f" Baseline t rule = baseline only with Student's t in place of {k:g} spreads "
            f"(`offline.adapt.share_rule.t_spreads_required`, spreads required per baseline: {ks}); reported, not used."
        )
        methods = methods[:2] + (("baseline_t", "baseline, t rule"),) + methods[2:]
    shipped = all("verdict" in row for t in tables for row in t)  # absent in manifests written before it
    if shipped:
        lines[-1] += (
            " Verdict = what `diagnose --vehicle DIR` said on this airframe, whose baseline records that a CG offset "
            "and damage look alike (`cg_damage_separable: false`): a fused fault becomes an imbalance near its rotors, "
            "no propeller called faulty (`offline.adapt.share_rule.cg_or_damage`); its cells: exact / called a propeller fault "
            "/ imbalance located (at the damaged rotors, or the rotors a mass hangs near) / any imbalance flagged (an "
            "ambiguous verdict, exit code 3: on a healthy flight, a false alarm)."
        )
        methods += (("verdict", "verdict (imbalance rule)"),)
    for kind, table in sorted(fusion["tables_by_log_kind"].items(), key=lambda kv: kv[0] != "motor"):  # motor logs first
        what = "logged motor commands" if kind == "motor" else "commands rebuilt by the firmware mixer"
        lines += [
            "",
            f"{kind} logs ({what}):",
            "",
            "| condition | flights | " + " | ".join(t for _, t in methods) + " |",
            "|---|---|" + "---|" * len(methods),
        ]
        for row in table:
            n = row["flights"]
            cells = [f"{row[m]['exact']}/{n} / {row[m]['called_fault']}/{n}" for m, _ in methods]
            if shipped:
                cells[-1] += f" / {row['verdict']['imbalance_located']}/{n} / {row['verdict']['imbalance_any']}/{n}"
            lines.append(f"| {row['condition']} | {n} | " + " | ".join(cells) + " |")
    return lines


def write_card(manifest_path: str | Path, card_path: str | Path | None = None) -> Path:
    manifest_path = Path(manifest_path)
    manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
    name = manifest["shipped"].get("model", "crazyflie-classifier.onnx")
    card_path = Path(card_path) if card_path else manifest_path.with_name(Path(name).stem + ".card.md")
    card_path.write_text(card_markdown(manifest, name), encoding="utf-8")
    return card_path
