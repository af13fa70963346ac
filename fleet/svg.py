"""A small self-contained SVG line chart (no JavaScript, no CDN): points over flights, optional ± bands and links."""

from __future__ import annotations

import html
import math
from dataclasses import dataclass

import numpy as np

# Colour per propeller (PX4 rotor order), matplotlib's tab10 first four.
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728")


@dataclass(frozen=True)
class Series:
    name: str
    ys: tuple[float | None, ...]  # None: no value for that flight
    color: str
    band: tuple[tuple[float | None, ...], tuple[float | None, ...]] | None = None  # (low, high) per point


def _fmt(v: float) -> str:
    return f"{v:.1f}"


def line_chart(
    series: list[Series],
    x_labels: list[str],
    title: str,
    y_label: str,
    y_range: tuple[float, float] | None = None,
    links: list[str | None] | None = None,
    width: int = 760,
    height: int = 280,
    css_class: str = "chart",
    x_label: str = "flight (date UTC)",
    marks: tuple[tuple[float, str], ...] = (),
    points: bool = True,
) -> str:
    """An inline ``<svg>``: x = flight index (labelled ``x_labels``), one polyline + markers per series."""
    e = html.escape
    n = len(x_labels)
    left, right, top, bottom = 56, 130, 28, 52
    pw, ph = width - left - right, height - top - bottom
    values = [y for s in series for y in s.ys if y is not None and math.isfinite(y)]
    if y_range is None:
        lo, hi = (min(values), max(values)) if values else (0.0, 1.0)
        pad = 0.1 * (hi - lo) if hi > lo else 0.05
        y_range = (lo - pad, hi + pad)
    y0, y1 = y_range

    def px(i: int) -> float:
        return left + (pw * (i + 0.5) / n if n else 0)

    def py(y: float) -> float:
        return top + ph * (1 - (min(max(y, y0), y1) - y0) / (y1 - y0))

    out = [
        f'<svg class="{css_class}" xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" role="img" aria-label="{e(title)}">',
        f"<title>{e(title)}</title>",
        f'<text x="{left}" y="16" font-size="13" font-weight="bold">{e(title)}</text>',
        f'<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" stroke="#999"/>',
    ]
    for k in range(5):
        y = y0 + (y1 - y0) * k / 4
        out.append(f'<line x1="{left}" x2="{left + pw}" y1="{_fmt(py(y))}" y2="{_fmt(py(y))}" stroke="#eee"/>')
        out.append(f'<text x="{left - 6}" y="{_fmt(py(y) + 4)}" font-size="11" text-anchor="end">{y:.2f}</text>')
    out.append(
        f'<text x="14" y="{top + ph / 2:.0f}" font-size="11" transform="rotate(-90 14 {top + ph / 2:.0f})" '
        f'text-anchor="middle">{e(y_label)}</text>'
    )
    step = max(1, math.ceil(n / 12))
    for i in range(0, n, step):
        out.append(f'<text x="{_fmt(px(i))}" y="{top + ph + 16}" font-size="10" text-anchor="middle">{e(x_labels[i])}</text>')
    out.append(f'<text x="{left + pw / 2:.0f}" y="{height - 8}" font-size="11" text-anchor="middle">{e(x_label)}</text>')
    for i, what in marks:  # a moment to point at (x in point index units, fractional allowed): a red line
        x = left + (pw * (i + 0.5) / n if n else 0)
        out.append(
            f'<line class="mark" x1="{_fmt(x)}" x2="{_fmt(x)}" y1="{top}" y2="{top + ph}" stroke="#c00" stroke-width="2"/>'
        )
        out.append(f'<text x="{_fmt(x + 4)}" y="{top + 12}" font-size="11" fill="#c00">{e(what)}</text>')
    xs = [_fmt(px(i)) for i in range(n)]  # every series shares the x positions
    for k, s in enumerate(series):
        if s.band is not None:
            pts = [(i, lo_, hi_) for i, (lo_, hi_) in enumerate(zip(*s.band)) if lo_ is not None and hi_ is not None]
            if len(pts) >= 2:
                poly = [f"{_fmt(px(i))},{_fmt(py(h))}" for i, _, h in pts] + [
                    f"{_fmt(px(i))},{_fmt(py(lo_))}" for i, lo_, _ in reversed(pts)
                ]
                out.append(f'<polygon points="{" ".join(poly)}" fill="{s.color}" fill-opacity="0.15" stroke="none"/>')
        pts = [(i, y) for i, y in enumerate(s.ys) if y is not None and math.isfinite(y)]
        if len(pts) >= 2:
            idx, yv = zip(*pts)
            ypx = np.round(top + ph * (1 - (np.clip(yv, y0, y1) - y0) / (y1 - y0)), 1).tolist()
            xy = " ".join(map("{},{}".format, [xs[i] for i in idx], ypx))
            out.append(
                f'<polyline class="series" data-name="{e(s.name)}" points="{xy}" fill="none" stroke="{s.color}" stroke-width="1.6"/>'
            )
        for i, y in pts if points else ():  # a marker (with its value) per point; a long timeline draws lines only
            dot = (
                f'<circle class="point" cx="{_fmt(px(i))}" cy="{_fmt(py(y))}" r="3.2" fill="{s.color}">'
                f"<title>{e(s.name)}: {y:.3f} ({e(x_labels[i])})</title></circle>"
            )
            href = links[i] if links else None
            out.append(f'<a href="{e(href)}">{dot}</a>' if href else dot)
        ly = top + 14 + 18 * k
        out.append(f'<rect x="{left + pw + 12}" y="{ly - 9}" width="12" height="10" fill="{s.color}"/>')
        out.append(f'<text x="{left + pw + 30}" y="{ly}" font-size="11">{e(s.name)}</text>')
    out.append("</svg>")
    return "\n".join(out)
