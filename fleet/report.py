"""``fleet report``: the fleet database -> a static web site (no JavaScript library, no CDN), sized for 1,000 vehicles.

    site/index.html              every vehicle: its latest verdict (headline, confidence, next step), "compared with",
                                 flags; sortable, paged, filtered by text and by date
    site/flights.html            every flight of the fleet, the same way
    site/vehicles/<slug>.html    one vehicle: its latest verdict, trends over its flights, every flight; each
                                 flight a section (#f-<hash>): the verdict as ``propwatch diagnose`` words it, its
                                 evidence in pictures
    site/problems.html           logs without a verdict and logs that could not be read, with the reason
    site/table.js                the one script: renders, sorts, pages and filters each table from the JSON its page
                                 embeds (a page holds data, not 20,000 rows of markup)

Every verdict is ``monitor.diagnose.verdict`` applied to the row's stored diagnosis (``row_verdict``), so a row says
what ``propwatch diagnose`` says of the same log. A flight's time is the log's own (GPS or the log's header clock:
``time_known``); a log without one reads "time unknown", never its file's date.

Flags on the index (per vehicle):
- *recent*: a propeller to replace or inspect in any of its last ``RECENT_FLIGHTS`` flights with a verdict;
- *effectiveness trending down*: over its last ``TREND_FLIGHTS`` flights that carry rotor
  effectiveness (at least ``TREND_MIN_FLIGHTS``), the least-squares line of a rotor's
  effectiveness against flight number falls by ``TREND_DROP`` or more from first to last.
The site is written into a temporary folder and swapped in, so a reader never sees half a site.
"""

from __future__ import annotations

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
from monitor.diagnose.memory_adapter import with_memory
from monitor.diagnose.report import verdict_html
from monitor.diagnose.verdict import POSITION, Verdict, flight_seconds, set_words, verdict_of

