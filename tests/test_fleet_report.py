"""propwatch fleet report: flags, pages and links from a fleet database; the site in a real headless Chromium."""

from __future__ import annotations

import datetime as dt
import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest

pytest.importorskip("duckdb")

from fleet.errors import FleetError  # noqa: E402
from fleet.report import TREND_DROP, write_site  # noqa: E402
from fleet.schema import insert_rows, open_db  # noqa: E402
from fleet.worker import empty_row  # noqa: E402

DAY = dt.timedelta(days=1)
T0 = dt.datetime(2025, 3, 1, 9, 0)


def flight(vid: str, k: int, p_faulty=(0.01, 0.02, 0.01, 0.03), faulty=(), eff=None, status="ok", error=None) -> dict:
    r = empty_row(Path(f"/logs/{vid}/flight_{k:02d}.tlog"), f"{vid}-{k:02d}".ljust(64, "0"), 1000)
    r.update(vehicle_id=vid, vehicle_id_source="mavlink:AUTOPILOT_VERSION.uid", start_time_utc=T0 + k * DAY)
    r.update(start_time_source="tlog:receive_time", status=status, error=error, format="tlog", ingested_at=T0)
    if status == "ok":
        timeline = {"t_boot_s": [5.0, 6.0, 7.0], "fault_probability": [list(p_faulty)] * 3, "label": [1, 1, 1]}
        r.update(
            verdict_label=1,
            faulty_propellers=list(faulty),
            p_faulty=list(p_faulty),
            windows=3,
            duration_s=20.0,
            airborne_s=18.0,
            propeller_names=["1", "2", "3", "4"],
            diagnosis=json.dumps({"timeline": timeline, "airborne_segments": [], "envelope": {"rpm_ratio": 1.0}}),
            rotor_effectiveness=None if eff is None else list(eff),
            rotor_effectiveness_std=None if eff is None else [0.01] * 4,
            hypotheses=json.dumps([{"faulty_propellers": list(faulty), "probability": 0.9}]),
        )
    return r


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("report")
    con = open_db(root / "fleet.duckdb")
    rows = []
    # "wear": rotor 2 loses 3 points of effectiveness a flight (0.12 over 5 flights), never called faulty.
    rows += [flight("wear", k, eff=(1.0, 1.0 - 0.03 * k, 0.99, 1.0)) for k in range(5)]
    # "hit": healthy, then propeller 4 faulty in its last flight.
    rows += [flight("hit", k, eff=(1.0, 1.0, 1.0, 1.0)) for k in range(3)]
    rows.append(flight("hit", 3, p_faulty=(0.01, 0.02, 0.05, 0.97), faulty=(4,), eff=(1.0, 1.0, 1.0, 0.8)))
    # "calm": healthy, no effectiveness (an older model), plus an unreadable log.
    rows += [flight("calm", k) for k in range(2)]
    rows.append(flight("calm", 2, status="error", error="/logs/calm/flight_02.tlog: unknown log format"))
    insert_rows(con, rows)
    con.close()
    out = root / "site"
    res = write_site(root / "fleet.duckdb", out)
    assert res == {"index": str(out / "index.html"), "vehicles": 3, "flights": 12}
    return out


class Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.refs: list[str] = []

    def handle_starttag(self, tag, attrs):
        for k, v in attrs:
            if k in ("href", "src") and v:
                self.refs.append(v)


def links_of(page: Path) -> list[str]:
    p = Links()
    p.feed(page.read_text(encoding="utf-8"))
    return p.refs


def vehicle_page(site: Path, vid: str) -> Path:
    return next(p for p in (site / "vehicles").glob(f"{vid}-*.html"))


