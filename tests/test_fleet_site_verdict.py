"""One verdict everywhere: the fleet's row, its web site and ``propwatch diagnose`` (``--baseline`` against the same
history where the vehicle memory compared the flight) say the same thing about every flight, word for word.

A fleet of two simulated vehicles (``propwatch simulate --vehicle-id``), each with healthy flights and then a
propeller damaged from take-off; and every flight log in ../shared/data (no history there: the nominal verdict).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from monitor.cli import main as propwatch

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
# vehicle id: (healthy flights, label of the damaged ones, damaged flights)
VEHICLES = {1: (4, 3, 2), 2: (3, 5, 1)}  # label 3: propeller 2; label 5: propeller 4


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    pytest.importorskip("duckdb")
    pytest.importorskip("torch")  # simulate's learnt propellers
    from fleet.ingest import ingest
    from offline.simulate import SimulateSpec, write_flights

    root = tmp_path_factory.mktemp("fleet")
    for vid, (healthy, label, damaged) in VEHICLES.items():
        out = root / f"quad{vid}"
        write_flights(out, SimulateSpec(flights=healthy, duration_s=30.0, vehicle_id=vid, seed=vid))
        write_flights(
            out, SimulateSpec(flights=damaged, label=label, duration_s=30.0, vehicle_id=vid, first_flight=healthy, seed=vid)
        )
    db = root / "fleet.duckdb"
    ingest([str(root)], db, ray_address="off", progress=False)
    return root, db


def rows_of(db) -> list[dict]:
    from fleet.schema import open_db

    con = open_db(db, read_only=True)
    try:
        cur = con.execute("SELECT * FROM flights ORDER BY vehicle_id, start_time_utc")
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r)) for r in cur.fetchall()]
    finally:
        con.close()


def diagnosed(capsys, *args) -> tuple[dict, str]:
    """``propwatch diagnose`` as JSON and as text, in process."""
    propwatch(["diagnose", *map(str, args), "--json"])
    res = json.loads(capsys.readouterr().out)
    propwatch(["diagnose", *map(str, args)])
    return res, capsys.readouterr().out


def test_the_site_says_what_diagnose_baseline_says_on_every_flight_of_the_fleet(fleet, tmp_path, capsys):
    from fleet.report import row_verdict, write_site
    from monitor.diagnose.verdict import verdict_of

    root, db = fleet
    rows = rows_of(db)
    by_hash = {r["log_hash"]: r["path"] for r in rows}
    write_site(db, tmp_path / "site", pictures="none")
    site = "".join(p.read_text() for p in (tmp_path / "site").rglob("*.html"))
    judged = 0
    for r in rows:
        history = r["compared_with_logs"] or []
        args = [r["path"]]
        if r["baseline_flights"] and r["baseline_flights"] >= 3:
            b = tmp_path / f"{r['log_hash'][:12]}.json"
            assert propwatch(["baseline", "learn", *[by_hash[h] for h in history], "--out", str(b)]) == 0
            capsys.readouterr()
            args += ["--baseline", b]
            judged += 1
        res, text = diagnosed(capsys, *args)
        said, shown = verdict_of(res), row_verdict(r)
        assert shown.to_json() == said.to_json(), (r["path"], shown.headline, said.headline)
        assert said.headline in text and said.headline in site.replace("&#x27;", "'"), said.headline
        assert (r["verdict_label"], r["confidence"]) == (res["verdict"]["label"], res["verdict"]["confidence"]), r["path"]
    assert judged == sum(h + d - 3 for h, _, d in VEHICLES.values())
    # ... and the verdicts are right: against its history each damaged flight names its propeller, to be replaced
    for r in rows:
        truth = json.loads(Path(r["path"]).with_name(_sidecar(r["path"])).read_text())
        flight = next(f for f in truth["flights"] if f["file"] == Path(r["path"]).name)
        if r["baseline_flights"] >= 3:
            v = row_verdict(r)
            assert (v.state, list(v.replace)) == (("damaged", flight["faulty_propellers"]) if flight["faulty_propellers"]
                                                   else ("healthy", [])), (r["path"], v.headline)  # fmt: skip


def _sidecar(path: str) -> str:
    k = int(Path(path).stem.rsplit("_", 1)[1])
    for name in sorted(Path(path).parent.glob("sidecar*.json"), reverse=True):
        first = 0 if name.stem == "sidecar" else int(name.stem.rsplit("_", 1)[1])
        if k >= first:
            return name.name
    raise AssertionError(f"no sidecar for {path}")


CRAZYFLIE = REPO / "models" / "crazyflie.yaml"
# (folder, fleet ingest --format, diagnose's options for its logs)
REAL = [
    ("px4_ulog", None, []),
    ("ardupilot_log171", None, []),
    ("crazypad/motor", "crazypad", ["--format", "crazypad", "--vehicle", str(CRAZYFLIE)]),
    ("crazypad/controller", "crazypad-controller", ["--format", "crazypad-controller", "--vehicle", str(CRAZYFLIE)]),
]


@pytest.mark.slow
@pytest.mark.realdata
@pytest.mark.skipif(not (DATA / "crazypad").is_dir(), reason=f"real logs not found at {DATA}")
def test_the_site_says_what_diagnose_says_on_every_real_log(tmp_path, capsys):
    """Every flight log in ../shared/data through the fleet (its row and site) and through ``propwatch diagnose``
    with the model and vehicle the fleet chose: the same verdict, word for word (no history: the nominal one)."""
    pytest.importorskip("duckdb")
    from fleet.ingest import ingest
    from fleet.report import row_verdict, write_site
    from fleet.worker import IngestSettings
    from monitor.diagnose.verdict import verdict_of

    db = tmp_path / "real.duckdb"
    options = {}
    for folder, fmt, opts in REAL:
        ingest([str(DATA / folder)], db, IngestSettings(csv_format=fmt), ray_address="off", progress=False)
        options[folder] = opts
    write_site(db, tmp_path / "site", pictures="none")
    site = "".join(p.read_text() for p in (tmp_path / "site").rglob("*.html")).replace("&#x27;", "'")
    rows = rows_of(db)
    assert len(rows) == sum(1 for f, *_ in REAL for p in (DATA / f).rglob("*") if p.suffix in (".ulg", ".bin", ".gz"))
    for r in rows:
        opts = next(o for f, o in options.items() if r["path"].startswith(str(DATA / f)))
        code = propwatch(["diagnose", r["path"], "--json", "--hop", str(IngestSettings().hop), *opts])
        out = capsys.readouterr().out
        if r["status"] == "error":
            assert code == 2, (r["path"], out)
            continue
        res = json.loads(out)
        said, shown = verdict_of(res), row_verdict(r)
        assert shown.to_json() == said.to_json(), (r["path"], shown.headline, said.headline)
        assert said.headline in site, (r["path"], said.headline)


@pytest.mark.realdata
@pytest.mark.skipif(not (DATA / "ardupilot_log171").is_dir(), reason=f"log171 not found at {DATA}")
def test_a_warning_tells_the_in_flight_fault_as_the_evidence_and_the_json_do(capsys):
    """log171: the in-flight rule's first FAULT, which the log does not fit, in seconds after take-off and with the
    sets of that alert, in the warning as in the evidence line and the JSON."""
    log = DATA / "ardupilot_log171" / "log171.bin"
    propwatch(["diagnose", str(log), "--json"])
    res = json.loads(capsys.readouterr().out)
    first = next(a for a in res["decision"]["alerts"] if a["level"] == "fault")
    after_s = first["t_boot_s"] - res["airborne_segments"][0]["start_boot_s"]
    sets = " or ".join("+".join(map(str, s)) for s in first["hypothesis_sets"])
    warning = next(w for w in res["warnings"] if w.startswith("the in-flight rule reached fault level"))
    assert f"at {after_s:.0f} s after take-off ({sets})" in warning, (warning, first)
    propwatch(["diagnose", str(log)])
    text = capsys.readouterr().out.replace("\n    ", " ")
    assert f"at {after_s:.0f} s after take-off" in text.split("warning:")[0]  # the evidence line: the same instant