RECENT_FLIGHTS = 3
TREND_FLIGHTS = 10
TREND_MIN_FLIGHTS = 3
TREND_DROP = 0.05  # effectiveness is 1.0 for an intact rotor: 5 points lost across the window
MARKER = ".propwatch-fleet-site"
UNIDENTIFIED = "(unidentified)"
ROWS_PER_PAGE = 50
EVIDENCE_POINTS = 40  # at most this many windows drawn per flight's evidence chart (a 20-s flight: every one)
STATE_ORDER = {
    "damaged": 0,
    "motor": 1,
    "imbalance": 2,
    "inspect": 3,
    "unreadable": 4,
    "no verdict": 5,
    "healthy": 6,
}  # TABLE_JS's RANK

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:1.5em;color:#222;max-width:1200px}
table{border-collapse:collapse;margin:0.6em 0}th,td{border:1px solid #ccc;padding:3px 7px;font-size:13px;text-align:left}
th{background:#f3f3f3}td.num{text-align:right;font-variant-numeric:tabular-nums}
table.data th{cursor:pointer;user-select:none}table.data th.asc:after{content:" \\25B2"}table.data th.desc:after{content:" \\25BC"}
.flag{color:#a40000;font-weight:bold}.ok{color:#2a7a2a}.muted{color:#777}
td.damaged,.damaged .headline{color:#b00;font-weight:bold}td.inspect,td.imbalance,.inspect .headline,.imbalance .headline{color:#a50}
td.healthy,.healthy .headline{color:#070}tr.replace{background:#fdd}tr.inspect{background:#fed}
nav a{margin-right:1em}svg.chart{display:block;margin:0.8em 0;background:#fff}.controls input{margin-right:0.8em}
"""

# Renders a table from <script type="application/json" id=DATA>: {"cols": [{"h": header, "t": kind}], "rows": [...],
# "strings": [...]}. Kinds: "t" text (or an index into strings when "s"), "n" number, "a" [text, href], "v" [state,
# headline index, propellers] (a verdict cell), "d" a time "YYYY-MM-DD HH:MM" or "" (time unknown; the date filter).
TABLE_JS = r"""(function () {
  function esc(s) {
    return String(s).replace(/[&<>"']/g, function (c) {
      return {"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"}[c];
    });
  }
  var RANK = {"damaged": 0, "motor": 1, "imbalance": 2, "inspect": 3, "unreadable": 4, "no verdict": 5, "healthy": 6};
  window.pwTable = function (dataId, mountId) {
    var data = JSON.parse(document.getElementById(dataId).textContent);
    var S = data.strings, cols = data.cols, all = data.rows, per = data.per;
    var key = data.sort, dir = data.dir, page = 0, shown = all;
    var dcol = cols.findIndex(function (c) { return c.t === "d"; });
    function text(r, i) {
      var c = cols[i], v = r[i];
      if (c.t === "a") return v[0];
      if (c.t === "v") return S[v[1]];
      if (c.t === "d") return v || "time unknown";
      if (c.s) return S[v];
      return v === null ? "" : String(v);
    }
    function sortKey(r, i) {
      var c = cols[i], v = r[i];
      if (c.t === "n") return v === null ? -Infinity : v;
      if (c.t === "v") return (RANK[v[0]] === undefined ? 9 : RANK[v[0]]) + ":" + S[v[1]];  // who needs action first
      if (c.t === "d") return v || "0";
      return text(r, i).toLowerCase();
    }
    var hay = all.map(function (r) { return cols.map(function (c, i) { return text(r, i); }).join(" ").toLowerCase(); });
    all.forEach(function (r, k) { r.k = k; });
    var mount = document.getElementById(mountId);
    var dateInputs = dcol < 0 ? "" : '<label>from <input type="date" class="from"></label><label>to <input type="date" class="to"></label>';
    mount.innerHTML = '<p class="controls"><label>filter <input type="search" class="q" placeholder="id, verdict, propeller..."></label>' +
      dateInputs + '<button class="prev">&larr; previous</button> <span class="count"></span> <button class="next">next &rarr;</button></p>' +
      '<table class="data"><thead><tr>' + cols.map(function (c, i) { return '<th data-i="' + i + '">' + esc(c.h) + "</th>"; }).join("") +
      "</tr></thead><tbody></tbody></table>";
    var q = mount.querySelector(".q"), from = mount.querySelector(".from"), to = mount.querySelector(".to");
    var body = mount.querySelector("tbody"), count = mount.querySelector(".count");
    function cell(r, i) {
      var c = cols[i], v = r[i];
      if (c.t === "a") return '<td><a href="' + esc(v[1]) + '">' + esc(v[0]) + "</a></td>";
      if (c.t === "v") return '<td class="verdict ' + esc(v[0].replace(" ", "-")) + '" data-state="' + esc(v[0]) +
        '" data-propellers="' + esc(v[2]) + '">' + esc(S[v[1]]) + "</td>";
      if (c.t === "n") return '<td class="num">' + (v === null ? "" : esc(v)) + "</td>";
      if (c.t === "d") return "<td" + (v ? "" : ' class="muted"') + ">" + esc(text(r, i)) + "</td>";
      return "<td>" + esc(text(r, i)) + "</td>";
    }
    function render() {
      var n = shown.length, pages = Math.max(1, Math.ceil(n / per));
      page = Math.min(page, pages - 1);
      var rows = shown.slice(page * per, page * per + per);
      body.innerHTML = rows.map(function (r) { return "<tr>" + cols.map(function (c, i) { return cell(r, i); }).join("") + "</tr>"; }).join("");
      count.textContent = n ? "rows " + (page * per + 1) + "-" + (page * per + rows.length) + " of " + n : "no rows";
      mount.querySelectorAll("th").forEach(function (th) {
        th.className = +th.dataset.i === key ? (dir > 0 ? "asc" : "desc") : "";
      });
    }
    function apply() {
      var s = q.value.toLowerCase(), f = from && from.value, t = to && to.value;
      shown = all.filter(function (r) {
        if (s && hay[r.k].indexOf(s) < 0) return false;
        if ((f || t) && dcol >= 0) {
          var d = (r[dcol] || "").slice(0, 10);
          if (!d || (f && d < f) || (t && d > t)) return false;
        }
        return true;
      });
      shown.sort(function (a, b) {
        var x = sortKey(a, key), y = sortKey(b, key);
        return (x < y ? -1 : x > y ? 1 : a.k - b.k) * dir;
      });
      page = 0;
      render();
    }
    mount.querySelector("thead").addEventListener("click", function (ev) {
      var i = +ev.target.dataset.i;
      if (isNaN(i)) return;
      dir = i === key ? -dir : 1;
      key = i;
      apply();
    });
    [q, from, to].forEach(function (el) { if (el) el.addEventListener("input", apply); });
    mount.querySelector(".prev").addEventListener("click", function () { page = Math.max(0, page - 1); render(); });
    mount.querySelector(".next").addEventListener("click", function () { page += 1; render(); });
    apply();
    document.body.setAttribute("data-ready", String(all.length));
    document.body.setAttribute("data-ready-ms", performance.now().toFixed(1));  // since navigation began
  };
})();
"""


@dataclass
class Vehicle:
    vid: str
    slug: str
    flights: list[dict] = field(default_factory=list)  # by start time
    verdicts: list[Verdict] = field(default_factory=list)  # row_verdict of each flight, same order

    @property
    def judged(self) -> list[tuple[dict, Verdict]]:
        return [(f, v) for f, v in zip(self.flights, self.verdicts) if f["status"] == "ok"]

    def latest(self) -> tuple[dict, Verdict]:
        return self.flights[-1], self.verdicts[-1]

    def flags(self) -> list[str]:
        out = []
        recent = self.judged[-RECENT_FLIGHTS:]
        hits: dict[tuple[int, str], int] = {}
        for _, v in recent:
            for p in v.replace:
                hits[(p, "damaged")] = hits.get((p, "damaged"), 0) + 1
            for p in v.inspect:
                hits[(p, "to inspect")] = hits.get((p, "to inspect"), 0) + 1
        grouped: dict[tuple[str, int], list[int]] = {}
        for (p, what), k in sorted(hits.items()):
            grouped.setdefault((what, k), []).append(p)
        for (what, k), props in sorted(grouped.items(), key=lambda x: (x[0][0] != "damaged", -x[0][1])):
            plural = "s" if len(recent) != 1 else ""
            who = (
                f"propeller {self.prop_name(props[0])} ({POSITION[props[0]]})"
                if len(props) == 1
                else "propellers " + ", ".join(self.prop_name(p) for p in props)
            )
            out.append(f"{who} {what} in {k} of the last {len(recent)} flight{plural}")
        for p, drop, n in effectiveness_trends(self.flights):
            out.append(f"propeller {self.prop_name(p)} ({POSITION[p]}) thrust down {100 * drop:.1f} points over {n} flights")
        return out

    def prop_name(self, p: int) -> str:
        """A rotor by the vehicle's own name (CrazyPAD's M3 for PX4 rotor 2), as the verdicts name it."""
        names = next((f["propeller_names"] for f in reversed(self.flights) if f["propeller_names"]), None)
        return names[p - 1] if names else str(p)


def _probability(h: dict) -> str:
    """A hypothesis' probability, or what stands instead (the in-flight rule ranks its sets without weighing them)."""
    p = h.get("probability")
    return f"{float(p):.3f}" if p is not None else html.escape(str(h.get("evidence") or h.get("cause") or "-"))


def _day(t) -> str | None:
    """A date column (DATE, TIMESTAMP or text) as ``YYYY-MM-DD``; None stays None."""
    if t is None:
        return None
    return t.strftime("%Y-%m-%d") if hasattr(t, "strftime") else str(t)[:10]


def _judged_by_memory(f: dict) -> bool:
    """Whether the vehicle memory compared this flight with its vehicle's healthy flights (not "no baseline yet")."""
    if "memory" not in f:
        return True  # a store without the memory's judgement column: the counts alone say it
    try:
        memory = json.loads(f["memory"]) if f["memory"] else None
    except (TypeError, ValueError):
        return False
    return isinstance(memory, dict) and "note" not in memory


def row_result(f: dict) -> dict:
    """One database row as the ``diagnose --json`` object it stands for: its stored diagnosis, compared with its
    vehicle's history (``with_memory``, as ``propwatch diagnose --baseline``) where the vehicle memory judged it."""
    if not f.get("diagnosis"):
        return {"log": f.get("path"), "error": f.get("error") or "not diagnosed"}
    res = json.loads(f["diagnosis"])
    if not _judged_by_memory(f):
        return res
    if not f.get("memory"):  # a store without the judgement itself: what it was compared with, from the columns
        first, last = _day(f.get("compared_with_first")), _day(f.get("compared_with_last"))
        return res | {"baseline": {"compared_with": {"flights": f.get("baseline_flights"), "first": first, "last": last}}}
    return with_memory(res, json.loads(f["memory"]))


def row_verdict(f: dict) -> Verdict:
    """The verdict of one database row: ``row_result`` through ``monitor.diagnose.verdict``, exactly as ``propwatch
    diagnose`` (``--baseline`` where the vehicle memory compared it) prints it."""
    return verdict_of(row_result(f))


def verdict_cells(v: Verdict) -> str:
    """A flight's verdict as table cells (headline, confidence, next step); ``data-*`` state it for machines."""
    e = html.escape
    return (
        f"<td class='verdict {v.state.replace(' ', '-')}' data-state='{e(v.state)}' data-confidence='{e(v.confidence)}'"
        f" data-propellers='{','.join(map(str, v.propellers))}' data-replace='{','.join(map(str, v.replace))}'>"
        f"{e(v.headline)}</td><td>{e(v.confidence)}</td><td class='next'>{e(v.next_step)}</td>"
    )


def when(f: dict) -> str:
    """``YYYY-MM-DD HH:MM`` (UTC) from the log's own clock, or "" when the log has none (its file's date is no
    flight's time). ``time_known`` says which; a store without it counts a ``file:mtime`` source as unknown."""
    t, known = f.get("start_time_utc"), f.get("time_known")
    if known is None:
        known = t is not None and f.get("start_time_source") != "file:mtime"
    return t.strftime("%Y-%m-%d %H:%M") if known and t is not None else ""


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
        v = vehicles.setdefault(vid, Vehicle(vid, slug(vid)))
        v.flights.append(r)
        v.verdicts.append(row_verdict(r))
    return list(vehicles.values()), rows


PICTURES = ("action", "latest", "all", "none")


def write_site(db: str | Path, out: str | Path, pictures: str = "action") -> dict:
    """Write the site for ``db`` into ``out`` (replacing an earlier fleet site there); returns its paths.

    ``pictures``: which flights get the picture ``propwatch diagnose --report`` draws (each rotor's thrust share over
    the flight against its normal band, the evidence, motor outputs, attitude), from their logs where those are
    still on disk: ``action`` (default) the flights whose verdict asks to replace or inspect, ``latest`` those and
    each vehicle's latest, ``all``, or ``none``. Each picture re-reads and re-diagnoses its log (about half a
    second)."""
    if pictures not in PICTURES:
        raise FleetError(f"--pictures {pictures}: one of {', '.join(PICTURES)}")
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not (out / MARKER).exists():
        raise FleetError(f"{out}: folder exists and is not a fleet site; give an empty or new folder")
    vehicles, rows = load(db)
    tmp = out.with_name(out.name + ".tmp-site")
    shutil.rmtree(tmp, ignore_errors=True)
    (tmp / "vehicles").mkdir(parents=True)
    drawn = draw_pictures(vehicles, tmp / "pictures", pictures)
    (tmp / MARKER).write_text("written by propwatch fleet report\n", encoding="utf-8")
    (tmp / "table.js").write_text(TABLE_JS, encoding="utf-8")
    (tmp / "index.html").write_text(index_page(vehicles, rows, str(db)), encoding="utf-8")
    (tmp / "flights.html").write_text(flights_page(vehicles), encoding="utf-8")
    (tmp / "problems.html").write_text(problems_page(rows), encoding="utf-8")
    for v in vehicles:  # one file per vehicle, its flights as sections: 1,000 files for 20,000 flights, not 21,000
        (tmp / "vehicles" / f"{v.slug}.html").write_text(vehicle_page(v, drawn), encoding="utf-8")
    if out.exists():
        old = out.with_name(out.name + ".old-site")
        shutil.rmtree(old, ignore_errors=True)
        out.rename(old)
        tmp.rename(out)
        shutil.rmtree(old)
    else:
        tmp.rename(out)
    return {
        "index": str(out / "index.html"),
        "vehicles": len(vehicles),
        "flights": len(rows),
        "pictures": sum(why == "" for why in drawn.values()),
    }


def draw_pictures(vehicles: list[Vehicle], folder: Path, which: str) -> dict[str, str]:
    """log_hash -> why there is no picture, or "" where ``folder/<hash16>.png`` was drawn (``write_site``)."""
    out: dict[str, str] = {}
    for v in vehicles:
        for k, (f, verdict) in enumerate(zip(v.flights, v.verdicts)):
            wanted = which == "all" or (
                which in ("action", "latest") and verdict.propellers or which == "latest" and k == len(v.flights) - 1
            )
            if wanted and f["status"] == "ok":
                out[f["log_hash"]] = _picture(f, verdict, folder / f"{f['log_hash'][:16]}.png")
    return out


def _picture(f: dict, verdict: Verdict, png: Path) -> str:
    """Draw one flight's picture from its log, as ``diagnose --report`` does; "" on success, else why not."""
    from fleet.worker import IngestSettings, choose_model, log_format
    from monitor.diagnose.engine import diagnose_table
    from monitor.diagnose.report import plot
    from monitor.logs import BINARY_FORMATS, read_raw, to_flight_table

    path = Path(f["path"])
    if not path.is_file():
        return "its log is no longer where it was ingested from"
    try:
        settings = IngestSettings(csv_format=None if f["format"] in BINARY_FORMATS else f["format"])
        raw = read_raw(path, log_format(path, settings.csv_format), extras=False)
        clf, esc, _, version, vehicle = choose_model(settings, raw.cmd_unit)
        if version != f["model_version"]:
            return f"the model that would draw it ({version}) is not the one that judged it ({f['model_version']})"
        table = to_flight_table(raw, esc=esc, rate_hz=clf.info.sample_rate_hz)
        d = diagnose_table(table, clf, hop=20, esc=esc, vehicle=vehicle)
        png.parent.mkdir(exist_ok=True)
        plot(verdict, d, table, png, json.loads(f["memory"]) if f.get("memory") else None)
    except Exception as exc:  # noqa: BLE001 - a picture is extra: the page says why it is missing
        return f"its log could not be drawn ({type(exc).__name__}: {exc})"
    return ""


def _page(title: str, body: str, depth: int, script: str = "") -> str:
    up = "../" * depth
    nav = (
        f'<nav><a href="{up}index.html">vehicles</a><a href="{up}flights.html">all flights</a>'
        f'<a href="{up}problems.html">problem logs</a></nav>'
    )
    return (
        f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<meta name='viewport' content='width=device-width'><style>{CSS}</style></head><body>{nav}"
        f"<h1>{html.escape(title)}</h1>{body}{script}</body></html>\n"
    )


class _Strings:
    """Deduplicated strings of a page's table data (20,000 rows share a few hundred headlines)."""

    def __init__(self) -> None:
        self.index: dict[str, int] = {}

    def __call__(self, s: str) -> int:
        return self.index.setdefault(s, len(self.index))

    def to_list(self) -> list[str]:
        return list(self.index)


def _table(cols: list[dict], rows: list[list], strings: _Strings, sort: int, direction: int, depth: int) -> str:
    """A paged, sortable, filterable table: its data as JSON in the page, drawn by table.js."""
    data = {"cols": cols, "rows": rows, "strings": strings.to_list(), "per": ROWS_PER_PAGE, "sort": sort, "dir": direction}
    payload = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    return (
        f"<div id='tbl'><noscript>This table needs JavaScript.</noscript></div>"
        f"<script type='application/json' id='data'>{payload}</script>"
        f"<script src='{'../' * depth}table.js'></script><script>pwTable('data', 'tbl');</script>"
    )


def _verdict_value(v: Verdict, strings: _Strings) -> list:
    return [v.state, strings(v.headline), ",".join(map(str, v.propellers))]


def index_page(vehicles: list[Vehicle], rows: list[dict], db: str) -> str:
    e = html.escape
    n_err = sum(r["status"] == "error" for r in rows)
    n_nov = sum(r["status"] == "no_verdict" for r in rows)
    s = _Strings()
    data = []
    for v in vehicles:
        f, latest = v.latest()
        data.append(
            [
                [v.vid, f"vehicles/{v.slug}.html"],
                len(v.flights),
                when(f),
                _verdict_value(latest, s),
                s(latest.confidence),
                s(latest.next_step),
                s(latest.compared_with or "not yet compared"),
                s("; ".join(v.flags()) or "none"),
            ]
        )
    cols = [
        {"h": "vehicle", "t": "a"},
        {"h": "flights", "t": "n"},
        {"h": "last flight (UTC)", "t": "d"},
        {"h": "latest verdict", "t": "v"},
        {"h": "confidence", "t": "t", "s": True},
        {"h": "next step", "t": "t", "s": True},
        {"h": "compared with", "t": "t", "s": True},
        {"h": "flags", "t": "t", "s": True},
    ]
    data.sort(key=lambda r: (STATE_ORDER.get(r[3][0], 9), r[0][0]))  # who needs action first
    body = (
        f"<p>{len(vehicles)} vehicles, {len(rows)} logs ({n_nov} without a verdict, {n_err} unreadable: "
        f"<a href='problems.html'>problem logs</a>; <a href='flights.html'>every flight</a>). Database "
        f"<code>{e(db)}</code>. Vehicles needing action first; click a column to sort.</p>"
        + _table(cols, data, s, 3, 1, 0)
        + f"<p class='muted'>Flags: a propeller to replace or inspect in the last {RECENT_FLIGHTS} flights with a "
        f"verdict; a rotor's thrust (effectiveness) falling by {TREND_DROP:.2f} or more along a line fitted over its last "
        f"{TREND_FLIGHTS} flights (at least {TREND_MIN_FLIGHTS}). Times are the logs' own; a log without a clock "
        "reads 'time unknown'.</p>"
    )
    return _page("propwatch fleet", body, 0)


FLIGHT_COLS = [
    {"h": "time (UTC)", "t": "d"},
    {"h": "vehicle", "t": "a"},
    {"h": "log", "t": "a"},
    {"h": "verdict", "t": "v"},
    {"h": "confidence", "t": "t", "s": True},
    {"h": "compared with", "t": "t", "s": True},
]


def _flight_row(f: dict, v: Vehicle, verdict: Verdict, s: _Strings, up: str) -> list:
    return [
        when(f),
        [v.vid, f"{up}vehicles/{v.slug}.html"],
        [Path(f["path"]).name, f"{up}{flight_href(v, f)}"],
        _verdict_value(verdict, s),
        s(verdict.confidence),
        s(verdict.compared_with or "-"),
    ]


def flights_page(vehicles: list[Vehicle]) -> str:
    s = _Strings()
    data = [_flight_row(f, v, verdict, s, "") for v in vehicles for f, verdict in zip(v.flights, v.verdicts)]
    n = len(data)
    return _page(
        "every flight",
        f"<p>{n} flights of {len(vehicles)} vehicles, newest first; filter by text or date, click a column to sort.</p>"
        + _table(FLIGHT_COLS, data, s, 0, -1, 0),
        0,
    )


def vehicle_page(v: Vehicle, drawn: dict[str, str] | None = None) -> str:
    e = html.escape
    fl = v.flights
    labels = [(when(f)[5:10] or "?") for f in fl]
    links = [f"#{flight_anchor(f)}" for f in fl]

    def col(key: str, i: int):
        return tuple((f[key][i] if f[key] is not None else None) for f in fl)

    p_series = [Series(f"{v.prop_name(i + 1)} {POSITION[i + 1]}", col("p_faulty", i), COLORS[i]) for i in range(4)]
    charts = line_chart(p_series, labels, "probability of damage per propeller over flights", "probability", (0.0, 1.0), links)
    if any(f["rotor_effectiveness"] is not None for f in fl):
        eff_series = []
        for i in range(4):
            mid, sd = col("rotor_effectiveness", i), col("rotor_effectiveness_std", i)
            band = (
                tuple(m - s if m is not None and s is not None else None for m, s in zip(mid, sd)),
                tuple(m + s if m is not None and s is not None else None for m, s in zip(mid, sd)),
            )
            eff_series.append(Series(f"{v.prop_name(i + 1)} {POSITION[i + 1]}", mid, COLORS[i], band))
        charts += line_chart(
            eff_series, labels, "thrust each rotor gives (1 = intact) over flights, band = +-1 std", "thrust", None, links
        )
    else:
        charts += "<p class='muted'>Rotor thrust: not estimated by the model that diagnosed these flights.</p>"
    flags = v.flags()
    s = _Strings()
    data = [_flight_row(f, v, verdict, s, "../") for f, verdict in zip(fl, v.verdicts)]
    sections = "".join(
        flight_section(f, verdict, (drawn or {}).get(f["log_hash"])) for f, verdict in reversed(list(zip(fl, v.verdicts)))
    )
    src = sorted({f["vehicle_id_source"] or "none" for f in fl})
    _, latest = v.latest()
    body = (
        f"<p>{len(fl)} logs; id from {e(', '.join(src))}.</p><h2>Latest flight</h2>{verdict_html(latest)}"
        + ("<ul>" + "".join(f"<li class='flag'>{e(x)}</li>" for x in flags) + "</ul>" if flags else "<p class='ok'>No flags.</p>")
        + f"<div id='trend'>{charts}</div><h2>Flights</h2>"
        + _table(FLIGHT_COLS, data, s, 0, -1, 1)
        + sections
    )
    return _page(f"vehicle {v.vid}", body, 1)


def evidence_chart(d: dict, verdict: Verdict, names) -> str:
    """The fault classifier's probability of damage per 5 s of flight (seconds after take-off), with the moment the
    evidence changed marked."""
    tl = d.get("timeline") or {}
    if not tl.get("t_boot_s"):
        return "<p class='muted'>No stretch of this flight was classified.</p>"
    every = -(-len(tl["t_boot_s"]) // EVIDENCE_POINTS)  # a long flight drawn from every k-th window
    probs = np.asarray(tl["fault_probability"], dtype=np.float64)[::every]
    t = [flight_seconds(x, verdict.takeoff_boot_s) for x in tl["t_boot_s"][::every]]
    series = [Series(f"{names[i]} {POSITION[i + 1]}", tuple(probs[:, i].tolist()), COLORS[i]) for i in range(4)]
    marks = ()
    if verdict.change_s is not None:
        k = int(np.searchsorted(np.asarray(t), verdict.change_s))
        marks = ((min(k, len(t) - 1), f"evidence changed at {verdict.change_s:.0f} s"),)
    return line_chart(
        series,
        [f"{x:.0f}" for x in t],
        "evidence: the fault classifier's probability of damage per 5 s of flight",
        "probability",
        (0, 1),
        x_label="seconds after take-off",
        marks=marks,
        points=False,
    )


def sets_chart(d: dict, verdict: Verdict) -> str:
    """The propeller sets the verdict could not tell apart, as bars of their probability (ranked where none is stated)."""
    if not verdict.sets:
        return ""
    probs = {tuple(h["faulty_propellers"]): h.get("probability") for h in (d.get("hypotheses") or []) if "faulty_propellers" in h}
    rows = []
    for k, s in enumerate(verdict.sets[:8]):
        p = probs.get(tuple(s))
        width = 300 * (p if p is not None else 1.0 / len(verdict.sets))
        what = f"{100 * p:.0f} %" if p is not None else "the only one" if len(verdict.sets) == 1 else "ranked, not weighed"
        label = f"{set_words(s, list(verdict.names))}: {what}"
        y = 8 + 22 * k
        rows.append(
            f'<rect x="0" y="{y}" width="{width:.1f}" height="16" fill="#bbb"/>'
            f'<text x="4" y="{y + 12}" font-size="12">{html.escape(label)}</text>'
        )
    more = len(verdict.sets) - 8
    h = 16 + 22 * min(8, len(verdict.sets))
    return (
        "<h3>What the damage could be</h3>"
        f'<svg class="sets" xmlns="http://www.w3.org/2000/svg" width="420" height="{h}">'
        + "".join(rows)
        + "</svg>"
        + (f"<p class='muted'>and {more} more</p>" if more > 0 else "")
    )


def shares_chart(f: dict, names) -> str:
    """Each rotor's thrust share this flight against this vehicle's normal (the vehicle memory's judgement, in
    healthy spreads), where the memory compared it."""
    try:
        memory = json.loads(f.get("memory") or "null")
    except ValueError:
        memory = None
    dev = (memory or {}).get("deviation_sigma") if isinstance(memory, dict) else None
    if not dev:
        return ""
    bars = []
    for i, x in enumerate(dev):
        w = min(abs(x), 6.0) * 30
        x0 = 210 if x >= 0 else 210 - w
        colour = "#c00" if abs(x) > 3 else "#888"
        bars.append(
            f'<text x="0" y="{20 + 22 * i}" font-size="12">{html.escape(f"{names[i]} {POSITION[i + 1]}")}</text>'
            f'<rect x="{x0:.1f}" y="{8 + 22 * i}" width="{w:.1f}" height="16" fill="{colour}"/>'
            f'<text x="{x0 + w + 4 if x >= 0 else x0 - 40:.1f}" y="{20 + 22 * i}" font-size="11">{x:+.1f}</text>'
        )
    band = '<rect x="120" y="2" width="180" height="92" fill="#2a7a2a" fill-opacity="0.08"/>'  # +-3 spreads
    return (
        "<h3>Each rotor's thrust share against this vehicle's normal</h3>"
        f'<svg class="shares" xmlns="http://www.w3.org/2000/svg" width="420" height="100">{band}'
        + "".join(bars)
        + '<line x1="210" x2="210" y1="2" y2="94" stroke="#444"/></svg>'
        "<p class='muted'>In spreads of its healthy flights; shaded: within 3 (normal).</p>"
    )


def flight_anchor(f: dict) -> str:
    return f"f-{f['log_hash'][:16]}"


def flight_href(v: Vehicle, f: dict) -> str:
    """A flight's section, on its vehicle's page (relative to the site's root)."""
    return f"vehicles/{v.slug}.html#{flight_anchor(f)}"


def flight_section(f: dict, verdict: Verdict | None = None, picture: str | None = None) -> str:
    """One flight: the verdict as ``propwatch diagnose`` words it, its evidence in pictures, where it came from."""
    e = html.escape
    verdict = verdict or row_verdict(f)
    d = row_result(f) if f["diagnosis"] else {}
    names = f["propeller_names"] or ["1", "2", "3", "4"]
    meta = [
        ("log", f["path"]),
        ("content sha256", f["log_hash"]),
        ("vehicle id from", f["vehicle_id_source"] or "no id"),
        ("time (UTC)", f"{when(f)} ({f['start_time_source']})" if when(f) else "time unknown (the log carries no clock)"),
        ("duration / airborne", f"{f['duration_s'] or 0:.1f} s / {f['airborne_s'] or 0:.1f} s" if f["duration_s"] else "?"),
        ("format", f["format"] or "?"),
        ("model", f"{f['model_id'] or '?'} version {f['model_version'] or '?'}"),
        ("propwatch", f["propwatch_version"] or "?"),
    ]
    title = f"{Path(f['path']).name}, {when(f) or 'time unknown'}"
    body = f"<article class='flight' id='{flight_anchor(f)}'><h2>flight {e(title)}</h2>{verdict_html(verdict)}"
    if f["status"] == "ok":
        body += "<h3>The flight</h3>"
        if picture == "":
            body += f"<img src='../pictures/{f['log_hash'][:16]}.png' alt='thrust shares, evidence and signals' width='960'>"
        elif picture:
            body += f"<p class='muted'>No picture of this flight: {e(picture)}.</p>"
        body += evidence_chart(d, verdict, names) + sets_chart(d, verdict) + shares_chart(f, names)
    fmt_arg = f" --format {f['format']}" if f["format"] not in (None, "tlog", "ulog", "dataflash") else ""
    body += (
        ""
        if picture == ""
        else (
            "<p class='muted'>Each rotor's thrust share, the motor outputs and the attitude over this flight: "
            f"<code>propwatch diagnose {e(f['path'])}{e(fmt_arg)} --report DIR</code> (the log itself is not kept here).</p>"
        )
    )
    body += "<table>" + "".join(f"<tr><th>{e(k)}</th><td>{e(str(val))}</td></tr>" for k, val in meta) + "</table>"
    warns = f["warnings"] or []
    body += "<h3>Warnings</h3><ul>" + ("".join(f"<li>{e(w)}</li>" for w in warns) or "<li>none</li>") + "</ul>"
    segs = d.get("airborne_segments") or []
    if segs:
        body += (
            "<h3>Airborne</h3><ul>"
            + "".join(
                f"<li>{flight_seconds(s['start_boot_s'], verdict.takeoff_boot_s):.0f} - "
                f"{flight_seconds(s['stop_boot_s'], verdict.takeoff_boot_s):.0f} s after take-off</li>"
                for s in segs
            )
            + "</ul>"
        )
    if f["hypotheses"]:
        hyp = json.loads(f["hypotheses"])
        body += (
            "<details><summary>hypothesis sets as stored</summary><table><tr><th>propellers</th><th>probability</th></tr>"
            + "".join(
                f"<tr><td>{e(set_words(h.get('faulty_propellers') or [], names))}</td><td class='num'>{_probability(h)}</td></tr>"
                for h in hyp
            )
            + "</table></details>"
        )
    return body + "</article>"


def problems_page(rows: list[dict]) -> str:
    e = html.escape
    bad = [r for r in rows if r["status"] != "ok"]
    trs = "".join(
        f"<tr><td><a href='vehicles/{slug(r['vehicle_id'] or UNIDENTIFIED)}.html#{flight_anchor(r)}'>{e(r['path'])}</a></td>"
        f"<td>{e(r['vehicle_id'] or UNIDENTIFIED)}</td>"
        f"<td>{e(r['status'])}</td><td>{e(r['error'] or '')}</td></tr>"
        for r in bad
    )
    body = (
        f"<p>{len(bad)} of {len(rows)} logs.</p><table><tr><th>log</th><th>vehicle</th><th>status</th><th>reason</th></tr>{trs}</table>"
        if bad
        else "<p class='ok'>Every log has a verdict.</p>"
    )
    return _page("problem logs", body, 0)
