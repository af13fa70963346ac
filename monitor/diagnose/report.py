"""``--report DIR``: one PNG and one HTML page per log, both rendering the verdict (``monitor.diagnose.verdict``).

The picture, for a pilot: the verdict's headline and next step as its title; each rotor's share of the total
thrust over the flight against its normal band; the fault classifier's probability of damage (evidence, named as
such); the motor outputs and attitude; the moment the evidence changed; and the hypothesis sets the verdict
could not tell apart. Times are seconds after take-off. matplotlib is imported here only (Agg backend).
"""

from __future__ import annotations

import html
import json
import re
import textwrap
from pathlib import Path

import numpy as np

from monitor.decision.rotor_share import BASELINE_S, SHARE_AVERAGE_S
from monitor.diagnose.engine import Diagnosis
from monitor.diagnose.verdict import POSITION, Verdict, flight_seconds, set_words, verdict_of
from monitor.errors import PropwatchError
from monitor.flight import FlightTable
from monitor.resample import US_PER_S

# Half-width of a rotor's normal thrust-share band around the flight's own first 10 s: 99.9 % of healthy
# flights' 2-s shares stay within 0.032 of that start (monitor/decision/rotor_share.py's SHARE_SIGMA note,
# measured by `bench/alerts_flights.py --share-spread`).
SHARE_BAND = 0.032
# The verdict's FAULTY level on the classifier's P(faulty) (DecisionConfig.faulty_probability), drawn for reference.
FLAG_LEVEL = 0.9
STATUS = {"replace": "REPLACE", "inspect": "INSPECT", "ok": "ok", "not judged": "not judged"}
COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple")


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


