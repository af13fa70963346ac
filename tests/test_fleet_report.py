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
        verdict = {
            "label": 1 + (faulty[0] if faulty else 0),
            "faulty_propellers": list(faulty),
            "confidence": "confident",
            "fault_probability": list(p_faulty),
            "faulty_probability_required": 0.9,
        }
        diagnosis = {
            "log": r["path"],
            "verdict": verdict,
            "timeline": timeline,
            "airborne_segments": [{"start_boot_s": 1.0, "stop_boot_s": 19.0, "steps": 360}],
            "propellers": [{"propeller": i + 1, "name": str(i + 1)} for i in range(4)],
            "hypotheses": [{"faulty_propellers": list(faulty), "probability": 0.9}],
            "hypothesis_rule": {"score": "classifier x moment balance"},
            "envelope": {"rpm_ratio": 1.0},
        }
        r.update(
            verdict_label=1,
            faulty_propellers=list(faulty),
            p_faulty=list(p_faulty),
            windows=3,
            duration_s=20.0,
            airborne_s=18.0,
            propeller_names=["1", "2", "3", "4"],
            diagnosis=json.dumps(diagnosis),
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
    assert res == {"index": str(out / "index.html"), "vehicles": 3, "flights": 12, "pictures": 0}
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


def table_data(page: Path) -> tuple[list[dict], list[list], list[str]]:
    """A page's table as table.js receives it: columns, rows, deduplicated strings."""
    data = json.loads(re.search(r"id='data'>(.*?)</script>", page.read_text(encoding="utf-8")).group(1))
    return data["cols"], data["rows"], data["strings"]


def test_flags_name_the_trend_and_the_recent_fault(site):
    cols, rows, strings = table_data(site / "index.html")
    flags = [c["h"] for c in cols].index("flags")
    by_vehicle = {r[0][0]: strings[r[flags]] for r in rows}
    assert set(by_vehicle) == {"wear", "hit", "calm"}
    assert "propeller 2 (rear-left) thrust down 12.0 points over 5 flights" in by_vehicle["wear"]
    assert "propeller 4 (rear-right) damaged in 1 of the last 3 flights" in by_vehicle["hit"]
    assert by_vehicle["calm"] == "none"
    # The sudden 0.2 loss on its last flight fits a line falling 0.18 over 4 flights: flagged too.
    assert "propeller 4 (rear-right) thrust down 18.0 points over 4 flights" in by_vehicle["hit"]
    assert by_vehicle["wear"].count("thrust down") == 1 and by_vehicle["hit"].count("thrust down") == 1
    assert TREND_DROP <= 0.12
    # the vehicle that needs action comes first, with its verdict's own words
    assert rows[0][0][0] == "hit" and strings[rows[0][3][1]] == "Propeller 4 (rear-right) is damaged: replace it."


def test_every_link_resolves_and_no_page_reaches_outside(site):
    pages = list(site.rglob("*.html"))
    assert len(pages) == 1 + 1 + 1 + 3  # index, every flight, problems, vehicles (each holds its flights)
    for page in pages:
        refs = links_of(page)
        if "id='data'" in page.read_text(encoding="utf-8"):  # the table's links travel in its data
            cols, rows, _ = table_data(page)
            refs += [r[i][1] for r in rows for i, c in enumerate(cols) if c["t"] == "a"]
        for ref in refs:
            assert not re.match(r"^(https?:)?//", ref), f"{page.name} loads {ref} from the network"
            target, _, anchor = ref.partition("#")
            path = (page.parent / target).resolve() if target else page
            assert path.is_file(), f"{page} links to missing {ref}"
            assert not anchor or f"id='{anchor}'" in path.read_text(encoding="utf-8"), f"{page}: no section {ref}"


def test_vehicle_page_has_both_trends_and_each_flight_its_diagnosis(site):
    page = vehicle_page(site, "wear").read_text(encoding="utf-8")
    # 4 probability + 4 effectiveness trend series, and each of 5 flights' evidence over its own flight
    assert page.count('<polyline class="series"') == 8 + 4 * 5
    assert page.count('class="point"') == 2 * 4 * 5  # markers on the trends only
    calm = vehicle_page(site, "calm").read_text(encoding="utf-8")
    assert "not estimated by the model" in calm
    hit = vehicle_page(site, "hit").read_text(encoding="utf-8")
    last = hit[hit.index("id='f-" + "hit-03".ljust(64, "0")[:16] + "'") :]
    last = last[: last.index("</article>")]
    assert "Propeller 4 (rear-right) is damaged: replace it." in last and "<svg" in last
    assert "What the damage could be" in last and "seconds after take-off" in last
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
    assert 'data-ready="3"' in dom  # the table script ran to its end over the 3 vehicle rows
    hrefs = re.findall(r'href="(vehicles/[^"]+)"', dom)
    assert len(hrefs) == 3
    wear = next(h for h in hrefs if "wear-" in h)
    vdom, console = chromium_dom(site / wear, tmp_path / "profile")
    assert console == [] and 'data-ready="5"' in vdom
    assert "probability of damage per propeller over flights" in vdom and "rows 1-5 of 5" in vdom
    anchors = re.findall(r'href="(\.\./vehicles/[^"#]+)#(f-[0-9a-z-]+)"', vdom)
    assert len(anchors) == 5 and all((site / "vehicles" / Path(p).name).resolve() == (site / wear).resolve() for p, _ in anchors)
    assert all(f'id="{a}"' in vdom for _, a in anchors)
    assert "No damaged propeller found." in vdom


def test_pictures_are_drawn_from_the_logs_with_the_rows_own_words(site, tmp_path):
    # the fixture's logs are not on disk: the flight to act on says why it has no picture
    hit = vehicle_page(site, "hit").read_text(encoding="utf-8")
    assert "No picture of this flight: its log is no longer where it was ingested from." in hit
    log = Path(__file__).resolve().parents[2] / "shared" / "data" / "px4_ulog" / "sample_px4_events.ulg"
    if not log.is_file():
        pytest.skip(f"{log} not found")
    from PIL import Image

    from fleet.report import row_verdict
    from fleet.worker import IngestSettings, process_log

    row = process_log(str(log), "e" * 64, log.stat().st_size, IngestSettings())
    row.pop("worker_pid")
    con = open_db(tmp_path / "one.duckdb")
    insert_rows(con, [row])
    con.close()
    # the classifier alone flags 3 and 4, physics calls the flight healthy: nothing to act on, no picture then
    assert write_site(tmp_path / "one.duckdb", tmp_path / "site", pictures="action")["pictures"] == 0
    res = write_site(tmp_path / "one.duckdb", tmp_path / "site", pictures="latest")
    assert res["pictures"] == 1
    png = tmp_path / "site" / "pictures" / ("e" * 16 + ".png")
    drawn = Image.open(png).text
    assert drawn["Title"] == row_verdict(row).headline == "No damage seen."
    page = next((tmp_path / "site" / "vehicles").glob("*.html")).read_text(encoding="utf-8")
    assert f"src='../pictures/{'e' * 16}.png'" in page
