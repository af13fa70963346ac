"""``fleet report``: the fleet database -> a static web site (no JavaScript library, no CDN).

    site/index.html              every vehicle: latest per-propeller health, flags
    site/vehicles/<id>.html      trend of each rotor's P(faulty) and effectiveness over flights and dates
    site/flights/<hash>.html     one flight's diagnosis: verdict, propeller table, timeline plot, warnings
    site/problems.html           logs without a verdict and logs that could not be read, with the reason

Flags on the index (per vehicle):
- *recent faults*: a propeller was called faulty in any of its last ``RECENT_FLIGHTS`` flights with a verdict;
- *effectiveness trending down*: over its last ``TREND_FLIGHTS`` flights that carry rotor
  effectiveness (at least ``TREND_MIN_FLIGHTS``), the least-squares line of a rotor's
  effectiveness against flight number falls by ``TREND_DROP`` or more from first to last.
The site is written into a temporary folder and swapped in, so a reader never sees half a site.
"""

from __future__ import annotations

import dataclasses
import hashlib
import html
import json
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fleet.errors import FleetError
from fleet.schema import open_db
from fleet.svg import COLORS, Series, line_chart
from monitor.diagnose.verdict import Verdict, compared_with_words, verdict_of

RECENT_FLIGHTS = 3
TREND_FLIGHTS = 10
TREND_MIN_FLIGHTS = 3
TREND_DROP = 0.05  # effectiveness is 1.0 for an intact rotor: 5 points lost across the window
MARKER = ".propwatch-fleet-site"
UNIDENTIFIED = "(unidentified)"

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:1.5em;color:#222;max-width:1100px}
table{border-collapse:collapse;margin:0.6em 0}th,td{border:1px solid #ccc;padding:3px 7px;font-size:13px;text-align:left}
th{background:#f3f3f3}td.num{text-align:right;font-variant-numeric:tabular-nums}
.flag{color:#a40000;font-weight:bold}.ok{color:#2a7a2a}.muted{color:#777}
nav a{margin-right:1em}svg.chart{display:block;margin:0.8em 0;background:#fff}
"""


@dataclass
class Vehicle:
    vid: str
    slug: str
    flights: list[dict] = field(default_factory=list)  # by start time

    @property
    def judged(self) -> list[dict]:
        return [f for f in self.flights if f["status"] == "ok"]

    def flags(self) -> list[str]:
        out = []
        recent = self.judged[-RECENT_FLIGHTS:]
        hits: dict[int, int] = {}
        for f in recent:
            for p in f["faulty_propellers"] or []:
                hits[p] = hits.get(p, 0) + 1
        for p, k in sorted(hits.items()):
            plural = "s" if len(recent) != 1 else ""
            out.append(f"propeller {self.prop_name(p)} faulty in {k} of the last {len(recent)} flight{plural}")
        for p, drop, n in effectiveness_trends(self.flights):
            out.append(f"propeller {self.prop_name(p)} effectiveness down {100 * drop:.1f} points over {n} flights")
        return out

    def prop_name(self, p: int) -> str:
        names = next((f["propeller_names"] for f in reversed(self.flights) if f["propeller_names"]), None)
        return f"{p} ({names[p - 1]})" if names and names[p - 1] != str(p) else str(p)


def _probability(h: dict) -> str:
    """A hypothesis' probability, or what stands instead (the in-flight rule ranks its sets without weighing them)."""
    p = h.get("probability")
    return f"{float(p):.3f}" if p is not None else html.escape(str(h.get("evidence") or h.get("cause") or "-"))


def _day(t) -> str | None:
    """A date column (DATE, TIMESTAMP or text) as ``YYYY-MM-DD``; None stays None."""
    if t is None:
        return None
    return t.strftime("%Y-%m-%d") if hasattr(t, "strftime") else str(t)[:10]


def row_verdict(f: dict) -> Verdict:
    """The verdict of one database row: its stored diagnosis through ``monitor.diagnose.verdict``, exactly as
    ``propwatch diagnose`` prints it, with "compared with" from the vehicle memory's columns (``baseline_flights``,
    ``compared_with_first``, ``compared_with_last``; absent or NULL: none)."""
    if f.get("diagnosis"):
        res = json.loads(f["diagnosis"])
    else:
        res = {"log": f.get("path"), "error": f.get("error") or "not diagnosed"}
    v = verdict_of(res)
    said = compared_with_words(f.get("baseline_flights"), _day(f.get("compared_with_first")), _day(f.get("compared_with_last")))
    return dataclasses.replace(v, compared_with=said) if said else v


def verdict_cells(v: Verdict) -> str:
    """A flight's verdict as table cells (headline, confidence, next step); ``data-*`` state it for machines."""
    e = html.escape
    return (
        f"<td class='verdict {v.state.replace(' ', '-')}' data-state='{e(v.state)}' data-confidence='{e(v.confidence)}'"
        f" data-propellers='{','.join(map(str, v.propellers))}' data-replace='{','.join(map(str, v.replace))}'>"
        f"{e(v.headline)}</td><td>{e(v.confidence)}</td><td class='next'>{e(v.next_step)}</td>"
    )


def effectiveness_trends(flights: list[dict]) -> list[tuple[int, float, int]]:
    """(propeller, fitted drop, flights used) for each rotor whose effectiveness trends down by TREND_DROP or more."""
    eff = [f["rotor_effectiveness"] for f in flights if f["rotor_effectiveness"] is not None][-TREND_FLIGHTS:]
    if len(eff) < TREND_MIN_FLIGHTS:
        return []
    a = np.asarray(eff, dtype=np.float64)
    x = np.arange(len(a), dtype=np.float64)
    out = []
    for p in range(a.shape[1]):
        ok = np.isfinite(a[:, p])
        if ok.sum() < TREND_MIN_FLIGHTS:
            continue
        slope = np.polyfit(x[ok], a[ok, p], 1)[0]
        drop = -slope * (x[ok][-1] - x[ok][0])
        if drop >= TREND_DROP:
            out.append((p + 1, float(drop), int(ok.sum())))
    return out


def slug(vid: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", vid)[:48] + "-" + hashlib.sha1(vid.encode()).hexdigest()[:8]


def load(db: str | Path) -> tuple[list[Vehicle], list[dict]]:
    con = open_db(db, read_only=True)
    try:
        cur = con.execute("SELECT * FROM flights ORDER BY vehicle_id NULLS LAST, start_time_utc NULLS LAST, path")
        names = [d[0] for d in cur.description]
        rows = [dict(zip(names, r)) for r in cur.fetchall()]
    finally:
        con.close()
    vehicles: dict[str, Vehicle] = {}
    for r in rows:
        vid = r["vehicle_id"] or UNIDENTIFIED
        vehicles.setdefault(vid, Vehicle(vid, slug(vid))).flights.append(r)
    return list(vehicles.values()), rows


def write_site(db: str | Path, out: str | Path) -> dict:
    """Write the site for ``db`` into ``out`` (replacing an earlier fleet site there); returns its paths."""
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not (out / MARKER).exists():
        raise FleetError(f"{out}: folder exists and is not a fleet site; give an empty or new folder")
    vehicles, rows = load(db)
    tmp = out.with_name(out.name + ".tmp-site")
    shutil.rmtree(tmp, ignore_errors=True)
    (tmp / "vehicles").mkdir(parents=True)
    (tmp / "flights").mkdir()
    (tmp / MARKER).write_text("written by propwatch fleet report\n", encoding="utf-8")
    (tmp / "index.html").write_text(index_page(vehicles, rows, str(db)), encoding="utf-8")
    (tmp / "problems.html").write_text(problems_page(rows), encoding="utf-8")
    for v in vehicles:
        (tmp / "vehicles" / f"{v.slug}.html").write_text(vehicle_page(v), encoding="utf-8")
        for f in v.flights:
            (tmp / "flights" / f"{f['log_hash'][:16]}.html").write_text(flight_page(f, v), encoding="utf-8")
    if out.exists():
        old = out.with_name(out.name + ".old-site")
        shutil.rmtree(old, ignore_errors=True)
        out.rename(old)
        tmp.rename(out)
        shutil.rmtree(old)
    else:
        tmp.rename(out)
    return {"index": str(out / "index.html"), "vehicles": len(vehicles), "flights": len(rows)}


def _page(title: str, body: str, depth: int, script: str = "") -> str:
    up = "../" * depth
    nav = f'<nav><a href="{up}index.html">fleet</a><a href="{up}problems.html">problem logs</a></nav>'
    return (
        f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<meta name='viewport' content='width=device-width'><style>{CSS}</style></head><body>{nav}"
        f"<h1>{html.escape(title)}</h1>{body}{script}</body></html>\n"
    )


def _date(f: dict) -> str:
    t = f["start_time_utc"]
    return t.strftime("%Y-%m-%d %H:%M") if t is not None else "?"


def _p_cells(ps, faulty=()) -> str:
    if ps is None:
        return "<td class='muted' colspan=4>no verdict</td>"
    cells = []
    for i, p in enumerate(ps):
        shade = f"rgba(214,39,40,{min(1.0, p):.2f})"
        bold = " class='num flag'" if (i + 1) in (faulty or ()) else " class='num'"
        cells.append(f"<td{bold} style='background:linear-gradient(90deg,{shade} {100 * p:.0f}%,transparent 0)'>{p:.3f}</td>")
    return "".join(cells)


def _eff_cells(eff) -> str:
    if eff is None:
        return "<td class='muted' colspan=4>not estimated</td>"
    return "".join(f"<td class='num'>{e:.3f}</td>" for e in eff)


FILTER_JS = """<script>
(function () {
  var box = document.getElementById('filter');
  var rows = document.querySelectorAll('#vehicles tbody tr');
  box.addEventListener('input', function () {
    var q = box.value.toLowerCase();
    rows.forEach(function (r) { r.style.display = r.textContent.toLowerCase().indexOf(q) >= 0 ? '' : 'none'; });
  });
  document.body.setAttribute('data-ready', String(rows.length));
})();
</script>"""


def index_page(vehicles: list[Vehicle], rows: list[dict], db: str) -> str:
    e = html.escape
    n_err = sum(r["status"] == "error" for r in rows)
    n_nov = sum(r["status"] == "no_verdict" for r in rows)
    order = sorted(vehicles, key=lambda v: (not v.flags(), v.vid == UNIDENTIFIED, v.vid))
    trs = []
    for v in order:
        last = v.judged[-1] if v.judged else None
        last_eff = next((f["rotor_effectiveness"] for f in reversed(v.flights) if f["rotor_effectiveness"] is not None), None)
        flags = v.flags()
        flag_html = "<br>".join(f"<span class='flag'>{e(x)}</span>" for x in flags) or "<span class='ok'>none</span>"
        trs.append(
            f"<tr><td><a href='vehicles/{v.slug}.html'>{e(v.vid)}</a></td><td class='num'>{len(v.flights)}</td>"
            f"<td>{e(_date(v.flights[-1]))}</td>"
            + (_p_cells(last["p_faulty"], last["faulty_propellers"]) if last else _p_cells(None))
            + _eff_cells(last_eff)
            + f"<td>{flag_html}</td></tr>"
        )
    body = (
        f"<p>{len(vehicles)} vehicles, {len(rows)} logs ({n_nov} without a verdict, {n_err} unreadable: "
        f"<a href='problems.html'>problem logs</a>). Database <code>{e(db)}</code>.</p>"
        "<p><label>filter vehicles <input id='filter' type='search' placeholder='id, date, flag...'></label></p>"
        "<table id='vehicles'><thead><tr><th rowspan=2>vehicle</th><th rowspan=2>logs</th><th rowspan=2>last log (UTC)</th>"
        "<th colspan=4>latest P(faulty), propeller 1-4 (PX4 order)</th><th colspan=4>latest rotor effectiveness 1-4</th>"
        "<th rowspan=2>flags</th></tr><tr>" + "<th>1</th><th>2</th><th>3</th><th>4</th>" * 2 + "</tr></thead>"
        f"<tbody>{''.join(trs)}</tbody></table>"
        f"<p class='muted'>Flags: a propeller called faulty in the last {RECENT_FLIGHTS} flights with a verdict; "
        f"a rotor's effectiveness falling by {TREND_DROP:.2f} or more along a line fitted over its last "
        f"{TREND_FLIGHTS} flights (at least {TREND_MIN_FLIGHTS}).</p>"
    )
    return _page("propwatch fleet", body, 0, FILTER_JS)


def vehicle_page(v: Vehicle) -> str:
    e = html.escape
    fl = v.flights
    labels = [(f["start_time_utc"].strftime("%m-%d") if f["start_time_utc"] else "?") for f in fl]
    links = [f"../flights/{f['log_hash'][:16]}.html" for f in fl]

    def col(key: str, i: int):
        return tuple((f[key][i] if f[key] is not None else None) for f in fl)

    p_series = [Series(f"propeller {v.prop_name(i + 1)}", col("p_faulty", i), COLORS[i]) for i in range(4)]
    charts = line_chart(p_series, labels, "P(faulty) per propeller over flights", "P(faulty)", (0.0, 1.0), links)
    if any(f["rotor_effectiveness"] is not None for f in fl):
        eff_series = []
        for i in range(4):
            mid, sd = col("rotor_effectiveness", i), col("rotor_effectiveness_std", i)
            band = (
                tuple(m - s if m is not None and s is not None else None for m, s in zip(mid, sd)),
                tuple(m + s if m is not None and s is not None else None for m, s in zip(mid, sd)),
            )
            eff_series.append(Series(f"rotor {v.prop_name(i + 1)}", mid, COLORS[i], band))
        charts += line_chart(
            eff_series, labels, "rotor effectiveness (1 = intact) over flights, band = ±1 std", "effectiveness", None, links
        )
    else:
        charts += "<p class='muted'>Rotor effectiveness: not estimated by the model that diagnosed these flights.</p>"
    flags = v.flags()
    rows = "".join(
        f"<tr><td><a href='../flights/{f['log_hash'][:16]}.html'>{e(_date(f))}</a></td><td>{e(Path(f['path']).name)}</td>"
        f"<td>{e(f['status'])}</td><td>{e(str(f['faulty_propellers'] if f['status'] == 'ok' else (f['error'] or '')))}</td>"
        + _p_cells(f["p_faulty"], f["faulty_propellers"])
        + "</tr>"
        for f in reversed(fl)
    )
    src = sorted({f["vehicle_id_source"] or "none" for f in fl})
    body = (
        f"<p>{len(fl)} logs; id from {e(', '.join(src))}.</p>"
        + ("<ul>" + "".join(f"<li class='flag'>{e(x)}</li>" for x in flags) + "</ul>" if flags else "<p class='ok'>No flags.</p>")
        + f"<div id='trend'>{charts}</div>"
        "<h2>Flights (newest first)</h2><table><tr><th>start (UTC)</th><th>file</th><th>status</th><th>faulty / reason</th>"
        f"<th>P1</th><th>P2</th><th>P3</th><th>P4</th></tr>{rows}</table>"
    )
    return _page(f"vehicle {v.vid}", body, 1)


def flight_page(f: dict, v: Vehicle) -> str:
    e = html.escape
    d = json.loads(f["diagnosis"]) if f["diagnosis"] else {}
    meta = [
        ("log", f["path"]),
        ("content sha256", f["log_hash"]),
        ("vehicle", f"{v.vid} ({f['vehicle_id_source'] or 'no id'})"),
        ("start (UTC)", f"{_date(f)} ({f['start_time_source'] or 'unknown'})"),
        ("duration / airborne", f"{f['duration_s'] or 0:.1f} s / {f['airborne_s'] or 0:.1f} s" if f["duration_s"] else "?"),
        ("format", f["format"] or "?"),
        ("model", f"{f['model_id'] or '?'} version {f['model_version'] or '?'}"),
        ("propwatch", f["propwatch_version"] or "?"),
    ]
    body = (
        f"<p><a href='../vehicles/{v.slug}.html'>vehicle {e(v.vid)}</a></p><table>"
        + "".join(f"<tr><th>{e(k)}</th><td>{e(str(val))}</td></tr>" for k, val in meta)
        + "</table>"
    )
    if f["status"] == "ok":
        names = f["propeller_names"] or ["1", "2", "3", "4"]
        eff, sd = f["rotor_effectiveness"], f["rotor_effectiveness_std"]
        rows = "".join(
            f"<tr><td>{i + 1}</td><td>{e(names[i])}</td><td class='num'>{f['p_faulty'][i]:.3f}</td>"
            f"<td>{'<b class=flag>FAULTY</b>' if (i + 1) in f['faulty_propellers'] else 'ok'}</td>"
            f"<td class='num'>{'' if eff is None else f'{eff[i]:.3f}'}{'' if sd is None else f' ± {sd[i]:.3f}'}</td></tr>"
            for i in range(4)
        )
        body += (
            f"<h2>Verdict: label {f['verdict_label']}, faulty propellers {e(str(f['faulty_propellers'] or 'none'))}</h2>"
            f"<p>{f['windows']} windows.</p><table><tr><th>propeller (PX4)</th><th>name</th><th>P(faulty)</th><th>verdict</th>"
            f"<th>effectiveness</th></tr>{rows}</table>"
        )
        if f["hypotheses"]:
            hyp = json.loads(f["hypotheses"])
            body += (
                "<h2>Hypotheses</h2><table><tr><th>faulty propellers</th><th>probability</th></tr>"
                + "".join(
                    f"<tr><td>{e(str(h.get('faulty_propellers')))}</td><td class='num'>{_probability(h)}</td></tr>" for h in hyp
                )
                + "</table>"
            )
        tl = d.get("timeline") or {}
        if tl.get("t_boot_s"):
            probs = np.asarray(tl["fault_probability"], dtype=np.float64)
            numbering = "vehicle's own numbering" if d.get("propeller_numbering") else "PX4 order"
            series = [Series(f"propeller {i + 1}", tuple(probs[:, i].tolist()), COLORS[i]) for i in range(4)]
            xl = [f"{t:.0f}" for t in tl["t_boot_s"]]
            body += line_chart(
                series, xl, f"P(faulty) per 5 s window ({numbering}); x: window end, s boot time", "P(faulty)", (0, 1)
            ).replace("flight (date UTC)", "window end (s, autopilot boot clock)")
    else:
        what = "No verdict" if f["status"] == "no_verdict" else "Unreadable log"
        body += f"<h2>{what}</h2><p class='flag'>{e(f['error'] or '')}</p>"
    fmt_arg = f" --format {f['format']}" if f["format"] not in (None, "tlog", "ulog", "dataflash") else ""
    body += (
        "<p class='muted'>Motor, attitude and rate signals of this flight: "
        f"<code>propwatch diagnose {e(f['path'])}{e(fmt_arg)} --report DIR</code> (the log itself is not kept here).</p>"
    )
    warns = f["warnings"] or []
    body += "<h2>Warnings</h2><ul>" + ("".join(f"<li>{e(w)}</li>" for w in warns) or "<li>none</li>") + "</ul>"
    segs = d.get("airborne_segments") or []
    if segs:
        body += (
            "<h2>Airborne segments</h2><ul>"
            + "".join(f"<li>{s['start_boot_s']:.1f} - {s['stop_boot_s']:.1f} s boot time ({s['steps']} steps)</li>" for s in segs)
            + "</ul>"
        )
    if d.get("envelope"):
        body += (
            "<h2>Envelope</h2><table>"
            + "".join(f"<tr><th>{e(k)}</th><td>{e(str(val))}</td></tr>" for k, val in d["envelope"].items())
            + "</table>"
        )
    return _page(f"flight {Path(f['path']).name}", body, 1)


def problems_page(rows: list[dict]) -> str:
    e = html.escape
    bad = [r for r in rows if r["status"] != "ok"]
    trs = "".join(
        f"<tr><td><a href='flights/{r['log_hash'][:16]}.html'>{e(r['path'])}</a></td><td>{e(r['vehicle_id'] or UNIDENTIFIED)}</td>"
        f"<td>{e(r['status'])}</td><td>{e(r['error'] or '')}</td></tr>"
        for r in bad
    )
    body = (
        f"<p>{len(bad)} of {len(rows)} logs.</p><table><tr><th>log</th><th>vehicle</th><th>status</th><th>reason</th></tr>{trs}</table>"
        if bad
        else "<p class='ok'>Every log has a verdict.</p>"
    )
    return _page("problem logs", body, 0)
