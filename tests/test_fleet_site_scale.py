"""The fleet site at 1,000 vehicles x 20 flights, in a real headless Chromium: the index <= 2 MB and drawn in
<= 2 s, a vehicle page in <= 1 s, sorting, paging, the date filter and "time unknown", and a screenshot that shows
verdict colours. The 20,000-row store is made synthetically in DuckDB (SQL over ``range``) so the test takes seconds:
each row's diagnosis is one of four real-shaped ``diagnose --json`` objects (healthy, damaged, an ambiguous pair,
no verdict); every verdict the site shows still goes through ``monitor.diagnose.verdict``.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

pytest.importorskip("duckdb")

from fleet.report import write_site  # noqa: E402
from fleet.schema import COLUMNS, open_db  # noqa: E402

VEHICLES, FLIGHTS = 1000, 20
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--enable-logging=stderr", "--v=0")  # fmt: skip


def _diagnosis(kind: str) -> str:
    """A ``diagnose --json`` object of one of four kinds (the keys ``monitor.diagnose.verdict`` reads)."""
    t = [10.0 + k for k in range(60)]
    p = {"healthy": [0.01, 0.02, 0.01, 0.0], "damaged": [0.0, 0.01, 0.98, 0.02], "pair": [0.01, 0.0, 0.95, 0.93]}
    if kind == "none":
        return json.dumps({"log": "x", "verdict": None, "reason": "no usable window: ...", "warnings": [],
                           "propellers": [], "airborne_segments": [{"start_boot_s": 10.0, "stop_boot_s": 13.0}]})  # fmt: skip
    sets = {"healthy": [[]], "damaged": [[3]], "pair": [[3, 4], []]}[kind]
    verdict = {
        "label": {"healthy": 1, "damaged": 4, "pair": 11}[kind],
        "faulty_propellers": sets[0],
        "confidence": "ambiguous" if len(sets) > 1 else "confident",
        "fault_probability": p[kind],
        "faulty_probability_required": 0.9,
    }
    return json.dumps(
        {
            "log": "x",
            "verdict": verdict,
            "reason": None,
            "warnings": [],
            "propellers": [{"propeller": i + 1, "name": str(i + 1)} for i in range(4)],
            "airborne_segments": [{"start_boot_s": 8.0, "stop_boot_s": 75.0, "steps": 1340}],
            "timeline": {"t_boot_s": t, "fault_probability": [p[kind]] * len(t), "label": [1] * len(t)},
            "hypotheses": [{"faulty_propellers": s, "probability": 0.9 if k == 0 else 0.1} for k, s in enumerate(sets)],
            "hypothesis_rule": {"score": "classifier x moment balance"},
            "rotor_effectiveness": [1.0, 1.0, 0.9 if kind != "healthy" else 1.0, 1.0],
            "rotor_effectiveness_std": [0.01] * 4,
            "decision": {"alerts": [], "final": {"tested_s": 55.0}},
        }
    )


def build_store(db: Path) -> None:
    """VEHICLES x FLIGHTS rows in one INSERT ... SELECT: vehicle v's flight k, a day apart; every 97th flight has no
    clock of its own (time_known false, its start a file date); kinds cycle so each vehicle's latest varies."""
    open_db(db).close()
    import duckdb

    exprs = {
        "log_hash": "lpad(to_hex(i), 64, '0')",
        "path": "'/logs/v' || (i // 20) || '/flight_' || (i % 20) || '.tlog'",
        "size_bytes": "1000",
        "format": "'tlog'",
        "vehicle_id": "'veh-' || lpad(CAST(i // 20 AS VARCHAR), 4, '0')",
        "vehicle_id_source": "'mavlink:AUTOPILOT_VERSION.uid'",
        "start_time_utc": "TIMESTAMP '2026-01-01 08:00' + INTERVAL 1 DAY * (i % 20) + INTERVAL 1 MINUTE * ((i // 20) % 600)",
        "start_time_source": "CASE WHEN i % 97 = 0 THEN 'file:mtime' ELSE 'tlog:receive_time' END",
        "time_known": "i % 97 <> 0",
        "duration_s": "80.0",
        "airborne_s": "67.0",
        "status": "CASE WHEN i % 23 = 0 THEN 'no_verdict' ELSE 'ok' END",
        "error": "CASE WHEN i % 23 = 0 THEN 'no usable window' END",
        "p_faulty": "[0.01, 0.02, 0.5, 0.4]",
        "propeller_names": "['1', '2', '3', '4']",
        "warnings": "[]::VARCHAR[]",
        "rotor_effectiveness": "[1.0, 1.0, 0.95, 1.0]",
        "rotor_effectiveness_std": "[0.01, 0.01, 0.01, 0.01]",
        "diagnosis": "CASE WHEN i % 23 = 0 THEN $none WHEN i % 7 = 0 THEN $damaged WHEN i % 5 = 0 THEN $pair ELSE $healthy END",
        "baseline_flights": "i % 20",
        "compared_with_first": "CASE WHEN i % 20 > 0 THEN '2026-01-01' END",
        "compared_with_last": "CASE WHEN i % 20 > 0 THEN strftime(DATE '2026-01-01' + CAST(i % 20 - 1 AS INTEGER), '%Y-%m-%d') END",
        # the judgement as monitor.diagnose.memory_adapter.judgement stores it: what it was compared with, the deviation
        "memory": 'CASE WHEN i % 20 >= 3 THEN \'{"deviation_sigma": [0.1, -0.2, 0.3, -0.1], "compared_with": '
        '{"flights": \' || (i % 20) || \', "first": "2026-01-01", "last": "\' || '
        "strftime(DATE '2026-01-01' + CAST(i % 20 - 1 AS INTEGER), '%Y-%m-%d') || '\"}}' END",
    }
    names = [c for c, _ in COLUMNS if c in exprs]
    con = duckdb.connect(str(db))
    con.execute(
        f"INSERT INTO flights ({', '.join(names)}) SELECT {', '.join(exprs[n] for n in names)} "
        f"FROM range({VEHICLES * FLIGHTS}) t(i)",
        {k: _diagnosis(k) for k in ("healthy", "damaged", "pair", "none")},
    )
    con.close()


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    # 190 MB of pages (every flight's section with its pictures): on tmpfs where there is one, the disk's speed is
    # not what this test measures
    shm = Path("/dev/shm")
    root = Path(tempfile.mkdtemp(dir=shm)) if shm.is_dir() else tmp_path_factory.mktemp("scale")
    build_store(root / "fleet.duckdb")
    res = write_site(root / "fleet.duckdb", root / "site")
    assert res["vehicles"] == VEHICLES and res["flights"] == VEHICLES * FLIGHTS
    yield root / "site"
    shutil.rmtree(root, ignore_errors=True)


