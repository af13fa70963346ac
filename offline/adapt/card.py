"""The card of an adapted model, written from its manifest (``adapt.manifest.json``)."""

from __future__ import annotations

import json
from pathlib import Path


def _row(name: str, s: dict) -> str:
    exact = f"{s['exact']}/{s['scored']}" if s["scored"] else "n/a"
    fa = f"{s['healthy_false_alarms']}/{s['healthy']}" if s["healthy"] else "n/a"
    return f"| {name} | {exact} | {fa} |"


def calibration_text(cal: dict) -> str:
    """One paragraph: the view used, the cause, the fit before and after, what is left unexplained or inseparable."""
    if cal.get("view") == "dynamic":
        g = cal["gain"]
        text = (
            f"**Calibration** (dynamic view of `offline/calibrate`, as `propwatch calibrate`; {cal['split']}): cause "
            f"`{cal['cause']}` ({cal['why']}); held-out residual RMS {g['heldout_residual_rms_before']} -> "
            f"{g['heldout_residual_rms_after']}."
        )
        un = cal.get("unexplained_residual")
        if un:
            text += f" Unexplained residual: {un['summary']}."
        return text + "".join(f" Note: {n}." for n in cal.get("notes", []))
    un = cal.get("unexplained_residual", {})
    return (
        f"**Calibration** (steady-state view of `offline/calibrate/fit.py`: {cal.get('view_why', 'per-motor mean commands')}): "
        f"cause `{cal['cause']}` ({cal['why']}); "
        f"held-out RMS command error {cal['holdout_rms_cmd']['nominal']} -> {cal['holdout_rms_cmd']['calibrated']}; "
        f"unexplained residual {un.get('rms_cmd')} command units ("
        + (
            f"{un['in_standard_errors']} standard errors"
            if un.get("in_standard_errors") is not None
            else "no flight-to-flight spread to measure it against: one fit flight"
        )
        + ")."
        + (
            " This view cannot separate "
            + "; ".join(" from ".join(f"`{t}`" for t in pair) for pair in cal["cannot_separate"])
            + ", and cannot see "
            + ", ".join(f"`{t}`" for t in cal.get("not_observable", []))
            + "."
            if cal.get("cannot_separate")
            else ""
        )
    )


def baseline_text(base: dict) -> str:
    """The vehicle-memory baseline (``monitor.memory.cli.describe``) that ``diagnose --vehicle DIR`` judges with."""
    head = (
        f"**Healthy baseline** (vehicle memory, `baseline.json`; {base['basis']} shares, PX4 order, names "
        f"{', '.join(base['motor_names'])}; {len(base['flights'])} flights)"
    )
    if not base["ready"]:
        return (
            head + f": not ready ({len(base['flights'])} of {base['flights_needed']} flights), so diagnose does not compare yet."
        )
    return (
        head
        + ": normal share "
        + ", ".join(f"{x:.3f}" for x in base["normal_share"])
        + "; flight-to-flight spread "
        + ", ".join(f"{x:.4f}" for x in base["spread_share"])
        + "."
    )


def card_markdown(m: dict) -> str:
    cal, base, cfg = m["calibration"], m["baseline"], m["config"]
    lines = [
        "# propwatch adapted classifier card",
        "",
        f"Written by `offline/adapt/card.py` from `adapt.manifest.json` (`propwatch adapt`, git revision "
        f"{m.get('git_revision')}, seed {m.get('seed')}).",
        "",
        f"**Healthy logs** ({len(m['healthy'])}): " + ", ".join(f"`{Path(p).name}`" for p in m["healthy"]) + ".",
        f"Healthy logs scored as held out (never trained on): {len(m['held_out_healthy'])}.",
        "",
        calibration_text(cal),
        "",
        baseline_text(base),
        *(
            [
                "",
                f"**CG offset or damage**: not separable on this airframe's kind of flights ({base['cg_damage_evidence']});"
                ' a fault verdict reads "imbalance near ROTOR: CG offset or damage" and names no faulty propeller'
                " (both causes are its hypotheses).",
            ]
            if base.get("cg_damage_separable") is False
            else []
        ),
        "",
        f"**Training** (simulation only; {m['assumptions']}): mission `{cfg['mission']}`, {cfg['flights_per_label']} "
        f"flights per label, features {', '.join(cfg['features'])}, window {cfg['window']}, {cfg['epochs']} epochs, "
        f"CNN {cfg['blocks']} blocks x {cfg['channels']} channels, dense {cfg['dense']}.",
        "",
        "**Gain over the nominal model** (same recipe and network, trained around the nominal vehicle), on the held-out",
        "healthy logs and the `--labelled` logs:",
        "",
        "| model | exact label | called faulty, of the flights whose truth is healthy (held-out healthy + labelled healthy) |",
        "|---|---|---|",
        _row("nominal", m["scores"]["nominal"]["summary"]),
        _row("adapted", m["scores"]["adapted"]["summary"]),
        "",
        "| log | truth | nominal | adapted |",
        "|---|---|---|---|",
    ]
    for a, b in zip(m["scores"]["nominal"]["logs"], m["scores"]["adapted"]["logs"]):
        lines.append(f"| `{Path(a['log']).name}` | {a['truth_label']} | {a['label']} | {b['label']} |")
    return "\n".join(lines) + "\n"


def write_card(manifest_path: str | Path, card_path: str | Path) -> Path:
    m = json.loads(Path(manifest_path).read_text(encoding="utf-8"))
    card_path = Path(card_path)
    card_path.write_text(card_markdown(m), encoding="utf-8")
    return card_path
