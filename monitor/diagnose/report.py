"""``--report DIR``: one PNG (probability timeline and the signals) and one HTML page per log.

matplotlib is imported here only (Agg backend, no display needed).
"""

from __future__ import annotations

import html
import re
from pathlib import Path

import numpy as np

from monitor.diagnose.engine import Diagnosis, describe_label, rotor_name
from monitor.errors import PropwatchError
from monitor.flight import FlightTable
from monitor.resample import US_PER_S


def _stem(source: str, out_dir: Path) -> str:
    """A file name for this log's report; CrazyPAD-like trees reuse names (E8_log00) in many folders."""
    p = Path(source)
    base = re.sub(r"[^A-Za-z0-9_.-]", "_", p.name) or "log"
    stem, k = base, 1
    while (out_dir / f"{stem}.html").exists() and (out_dir / f"{stem}.html").read_text(encoding="utf-8").find(
        html.escape(str(source)) + "<"
    ) < 0:
        k += 1
        stem = f"{base}-{k}"
    return stem


# The daemon's default alert threshold on P(faulty) (monitor.daemon.config.AlertConfig), drawn for reference.
ALERT_THRESHOLD = 0.9


def broken_at_gaps(t_s: np.ndarray, y: np.ndarray, max_step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)`` with a NaN row inserted wherever consecutive points are more than ``max_step_s`` apart,
    so a line is not drawn across a landed gap."""
    t_s, y = np.asarray(t_s, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if len(t_s) < 2:
        return t_s, y
    cut = np.flatnonzero(np.diff(t_s) > max_step_s * 1.5) + 1
    return np.insert(t_s, cut, np.nan), np.insert(y, cut, np.nan, axis=0)


def unwrap_deg(angle_rad: np.ndarray) -> np.ndarray:
    """Degrees, unwrapped across +-180 over the measured samples (NaN stays NaN), so yaw draws no spikes."""
    a = np.asarray(angle_rad, dtype=np.float64)
    out = np.full_like(a, np.nan)
    ok = np.isfinite(a)
    out[ok] = np.rad2deg(np.unwrap(a[ok]))
    return out


def _not_logged(ax, what: str) -> None:
    ax.set_yticks([])
    ax.text(0.5, 0.5, f"{what}: not logged", transform=ax.transAxes, ha="center", va="center", color="0.4", fontsize=11)


def plot(d: Diagnosis, table: FlightTable, png: Path, threshold: float = ALERT_THRESHOLD) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.patches import Patch
    except ImportError as exc:
        raise PropwatchError("--report needs matplotlib (pip install 'propwatch[logs]')") from exc
    t = table.timestamp_us / US_PER_S
    fig, ax = plt.subplots(4, 1, figsize=(11, 10), sharex=True)
    names = [rotor_name(n, i + 1) for i, n in enumerate(table.motor_names)]
    if d.timeline:
        step_s = d.hop_steps / table.rate_hz
        tl, p = broken_at_gaps(d.timeline["t_boot_s"], d.timeline["fault_probability"], step_s)
        for i in range(4):
            ax[0].plot(tl, p[:, i], ".-", ms=2, lw=0.8, label=names[i])
    else:
        _not_logged(ax[0], "no window classified, so P(faulty)")
    ax[0].axhline(threshold, color="tab:red", ls="--", lw=0.8, label=f"alert threshold {threshold:g}")
    ax[0].set_ylim(-0.02, 1.02)
    ax[0].set_ylabel("P(faulty) per window")
    handles, labels = ax[0].get_legend_handles_labels()
    handles.append(Patch(color="tab:green", alpha=0.15, lw=0))
    labels.append("airborne")
    ax[0].legend(handles, labels, loc="upper left", fontsize=8, ncol=3)
    title = (
        "no verdict: " + (d.reason or "")
        if d.verdict is None
        else describe_label(d.verdict["label"], list(table.motor_names), d.verdict.get("confidence", "confident"))
    )
    ax[0].set_title(f"{Path(d.source).name}: {title}", fontsize=10)
    rpm_known = np.isfinite(table.motor_rpm).any()
    motor = table.motor_rpm if rpm_known else table.motor_cmd
    _signals(ax[1], t, [(motor[:, i], names[i]) for i in range(4)], "motor commands")
    ax[1].set_ylabel("target RPM" if rpm_known else f"command ({table.extras.get('motor_cmd_unit', '')})")
    attitude = [
        (np.rad2deg(table.roll_rad), "roll"),
        (np.rad2deg(table.pitch_rad), "pitch"),
        (unwrap_deg(table.yaw_rad), "yaw (unwrapped)"),
    ]
    _signals(ax[2], t, attitude, "attitude")
    ax[2].set_ylabel("attitude (deg)")
    rates = [
        (np.rad2deg(getattr(table, name)), lab)
        for name, lab in (("roll_rate_rad_s", "roll rate"), ("pitch_rate_rad_s", "pitch rate"), ("yaw_rate_rad_s", "yaw rate"))
    ]
    _signals(ax[3], t, rates, "body rates")
    ax[3].set_ylabel("body rate (deg/s)")
    ax[3].set_xlabel("autopilot boot time (s)")
    for a in ax:
        for s in d.segments:
            a.axvspan(s["start_boot_s"], s["stop_boot_s"], color="tab:green", alpha=0.08, lw=0)
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    plt.close(fig)


def _signals(ax, t: np.ndarray, series: list[tuple[np.ndarray, str]], what: str) -> None:
    """Plot each (values, label); a series never measured is named as not logged instead of drawn empty."""
    missing = [lab for y, lab in series if not np.isfinite(y).any()]
    for y, lab in series:
        if np.isfinite(y).any():
            ax.plot(t, y, lw=0.7, label=lab)
    if len(missing) == len(series):
        _not_logged(ax, what)
    else:
        if missing:
            ax.text(0.01, 0.04, "not logged: " + ", ".join(missing), transform=ax.transAxes, color="0.4", fontsize=8)
        ax.legend(loc="upper right", fontsize=8)


def page(d: Diagnosis, png_name: str) -> str:
    e = html.escape
    rows = "".join(
        f"<tr><td>{e(p['name'])}</td><td>{p['propeller']}</td><td>{p['fault_probability']:.3f}</td>"
        f"<td>{'FAULTY' if p['faulty'] else 'suspect' if p.get('suspect') else 'ok'}</td></tr>"
        for p in d.propellers
    )
    conf = d.verdict.get("confidence", "confident") if d.verdict is not None else ""
    verdict = (
        f"<p><b>No verdict:</b> {e(d.reason or '')}</p>"
        if d.verdict is None
        else f"<p><b>Verdict: {e(describe_label(d.verdict['label'], [p['name'] for p in d.propellers], conf))}</b>"
        + (
            f" (from the in-flight rule's fault at {d.verdict['change_boot_s']:.1f} s boot time, the flight against its"
            " own start; over the whole flight: "
            + e(
                describe_label(
                    d.verdict["whole_flight"]["label"], [p["name"] for p in d.propellers], d.verdict["whole_flight"]["confidence"]
                )
            )
            + ")"
            if d.verdict.get("source") == "in-flight change"
            else ""
        )
        + f" ({d.windows} windows; {conf}: label probability {d.verdict.get('label_probability_of_verdict', float('nan')):.2f},"
        f" {100 * d.verdict.get('agreeing_windows', float('nan')):.0f} % of windows agree)</p><table border=1 cellpadding=4><tr><th>propeller</th><th>PX4 rotor</th>"
        f"<th>P(faulty)</th><th>verdict</th></tr>{rows}</table>"
    )
    segs = "".join(
        f"<li>{s['start_boot_s']:.1f} - {s['stop_boot_s']:.1f} s boot time ({s['steps']} steps)</li>" for s in d.segments
    )
    warns = "".join(f"<li>{e(w)}</li>" for w in d.warnings) or "<li>none</li>"
    return (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>propwatch: {e(Path(d.source).name)}</title></head>"
        f"<body><h1>propwatch diagnosis</h1><p>{e(d.source)}</p>{verdict}"
        f"<h2>Airborne segments used</h2><ul>{segs or '<li>none</li>'}</ul>"
        f"<h2>Warnings</h2><ul>{warns}</ul>"
        f"<h2>Timeline and signals</h2><img src='{e(png_name)}' alt='timeline and signals'></body></html>"
    )


def write_report(d: Diagnosis, table: FlightTable, out_dir: Path) -> Path:
    """Write ``<log>.png`` and ``<log>.html`` into ``out_dir``; return the HTML path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = _stem(d.source, out_dir)
    png = out_dir / f"{stem}.png"
    plot(d, table, png)
    page_path = out_dir / f"{stem}.html"
    page_path.write_text(page(d, png.name), encoding="utf-8")
    return page_path