def test_the_site_holds_every_vehicle_and_flight_and_no_file_date(site):
    index = (site / "index.html").read_text(encoding="utf-8")
    assert (site / "index.html").stat().st_size <= 2_000_000
    data = json.loads(re.search(r"id='data'>(.*?)</script>", index).group(1))
    assert len(data["rows"]) == VEHICLES
    assert len(list((site / "vehicles").glob("*.html"))) == VEHICLES
    flights = json.loads(re.search(r"id='data'>(.*?)</script>", (site / "flights.html").read_text()).group(1))
    assert len(flights["rows"]) == VEHICLES * FLIGHTS
    unknown = [r for r in flights["rows"] if r[0] == ""]
    # every 97th flight has only its file's date: shown as unknown, never as that date
    assert len(unknown) == len(range(0, VEHICLES * FLIGHTS, 97))
    head = {c["h"] for c in data["cols"]}
    assert {"confidence", "compared with", "latest verdict", "next step"} <= head
    assert any("against 19 healthy flights of this vehicle, 2026-01-01 to 01-19" == s for s in data["strings"])


def _dom(page: Path, profile: Path, *extra: str) -> str:
    res = subprocess.run(
        [CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *extra, "--dump-dom", page.resolve().as_uri()],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    console = [line for line in res.stderr.splitlines() if ":CONSOLE" in line or "Uncaught" in line]
    assert console == [], console
    return res.stdout


def _ready_ms(dom: str) -> float:
    return float(re.search(r'data-ready-ms="([\d.]+)"', dom).group(1))


@pytest.mark.browser
@pytest.mark.skipif(CHROMIUM is None, reason="Chromium not installed (apt-get install chromium); .ci/run installs it")
def test_index_and_vehicle_page_draw_in_time_in_chromium(site, tmp_path):
    dom = _dom(site / "index.html", tmp_path / "p")
    assert f'data-ready="{VEHICLES}"' in dom and _ready_ms(dom) <= 2000, _ready_ms(dom)
    assert dom.count("<tr>") == 50 + 1 and "rows 1-50 of 1000" in dom  # one page of 50 and the header
    states = re.findall(r'<td class="verdict ([a-z-]+)"', dom)
    assert states[0] == "damaged" and "healthy" not in states[:10]  # who needs action first
    vehicle = re.search(r'href="(vehicles/[^"]+)"', dom).group(1)
    vdom = _dom(site / vehicle, tmp_path / "p")
    assert f'data-ready="{FLIGHTS}"' in vdom and _ready_ms(vdom) <= 1000, _ready_ms(vdom)
    assert "rows 1-20 of 20" in vdom and "<svg" in vdom
    fdom = _dom(site / "flights.html", tmp_path / "p")
    assert f'data-ready="{VEHICLES * FLIGHTS}"' in fdom and "rows 1-50 of 20000" in fdom


@pytest.mark.browser
@pytest.mark.skipif(CHROMIUM is None, reason="Chromium not installed (apt-get install chromium); .ci/run installs it")
def test_sort_page_and_date_filter_in_chromium(site, tmp_path):
    """Drive the flights list as a user would (a script in the page clicks and types), then read the DOM."""
    page = tmp_path / "drive.html"
    page.write_text(
        (site / "flights.html")
        .read_text(encoding="utf-8")
        .replace(
            "</body>",
            "<script>var th = document.querySelectorAll('th')[0]; th.click();"  # oldest first
            "var first = document.querySelector('tbody tr td').textContent;"
            "document.body.setAttribute('data-first', first);"
            "document.querySelector('.next').click();"
            "document.body.setAttribute('data-page2', document.querySelector('.count').textContent);"
            "var f = document.querySelector('.from'), t = document.querySelector('.to');"
            "f.value = '2026-01-05'; t.value = '2026-01-05'; t.dispatchEvent(new Event('input'));"
            "document.body.setAttribute('data-filtered', document.querySelector('.count').textContent);</script></body>",
        ),
        encoding="utf-8",
    )
    shutil.copy(site / "table.js", tmp_path / "table.js")
    dom = _dom(page, tmp_path / "p")
    assert re.search(r'data-first="time unknown"', dom)  # unknown times sort before every known one
    assert 'data-page2="rows 51-100 of 20000"' in dom
    # 2026-01-05 is flight 4 of every vehicle: 1,000 flights, less those without a clock of their own
    n = sum(1 for i in range(VEHICLES * FLIGHTS) if i % 20 == 4 and i % 97 != 0)
    assert f'data-filtered="rows 1-50 of {n}"' in dom


@pytest.mark.browser
@pytest.mark.skipif(CHROMIUM is None, reason="Chromium not installed (apt-get install chromium); .ci/run installs it")
def test_index_screenshot_shows_the_verdicts(site, tmp_path):
    from PIL import Image

    shot = tmp_path / "index.png"
    res = subprocess.run(
        [CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'p'}", "--window-size=1280,900", f"--screenshot={shot}",
         (site / "index.html").resolve().as_uri()],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert res.returncode == 0 and shot.is_file(), res.stderr[-2000:]
    img = Image.open(shot).convert("RGB")
    assert img.size == (1280, 900)
    colours = img.getcolors(1_000_000)
    red = sum(n for n, (r, g, b) in colours if r > 150 and g < 60 and b < 60)  # damaged: #b00
    assert red > 200, "no red verdict text drawn: the table did not render"
