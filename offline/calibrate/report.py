"""``--report DIR``: what the simulation gets wrong, as plots and tables.

- ``residuals_timeseries.png``: each residual signal of the first segments, nominal vs calibrated;
- ``residuals_by_phase.png``: RMS per signal and flight phase, nominal vs calibrated;
- ``steady_state.png``: per-motor command in hover / cruise, measured vs nominal vs calibrated model;
- ``candidates.png``: every candidate term's held-out BIC gain (the ranking);
- ``report.md`` and ``calibration.json``: the same numbers as text.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from offline.calibrate.calibrate import CalibrationResult


def write_report(out_dir: str | Path, result: CalibrationResult) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = [_timeseries(out, result, plt), _by_phase(out, result, plt), _steady(out, result, plt), _candidates(out, result, plt)]
    (out / "calibration.json").write_text(json.dumps(result.to_json(), indent=2) + "\n", encoding="utf-8")
    (out / "report.md").write_text(markdown(result), encoding="utf-8")
    return [f for f in files if f] + [out / "calibration.json", out / "report.md"]


def _timeseries(out: Path, r: CalibrationResult, plt) -> Path:
    names = list(r.selection.nominal_residuals[0])
    calib = r.selection.final.residuals if r.selection.final else r.selection.nominal_residuals
    fig, axes = plt.subplots(len(names), 1, figsize=(11, 1.6 * len(names)), sharex=True)
    t0 = 0.0
    for k, seg in enumerate(r.segments[:3]):
        t = seg.time_s + t0
        for ax, name in zip(axes, names):
            ax.plot(t, r.selection.nominal_residuals[k][name], lw=0.6, color="tab:red", label="nominal" if k == 0 else None)
            ax.plot(t, calib[k][name], lw=0.6, color="tab:blue", label="calibrated" if k == 0 else None)
            ax.set_ylabel(name, fontsize=7, rotation=0, ha="right")
        t0 = t[-1] + 2.0
    axes[0].legend(loc="upper right", fontsize=7)
    axes[-1].set_xlabel("time in segment (s, segments placed end to end)")
    fig.suptitle("equation error, measured minus predicted")
    fig.tight_layout()
    path = out / "residuals_timeseries.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _by_phase(out: Path, r: CalibrationResult, plt) -> Path:
    nom, cal = r.residuals["nominal"], r.residuals["calibrated"]
    phases = list(nom)
    names = list(next(iter(nom.values())))
    fig, axes = plt.subplots(1, len(names), figsize=(2.2 * len(names), 3.2))
    x = np.arange(len(phases))
    for ax, name in zip(axes, names):
        ax.bar(x - 0.2, [nom[p][name] for p in phases], 0.4, color="tab:red", label="nominal")
        ax.bar(x + 0.2, [cal[p][name] for p in phases], 0.4, color="tab:blue", label="calibrated")
        ax.set_xticks(x, phases, rotation=60, fontsize=7)
        ax.set_title(name, fontsize=7)
    axes[0].legend(fontsize=7)
    fig.suptitle("residual RMS per signal and flight phase")
    fig.tight_layout()
    path = out / "residuals_by_phase.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _steady(out: Path, r: CalibrationResult, plt) -> Path | None:
    phases = list(r.steady["nominal"])
    if not phases:
        return None
    fig, axes = plt.subplots(1, len(phases), figsize=(5 * len(phases), 3.4), squeeze=False)
    x = np.arange(4)
    for ax, p in zip(axes[0], phases):
        nom, cal = r.steady["nominal"][p], r.steady["calibrated"][p]
        ax.bar(x - 0.27, nom["measured"], 0.27, color="k", label="measured")
        ax.bar(x, nom["predicted"], 0.27, color="tab:red", label="nominal model")
        ax.bar(x + 0.27, cal["predicted"], 0.27, color="tab:blue", label="calibrated model")
        lo = min(min(nom["measured"]), min(nom["predicted"]), min(cal["predicted"]))
        hi = max(max(nom["measured"]), max(nom["predicted"]), max(cal["predicted"]))
        ax.set_ylim(lo - 0.2 * (hi - lo + 1), hi + 0.2 * (hi - lo + 1))
        ax.set_xticks(x, [f"motor {i + 1}" for i in range(4)])
        ax.set_title(f"{p}: mean command ({nom['n_samples']} held-out samples)")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    path = out / "steady_state.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _candidates(out: Path, r: CalibrationResult, plt) -> Path:
    names = list(r.candidates)
    scores = [r.candidates[n]["score"] if r.candidates[n]["identifiable"] else 0.0 for n in names]
    fig, ax = plt.subplots(figsize=(8, 3.2))
    colors = [
        "tab:green" if n == r.cause else ("tab:gray" if not r.candidates[n]["identifiable"] else "tab:orange") for n in names
    ]
    ax.bar(names, np.sign(scores) * np.log10(1 + np.abs(scores)), color=colors)
    ax.set_ylabel("sign * log10(1 + held-out BIC gain)")
    ax.set_title("candidate terms alone on the nominal model (grey: not identifiable)")
    ax.tick_params(axis="x", rotation=30, labelsize=8)
    fig.tight_layout()
    path = out / "candidates.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def markdown(r: CalibrationResult) -> str:
    lines = [
        "# Calibration report",
        "",
        f"Logs: {', '.join(r.sources)}",
        "",
        f"**Cause: {r.cause or 'none stands out above the noise'}**" + (f" (confidence {r.confidence:.3f})" if r.cause else ""),
        "",
    ]
    if r.unexplained.get("found"):
        lines += [
            f"**Unexplained residual** (no term can express it; nothing written onto the vehicle): {r.unexplained['summary']}",
            "",
        ]
    if r.inspect_rotor:
        lines += [f"**Inspect rotor {r.inspect_rotor['rotor']}'s propeller** before trusting this calibration (notes below).", ""]
    for f in r.findings:
        lines += (
            [
                f"## {f['effect']}",
                "",
                f"params: {f['params']} (standard errors {f['std']})",
                f"held-out residual RMS {f['residual_rms_before']:.4g} -> {f['residual_rms_after']:.4g}, "
                f"BIC gain {f['score']:.1f}",
                "",
            ]
            + [f"- {e}" for e in f["evidence"]]
            + [""]
        )
    lines += [f"Note: {n}" for n in r.notes] + ([""] if r.notes else [])
    lines += [
        "## Candidates (each alone on the nominal model)",
        "",
        "| term | identifiable | BIC gain | params | note |",
        "|---|---|---|---|---|",
    ]
    for n, c in r.candidates.items():
        lines.append(f"| {n} | {c['identifiable']} | {c['score']} | {c['params']} | {c['reason']} |")
    for which in ("nominal", "calibrated"):
        res = r.residuals[which]
        names = list(next(iter(res.values())))
        lines += [
            "",
            f"## Residual RMS per phase, {which} model",
            "",
            "| phase | " + " | ".join(names) + " |",
            "|---" * (len(names) + 1) + "|",
        ]
        lines += [f"| {p} | " + " | ".join(f"{v[s]:.4g}" for s in names) + " |" for p, v in res.items()]
    lines += ["", "## Steady state (held-out samples)", ""]
    for which in ("nominal", "calibrated"):
        for p, v in r.steady[which].items():
            lines.append(
                f"- {which} {p}: measured {np.round(v['measured'], 1).tolist()}, predicted "
                f"{np.round(v['predicted'], 1).tolist()}, error RMS {v['error_rms']:.2f}"
            )
    u = r.unbalance
    lines += [
        "",
        "## Paper's unbalance ratio (eqs. 14-17) vs fitted motor_efficiency",
        "",
        f"ratios {u['ratio']}; held-out residual RMS nominal {u['residual_rms_nominal']:.4g}, "
        f"unbalance ratio {u['residual_rms_unbalance_ratio']:.4g}, fitted motor_efficiency "
        f"{u['residual_rms_fitted_motor_efficiency']:.4g}",
        "",
        "## Gain",
        "",
        "```",
        json.dumps(r.gain, indent=1),
        "```",
        "",
    ]
    return "\n".join(lines)