def broken_at_gaps(t_s: np.ndarray, y: np.ndarray, max_step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)`` with a NaN row inserted wherever consecutive points are more than ``max_step_s`` apart,
    so a line is not drawn across a landed gap."""
    t_s, y = np.asarray(t_s, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if len(t_s) < 2:
        return t_s, y
    cut = np.flatnonzero(np.diff(t_s) > max_step_s * 1.5) + 1
    return np.insert(t_s, cut, np.nan), np.insert(y, cut, np.nan, axis=0)


def thrust_shares(table: FlightTable) -> tuple[np.ndarray, np.ndarray | None]:
    """((T, 4) each rotor's share of the total thrust, omega^2 / sum omega^2, as a 2-s running mean, NaN on the
    ground; (4, 2) its normal band: the mean of the flight's first 10 s airborne +- ``SHARE_BAND``, or None
    where the flight has fewer than 10 s airborne)."""
    rpm = np.asarray(table.motor_rpm, dtype=np.float64)
    if not np.isfinite(rpm).any():
        rpm = np.asarray(table.motor_cmd, dtype=np.float64)  # commands when no RPM: still ordered like thrust
    w2 = rpm**2
    share = w2 / np.sum(w2, axis=1, keepdims=True)
    share[~np.asarray(table.airborne, bool)] = np.nan
    k = max(1, int(round(SHARE_AVERAGE_S * table.rate_hz)))
    ok = np.isfinite(share).all(axis=1)
    c = np.concatenate([np.zeros((1, 4)), np.cumsum(np.where(ok[:, None], share, 0.0), axis=0)])
    n = np.concatenate([[0], np.cumsum(ok)])
    i = np.arange(len(share))
    lo = np.maximum(i + 1 - k, 0)
    cnt = n[i + 1] - n[lo]
    mean = (c[i + 1] - c[lo]) / np.maximum(cnt, 1)[:, None]
    mean[(cnt < k) | ~ok] = np.nan
    first = np.flatnonzero(np.isfinite(mean).all(axis=1))
    need = int(BASELINE_S * table.rate_hz)
    if len(first) < need:
        return mean, None
    start = mean[first[:need]].mean(axis=0)
    return mean, np.stack([start - SHARE_BAND, start + SHARE_BAND], axis=1)


def memory_band(share: np.ndarray, memory: dict | None) -> np.ndarray | None:
    """(4, 2) each rotor's normal thrust-share band from the vehicle memory's comparison (``monitor.memory.judge``:
    ``deviation``, the flight's mean share minus the vehicle's normal, in shares that sum to 4, and
    ``deviation_sigma``, the same in its healthy spreads): normal +- 3 spreads, as shares of 1; None without one."""
    dev, sig = (memory or {}).get("deviation"), (memory or {}).get("deviation_sigma")
    if not dev or not sig or not np.isfinite(share).any():
        return None
    dev, sig = np.asarray(dev, dtype=np.float64) / 4, np.asarray(sig, dtype=np.float64)
    spread = np.abs(dev / np.where(sig == 0, np.nan, sig))
    normal = np.nanmean(share, axis=0) - dev
    if not np.isfinite(normal).all() or not np.isfinite(spread).all():
        return None
    return np.stack([normal - 3 * spread, normal + 3 * spread], axis=1)


def _not_logged(ax, what: str, why: str = "not logged") -> None:
    ax.set_yticks([])
    ax.text(0.5, 0.5, f"{what}: {why}", transform=ax.transAxes, ha="center", va="center", color="0.4", fontsize=11)


# Figure fractions of the 12-inch report figure: a 13-pt headline line, a 9.5-pt next-step line (x 1.2 line
# spacing), and the first panel's two 8-pt caption lines with their padding.
HEADLINE_LINE = 13 * 1.2 / 72 / 12
NEXT_LINE = 9.5 * 1.2 / 72 / 12
CAPTION_ABOVE = 0.04


def figure(v: Verdict, d: Diagnosis, table: FlightTable, memory: dict | None = None):
    """The report's matplotlib figure (the caller saves and closes it). ``memory``: the vehicle memory's
    comparison (the JSON's ``baseline``), whose normal then gives the share bands (``memory_band``)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise PropwatchError("--report needs matplotlib (pip install matplotlib)") from exc
    t_boot = np.asarray(table.timestamp_us) / US_PER_S
    # seconds after take-off; a log that never took off counts from its own start
    zero = v.takeoff_boot_s if v.takeoff_boot_s is not None else (float(t_boot[0]) if len(t_boot) else 0.0)
    t = t_boot - zero
    fig = plt.figure(figsize=(12, 12))
    headline = textwrap.wrap(v.headline, 95)
    next_step = textwrap.wrap("Next step: " + v.next_step, 140)
    # Stacked from the top, in figure fractions of this 12-inch figure: the headline's lines (13 pt), the next step's
    # (9.5 pt), then the first panel's two-line caption above its axes, so none is drawn over another.
    next_y = 0.985 - HEADLINE_LINE * len(headline) - 0.006
    top = next_y - NEXT_LINE * len(next_step) - CAPTION_ABOVE
    gs = fig.add_gridspec(
        7,
        2,
        width_ratios=(3.2, 1),
        height_ratios=(0.7, 0.7, 0.7, 0.7, 1.2, 1.1, 1.0),
        hspace=0.45,
        wspace=0.12,
        top=top,
        bottom=0.05,
        left=0.07,
        right=0.98,
    )
    ax = [fig.add_subplot(gs[0, 0])]
    ax += [fig.add_subplot(gs[k, 0], sharex=ax[0]) for k in range(1, 7)]
    names = [f"{v.names[i]} {POSITION[i + 1]}" for i in range(4)]
    colour = {
        "damaged": "tab:red",
        "motor": "tab:red",
        "inspect": "darkorange",
        "imbalance": "darkorange",
        "healthy": "tab:green",
    }
    fig.suptitle("\n".join(headline), x=0.07, y=0.985, ha="left", fontsize=13, weight="bold", color=colour.get(v.state, "0.2"))
    fig._suptitle.set_gid("verdict-headline")
    nxt = fig.text(0.07, next_y, "\n".join(next_step), fontsize=9.5, va="top")
    nxt.set_gid("verdict-next")
    share, band = thrust_shares(table)
    vehicle_band = memory_band(share, memory)
    basis = (
        f" ({v.compared_with}, +-3 of its spreads)"
        if vehicle_band is not None
        else " (this flight's first 10 s +-3 points: blind to damage from take-off)"
        if band is not None
        else " (flight too short to learn it)"
    )
    band = vehicle_band if vehicle_band is not None else band
    ax[0].set_title(
        "each rotor's share of the total thrust (2-s mean); shaded: its normal band\n" + basis.strip(" ()"),
        fontsize=8,
        loc="left",
    )
    for i in range(4):
        a = ax[i]
        if np.isfinite(share[:, i]).any():
            a.plot(t, 100 * share[:, i], lw=1.0, color=COLOURS[i])
            if band is not None:
                a.axhspan(100 * band[i, 0], 100 * band[i, 1], color=COLOURS[i], alpha=0.15, lw=0)
            lo, hi = np.nanmin(share[:, i]), np.nanmax(share[:, i])
            if band is not None:
                lo, hi = min(lo, band[i, 0]), max(hi, band[i, 1])
            a.set_ylim(100 * lo - 1, 100 * hi + 1)
        else:
            if not np.isfinite(table.motor_cmd).any():
                _not_logged(a, "motor outputs")
            elif table.airborne.any():  # airborne, but not for one 2-s mean (the text's "airborne 0-1 s")
                _not_logged(a, "airborne too briefly for a 2-s mean: the share", "not drawn")
            else:
                _not_logged(a, "never airborne: the share", "not drawn")
        a.text(
            0.005,
            0.92,
            f"{names[i]}: {STATUS[v.status(i + 1)]}",
            transform=a.transAxes,
            gid=f"verdict-rotor-{i + 1}",
            fontsize=8,
            va="top",
            color=COLOURS[i],
            weight="bold",
        )
        a.set_ylabel("%", fontsize=8)
        a.tick_params(labelsize=7)
        if i < 3:
            a.tick_params(labelbottom=False)
    tl = d.timeline or {}
    if tl.get("t_boot_s"):
        step_s = d.hop_steps / table.rate_hz
        tt, p = broken_at_gaps(flight_seconds(np.asarray(tl["t_boot_s"]), v.takeoff_boot_s), tl["fault_probability"], step_s)
        for i in range(4):
            ax[4].plot(tt, 100 * p[:, i], ".-", ms=2, lw=0.8, color=COLOURS[i], label=names[i])
        ax[4].axhline(100 * FLAG_LEVEL, color="0.4", ls=":", lw=0.8)
        ax[4].text(0.005, 100 * FLAG_LEVEL, " flag level", transform=ax[4].get_yaxis_transform(), fontsize=7, va="bottom")
    else:
        _not_logged(ax[4], "no stretch of flight classified, so the classifier's probability")
    ax[4].set_ylim(-2, 102)
    ax[4].set_ylabel("P(damaged) %")
    ax[4].set_title("evidence: the fault classifier's probability of damage per 5 s of flight", fontsize=9, loc="left")
    rpm_known = np.isfinite(table.motor_rpm).any()
    motor = table.motor_rpm if rpm_known else table.motor_cmd
    _signals(ax[5], t, [(motor[:, i], names[i]) for i in range(4)], "motor outputs")
    ax[5].set_ylabel("target RPM" if rpm_known else f"command ({table.extras.get('motor_cmd_unit', '')})")
    ax[5].set_title("motor outputs", fontsize=9, loc="left")
    attitude = [
        (np.rad2deg(table.roll_rad), "roll"),
        (np.rad2deg(table.pitch_rad), "pitch"),
    ]
    _signals(ax[6], t, attitude, "attitude")
    ax[6].set_ylabel("degrees")
    ax[6].set_title("attitude", fontsize=9, loc="left")
    ax[6].set_xlabel("seconds after take-off" if v.takeoff_boot_s is not None else "seconds from the start of the log")
    segs = [
        (flight_seconds(s["start_boot_s"], v.takeoff_boot_s), flight_seconds(s["stop_boot_s"], v.takeoff_boot_s))
        for s in d.segments
    ]
    if segs:
        ax[0].set_xlim(min(a for a, _ in segs) - 3, max(b for _, b in segs) + 3)
    for a in ax:
        for s0, s1 in segs:
            a.axvspan(s0, s1, color="tab:green", alpha=0.05, lw=0)
        if v.change_s is not None:
            a.axvline(v.change_s, color="tab:red", lw=1.5)
        a.grid(alpha=0.3)
    for a in ax[:3]:
        a.tick_params(labelbottom=False)
    if v.change_s is not None:
        ax[0].text(
            v.change_s,
            1.0,
            f" evidence changed at {v.change_s:.0f} s",
            color="tab:red",
            fontsize=8,
            transform=ax[0].get_xaxis_transform(),
            va="bottom",
        )
    _sets_panel(fig.add_subplot(gs[0:4, 1]), v, d)
    _evidence_panel(fig.add_subplot(gs[4:7, 1]), v)
    return fig


def _sets_panel(ax, v: Verdict, d: Diagnosis) -> None:
    """The hypothesis sets the verdict names, as bars of their probability (equal where none is stated)."""
    probs = {tuple(h["faulty_propellers"]): h.get("probability") for h in (d.hypotheses or []) if "faulty_propellers" in h}
    sets = list(v.sets)[:8]
    ax.set_title("what the damage could be", fontsize=9, loc="left")
    if not sets:
        ax.axis("off")
        ax.text(0.0, 0.9, "no verdict", fontsize=10, transform=ax.transAxes)
        return
    stated = [probs.get(tuple(s)) for s in sets]
    y = np.arange(len(sets))[::-1]
    ax.barh(y, [100 * (1.0 / len(sets) if x is None else x) for x in stated], color="0.8")
    ax.set_yticks([])
    for yy, s, x in zip(y, sets, stated):
        # a set without a stated probability (the in-flight rule's ranking, or a verdict without a set rule)
        # is named without one, never given a made-up share
        what = f"{100 * x:.0f} %" if x is not None else "the only one" if len(sets) == 1 else "ranked, not weighed"
        ax.text(1, yy, f"{set_words(s, list(v.names))}: {what}", va="center", fontsize=8, gid="verdict-set")
    ax.set_xlim(0, 100)
    ax.set_xlabel("probability (%)", fontsize=8)
    if len(v.sets) > len(sets):
        ax.text(0.98, 0.02, f"+{len(v.sets) - len(sets)} more", transform=ax.transAxes, ha="right", fontsize=8)


def _evidence_panel(ax, v: Verdict) -> None:
    ax.axis("off")
    lines = ([f"Why not sure: {v.why}"] if v.why else []) + list(v.evidence)
    if v.compared_with:
        lines.append(f"Compared {v.compared_with}.")
    text = "\n".join("\n".join(textwrap.wrap(line, 44)) for line in lines)
    ax.text(0.0, 1.0, text, va="top", fontsize=7.5, transform=ax.transAxes)


def _signals(ax, t: np.ndarray, series: list[tuple[np.ndarray, str]], what: str) -> None:
    """Plot each (values, label); a series never measured is named as not logged instead of drawn empty."""
    missing = [lab for y, lab in series if not np.isfinite(y).any()]
    for k, (y, lab) in enumerate(series):
        if np.isfinite(y).any():
            ax.plot(t, y, lw=0.7, label=lab, color=COLOURS[k % 4] if len(series) == 4 else None)
    if len(missing) == len(series):
        _not_logged(ax, what)
    else:
        if missing:
            ax.text(0.01, 0.04, "not logged: " + ", ".join(missing), transform=ax.transAxes, color="0.4", fontsize=8)
        ax.legend(loc="upper right", fontsize=8, ncol=4)


def plot(v: Verdict, d: Diagnosis, table: FlightTable, png: Path, memory: dict | None = None) -> None:
    import matplotlib.pyplot as plt

    fig = figure(v, d, table, memory)
    # What the picture states, as drawn, also in the PNG's text chunk: a reader (and the agreement test) checks it.
    fig.savefig(png, dpi=80, metadata={"Title": v.headline, "Description": json.dumps(drawn_verdict(fig))})
    plt.close(fig)


def drawn_verdict(fig) -> dict:
    """The verdict's words as the figure draws them: headline, next step, each rotor's status label, the sets."""
    texts = [t for t in fig.findobj(lambda a: (a.get_gid() or "").startswith("verdict-")) if hasattr(t, "get_text")]

    def one(gid: str) -> list[str]:
        return [" ".join(t.get_text().split()) for t in texts if t.get_gid() == gid]

    return {
        "headline": one("verdict-headline")[0],
        "next_step": one("verdict-next")[0].removeprefix("Next step: "),
        "rotors": [one(f"verdict-rotor-{i}")[0] for i in range(1, 5)],
        "sets": one("verdict-set"),
    }


def verdict_html(v: Verdict) -> str:
    """The verdict block every HTML page shows (diagnose's report and the fleet's flight page): the same
    headline, next step, why and evidence as the text output; ``data-*`` attributes state it for machines."""
    e = html.escape
    rows = "".join(
        f"<tr class='{v.status(i)}'><td>{e(v.names[i - 1])}</td><td>{POSITION[i]}</td><td>{STATUS[v.status(i)]}</td></tr>"
        for i in range(1, 5)
    )
    table = (
        f"<table class='props'><tr><th>propeller</th><th>where</th><th>what to do</th></tr>{rows}</table>"
        if v.state not in ("no verdict", "unreadable")
        else ""
    )
    why = f"<p><b>Why not sure:</b> {e(v.why)}</p>" if v.why else ""
    compared = f"<p>Compared {e(v.compared_with)}.</p>" if v.compared_with else ""
    evidence = "".join(f"<li>{e(x)}</li>" for x in v.evidence)
    return (
        f"<section class='verdict {v.state.replace(' ', '-')}' data-state='{e(v.state)}' data-confidence='{e(v.confidence)}'"
        f" data-propellers='{','.join(map(str, v.propellers))}' data-replace='{','.join(map(str, v.replace))}'>"
        f"<h2 class='headline'>{e(v.headline)}</h2><p class='next'><b>Next step:</b> {e(v.next_step)}</p>{why}{compared}"
        f"{table}" + (f"<h3>Evidence</h3><ul>{evidence}</ul>" if evidence else "") + "</section>"
    )


STYLE = (
    "body{font-family:sans-serif;max-width:1000px;margin:1em auto;padding:0 1em}"
    ".damaged .headline{color:#b00}.inspect .headline,.imbalance .headline{color:#b60}.healthy .headline{color:#070}"
    "table.props td,table.props th{padding:2px 10px;text-align:left}tr.replace{background:#fdd}tr.inspect{background:#fed}"
    "img{max-width:100%}"
)


def page(v: Verdict, d: Diagnosis, png_name: str) -> str:
    e = html.escape
    segs = "".join(
        f"<li>{flight_seconds(s['start_boot_s'], v.takeoff_boot_s):.0f} - {flight_seconds(s['stop_boot_s'], v.takeoff_boot_s):.0f}"
        " s after take-off</li>"
        for s in d.segments
    )
    warns = "".join(f"<li>{e(w)}</li>" for w in d.warnings) or "<li>none</li>"
    return (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>propwatch: {e(Path(d.source).name)}</title>"
        f"<style>{STYLE}</style></head><body><h1>propwatch: {e(Path(d.source).name)}</h1><p>{e(d.source)}</p>"
        f"{verdict_html(v)}<h3>The flight</h3><img src='{e(png_name)}' alt='thrust shares, evidence and signals'>"
        f"<h3>Airborne</h3><ul>{segs or '<li>none</li>'}</ul><h3>Warnings</h3><ul>{warns}</ul>"
        "<p>Every figure behind this verdict: <code>propwatch diagnose --json</code> (docs/diagnose-json.md).</p>"
        "</body></html>"
    )


def write_report(d: Diagnosis, table: FlightTable, out_dir: Path, result: dict | None = None) -> Path:
    """Write ``<log>.png`` and ``<log>.html`` into ``out_dir``; return the HTML path. ``result``: the ``--json``
    object when the caller has it (its ``baseline`` gives the verdict's "compared with"), else ``d.to_json()``."""
    v = verdict_of(result if result is not None else d.to_json())
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = _stem(d.source, out_dir)
    png = out_dir / f"{stem}.png"
    plot(v, d, table, png, (result or {}).get("baseline"))
    page_path = out_dir / f"{stem}.html"
    page_path.write_text(page(v, d, png.name), encoding="utf-8")
    return page_path