def test_flags_name_the_trend_and_the_recent_fault(site):
    index = (site / "index.html").read_text(encoding="utf-8")
    rows = {m.group(1): m.group(0) for m in re.finditer(r"<tr><td><a href='vehicles/[^']+'>(\w+)</a>.*?</tr>", index)}
    assert set(rows) == {"wear", "hit", "calm"}
    assert "propeller 2 effectiveness down 12.0 points over 5 flights" in rows["wear"]
    assert "propeller 4 faulty in 1 of the last 3 flights" in rows["hit"]
    assert "flag'>" not in rows["calm"] and "not estimated" in rows["calm"]
    # The sudden 0.2 loss on its last flight fits a line falling 0.18 over 4 flights: flagged too.
    assert "propeller 4 effectiveness down 18.0 points over 4 flights" in rows["hit"]
    assert rows["wear"].count("effectiveness down") == 1 and rows["hit"].count("effectiveness down") == 1
    assert TREND_DROP <= 0.12


def test_every_link_resolves_and_no_page_reaches_outside(site):
    pages = list(site.rglob("*.html"))
    assert len(pages) == 1 + 1 + 3 + 12  # index, problems, vehicles, flights
    for page in pages:
        for ref in links_of(page):
            assert not re.match(r"^(https?:)?//", ref), f"{page.name} loads {ref} from the network"
            assert (page.parent / ref).resolve().is_file(), f"{page} links to missing {ref}"


def test_vehicle_page_has_both_trends_and_flight_page_the_diagnosis(site):
    page = vehicle_page(site, "wear").read_text(encoding="utf-8")
    assert page.count('<polyline class="series"') == 8  # 4 P(faulty) + 4 effectiveness series
    assert page.count('class="point"') == 2 * 4 * 5
    calm = vehicle_page(site, "calm").read_text(encoding="utf-8")
    assert "not estimated by the model" in calm
    hit_last = (site / "flights" / ("hit-03".ljust(64, "0")[:16] + ".html")).read_text(encoding="utf-8")
    assert "FAULTY" in hit_last and "0.970" in hit_last and "Hypotheses" in hit_last and "<svg" in hit_last
    problems = (site / "problems.html").read_text(encoding="utf-8")
    assert "unknown log format" in problems and "1 of 12 logs" in problems


def test_rewrite_replaces_a_site_but_never_a_foreign_folder(site, tmp_path):
    db = site.parent / "fleet.duckdb"
    write_site(db, site)  # again, in place
    assert (site / "index.html").is_file() and not list(site.parent.glob("*.tmp-site"))
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    with pytest.raises(FleetError, match="not a fleet site"):
        write_site(db, foreign)
    assert (foreign / "notes.txt").read_text() == "keep me"


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-logging=stderr",
    "--v=0",
)


def chromium_dom(page: Path, profile: Path) -> tuple[str, list[str]]:
    """The DOM after Chromium loaded ``page`` (scripts run), and the console lines it logged."""
    res = subprocess.run(
        [CHROMIUM, *FLAGS, f"--user-data-dir={profile}", "--dump-dom", page.resolve().as_uri()],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr[-2000:]
    console = [line for line in res.stderr.splitlines() if ":CONSOLE" in line or "Uncaught" in line]
    return res.stdout, console


@pytest.mark.browser
@pytest.mark.skipif(CHROMIUM is None, reason="Chromium not installed (apt-get install chromium); .ci/run installs it")
def test_site_in_headless_chromium(site, tmp_path):
    dom, console = chromium_dom(site / "index.html", tmp_path / "profile")
    assert console == []
    assert 'data-ready="3"' in dom  # the filter script ran to its end over the 3 vehicle rows
    hrefs = re.findall(r'href="(vehicles/[^"]+)"', dom)
    assert len(hrefs) == 3
    wear = next(h for h in hrefs if "wear-" in h)
    vdom, console = chromium_dom(site / wear, tmp_path / "profile")
    assert console == []
    assert vdom.count('class="series"') == 8 and "P(faulty) per propeller over flights" in vdom
    flight_href = re.findall(r'href="(\.\./flights/[^"]+)"', vdom)[0]
    fdom, console = chromium_dom((site / wear).parent / flight_href, tmp_path / "profile")
    assert console == [] and "Verdict: label 1" in fdom and "<svg" in fdom
    back = re.findall(r'href="(\.\./vehicles/[^"]+)"', fdom)
    assert back and ((site / "flights") / back[0]).resolve() == (site / wear).resolve()
