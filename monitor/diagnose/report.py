"""``--report DIR``: one PNG (probability timeline and the signals) and one HTML page per log.

matplotlib is imported here only (Agg backend, no display needed).
"""

from __future__ import annotations

import html
import re
from pathlib import Path

import numpy as np

from monitor.diagnose.engine import Diagnosis
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


def plot(d: Diagnosis, table: FlightTable, png: Path) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise PropwatchError("--report needs matplotlib (pip install 'propwatch[logs]')") from exc
    t = table.timestamp_us / US_PER_S
    fig, ax = plt.subplots(4, 1, figsize=(11, 10), sharex=True)
    names = table.motor_names
    if d.timeline:
        tl = np.asarray(d.timeline["fault_probability"])
        for i in range(4):
            ax[0].plot(d.timeline["t_boot_s"], tl[:, i], ".-", ms=2, lw=0.8, label=f"propeller {i + 1} ({names[i]})")
    ax[0].set_ylim(-0.02, 1.02)
    ax[0].set_ylabel("P(faulty)")
    ax[0].legend(loc="upper right", fontsize=8)
    title = (
        "no verdict: " + (d.reason or "")
        if d.verdict is None
        else f"label {d.verdict['label']}, faulty {d.verdict['faulty_propellers'] or 'none'}"
    )
    ax[0].set_title(f"{Path(d.source).name}: {title}", fontsize=10)
    rpm_known = np.isfinite(table.motor_rpm).any()
    motor = table.motor_rpm if rpm_known else table.motor_cmd
    for i in range(4):
        ax[1].plot(t, motor[:, i], lw=0.7, label=f"{i + 1} ({names[i]})")
    ax[1].set_ylabel("target RPM" if rpm_known else f"command ({table.extras.get('motor_cmd_unit', '')})")
    ax[1].legend(loc="upper right", fontsize=8)
    for name, lab in (("roll_rad", "roll"), ("pitch_rad", "pitch"), ("yaw_rad", "yaw")):
        ax[2].plot(t, np.rad2deg(getattr(table, name)), lw=0.7, label=lab)
    ax[2].set_ylabel("attitude (deg)")
    ax[2].legend(loc="upper right", fontsize=8)
    for name, lab in (("roll_rate_rad_s", "roll rate"), ("pitch_rate_rad_s", "pitch rate"), ("yaw_rate_rad_s", "yaw rate")):
        ax[3].plot(t, np.rad2deg(getattr(table, name)), lw=0.7, label=lab)
    ax[3].set_ylabel("body rate (deg/s)")
    ax[3].set_xlabel("autopilot boot time (s)")
    ax[3].legend(loc="upper right", fontsize=8)
    for a in ax:
        for s in d.segments:
            a.axvspan(s["start_boot_s"], s["stop_boot_s"], color="tab:green", alpha=0.08, lw=0)
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    plt.close(fig)


def page(d: Diagnosis, png_name: str) -> str:
    e = html.escape
    rows = "".join(
        f"<tr><td>{p['propeller']}</td><td>{e(p['name'])}</td><td>{p['fault_probability']:.3f}</td>"
        f"<td>{'FAULTY' if p['faulty'] else 'ok'}</td></tr>"
        for p in d.propellers
    )
    verdict = (
        f"<p><b>No verdict:</b> {e(d.reason or '')}</p>"
        if d.verdict is None
        else f"<p><b>Label {d.verdict['label']}</b>, faulty propellers: {d.verdict['faulty_propellers'] or 'none'}"
        f" ({d.windows} windows)</p><table border=1 cellpadding=4><tr><th>propeller (PX4)</th><th>name</th>"
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
