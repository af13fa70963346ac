"""propwatch fleet ingest: rows per log, idempotent re-runs, error rows, Ray retries, schema and address checks."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import threading
import time
from pathlib import Path

import pytest

duckdb = pytest.importorskip("duckdb")
pytest.importorskip("ray")
pytest.importorskip("offline.sim.simulator")

from ray_fixture import ray_local  # noqa: E402,F401

from fleet.errors import FleetError  # noqa: E402
from fleet.ingest import ingest  # noqa: E402
from fleet.schema import SCHEMA_VERSION, insert_rows, open_db  # noqa: E402
from fleet.worker import IngestSettings, empty_row, process_log  # noqa: E402
from monitor.cli import main as propwatch  # noqa: E402
from offline.fleet_sim import FleetSpec, vehicle_uid, write_fleet  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
# The simulated fleet is the paper's quad, declared as `fleet ingest --vehicle models/vehicle.yaml` would: its network
# may speak (fleet.worker.declared).
PAPER = IngestSettings(vehicle_yaml=str(Path(__file__).resolve().parents[1] / "models" / "vehicle.yaml"))
SPEC = FleetSpec(vehicles=2, flights=3, duration_s=14.0, faulty_vehicle=1, fault_from_flight=1, faulty_propeller=3, seed=5)


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("fleet")
    write_fleet(root / "sim", SPEC)
    bad = root / "bad"
    bad.mkdir()
    (bad / "corrupt.tlog").write_bytes(os.urandom(3000))
    (bad / "empty.ulg").write_bytes(b"")
    (bad / "foreign.bin").write_bytes(b"%PDF-1.4 not a flight log\n" * 20)
    return root


def rows(db: Path) -> list[dict]:
    con = duckdb.connect(str(db), read_only=True)
    try:
        cur = con.execute("SELECT * FROM flights ORDER BY path")
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r)) for r in cur.fetchall()]
    finally:
        con.close()


@pytest.fixture(scope="module")
def serial_db(fleet_dir, tmp_path_factory) -> Path:
    db = tmp_path_factory.mktemp("db") / "fleet.duckdb"
    s = ingest([str(fleet_dir)], db, settings=PAPER, ray_address="off", progress=False)
    assert (s.found, s.new, s.error) == (9, 9, 3)
    return db


def test_one_row_per_log_with_vehicle_date_and_verdict(serial_db):
    by_name = {Path(r["path"]).parent.name + "/" + Path(r["path"]).name: r for r in rows(serial_db)}
    assert len(by_name) == 9
    for v in range(SPEC.vehicles):
        for k in range(SPEC.flights):
            r = by_name[f"vehicle_{v + 1}/flight_{k + 1:02d}.tlog"]
            assert r["status"] == "ok", r["error"]
            assert r["vehicle_id"] == f"{vehicle_uid(v):016x}" and r["vehicle_id_source"] == "mavlink:AUTOPILOT_VERSION.uid"
            assert r["start_time_source"] == "tlog:receive_time" and r["start_time_utc"].day == 1 + k
            assert len(r["p_faulty"]) == 4 and r["model_version"] and r["propwatch_version"]
            assert r["duration_s"] == pytest.approx(SPEC.duration_s, abs=0.2) and 0 < r["airborne_s"] <= r["duration_s"]
            d = json.loads(r["diagnosis"])  # the new keys are stored as diagnose gives them, NULL when it does not
            assert r["rotor_effectiveness"] == d.get("rotor_effectiveness")
            assert (json.loads(r["hypotheses"]) if r["hypotheses"] is not None else None) == d.get("hypotheses")
    # Vehicle 2 bent propeller 3 from its second flight on: the verdicts say so, its first flight and vehicle 1 do not.
    assert by_name["vehicle_2/flight_02.tlog"]["faulty_propellers"] == [3]
    assert by_name["vehicle_2/flight_03.tlog"]["faulty_propellers"] == [3]
    assert by_name["vehicle_2/flight_01.tlog"]["faulty_propellers"] == []
    assert all(by_name[f"vehicle_1/flight_0{k}.tlog"]["faulty_propellers"] == [] for k in (1, 2, 3))


def test_bad_logs_are_error_rows_with_the_reason(serial_db):
    errs = {Path(r["path"]).name: r for r in rows(serial_db) if r["status"] == "error"}
    assert set(errs) == {"corrupt.tlog", "empty.ulg", "foreign.bin"}
    assert "empty file" in errs["empty.ulg"]["error"]
    assert "unknown log format" in errs["foreign.bin"]["error"] and "foreign.bin" in errs["foreign.bin"]["error"]
    assert "corrupt.tlog" in errs["corrupt.tlog"]["error"]
    assert all(r["verdict_label"] is None and r["p_faulty"] is None for r in errs.values())


def test_reingest_skips_known_content_and_takes_only_new_logs(serial_db, fleet_dir, tmp_path):
    before = rows(serial_db)
    again = ingest([str(fleet_dir)], serial_db, settings=PAPER, ray_address="off", progress=False)
    assert (again.found, again.already_known, again.new, again.hashed) == (9, 9, 0, 0)  # nothing re-read
    assert rows(serial_db) == before
    touched = fleet_dir / "sim" / "vehicle_1" / "flight_02.tlog"
    os.utime(touched, ns=(time.time_ns(), time.time_ns()))  # new mtime, same bytes: re-read, still known
    again = ingest([str(fleet_dir)], serial_db, settings=PAPER, ray_address="off", progress=False)
    assert (again.already_known, again.new, again.hashed) == (9, 0, 1)
    assert (
        ingest([str(fleet_dir)], serial_db, settings=PAPER, ray_address="off", progress=False).hashed == 0
    )  # new mtime recorded
    assert ingest([str(fleet_dir)], serial_db, settings=PAPER, ray_address="off", progress=False, rehash=True).hashed == 9
    # A copy under another name is the same flight; a new file is ingested alone.
    extra = tmp_path / "more"
    extra.mkdir()
    shutil.copy(fleet_dir / "sim" / "vehicle_1" / "flight_01.tlog", extra / "same_bytes.tlog")
    (extra / "new.tlog").write_bytes(b"\x00" * 100)
    s = ingest([str(fleet_dir), str(extra)], serial_db, settings=PAPER, ray_address="off", progress=False)
    assert (s.already_known, s.new, s.error) == (10, 1, 1)
    assert len(rows(serial_db)) == 10


@pytest.mark.usefixtures("ray_local")
def test_ray_rows_equal_serial_rows(fleet_dir, serial_db, tmp_path):
    db = tmp_path / "ray.duckdb"
    s = ingest([str(fleet_dir / "sim")], db, settings=PAPER, ray_address="auto", progress=False)
    assert s.mode == "ray" and s.new == 6 and s.ok == 6
    keep = ("log_hash", "vehicle_id", "start_time_utc", "status", "verdict_label", "faulty_propellers", "p_faulty", "diagnosis")
    ray_rows = {r["log_hash"]: {k: r[k] for k in keep} for r in rows(db)}
    serial = {r["log_hash"]: {k: r[k] for k in keep} for r in rows(serial_db) if r["log_hash"] in ray_rows}
    assert ray_rows == serial


def _kill_one_running_task(name: str, killed: list[int], stop: threading.Event, give_up_s: float = 60.0) -> None:
    """SIGKILL the first process whose title says it is running ``name`` (Ray sets ``ray::<task>``, ``ray::<Actor.method>``)."""
    t_end = time.monotonic() + give_up_s
    while not stop.is_set() and time.monotonic() < t_end:
        for pid in filter(str.isdigit, os.listdir("/proc")):
            try:
                with open(f"/proc/{pid}/cmdline", "rb") as f:
                    title = f.read().split(b"\0")[0]
            except OSError:
                continue
            if title.strip() == f"ray::{name}".encode():
                os.kill(int(pid), signal.SIGKILL)
                killed.append(int(pid))
                return
        time.sleep(0.01)


@pytest.mark.usefixtures("ray_local")
def test_a_worker_killed_mid_run_loses_no_row(fleet_dir, tmp_path):
    db = tmp_path / "killed.duckdb"
    killed: list[int] = []
    stop = threading.Event()
    killer = threading.Thread(target=_kill_one_running_task, args=("LogWorker.process_batch", killed, stop))
    killer.start()
    try:
        s = ingest(
            [str(fleet_dir / "sim")], db, settings=PAPER, ray_address="auto", progress=False, batch_rows=2, logs_per_call=2
        )
    finally:
        stop.set()
        killer.join()
    assert killed, "no worker was seen running a task: the kill did not happen"
    assert killed[0] not in s.worker_pids  # the rows of the killed call came from its retry in a restarted worker
    got = rows(db)
    assert len(got) == 6 and len({r["log_hash"] for r in got}) == 6 and len({r["path"] for r in got}) == 6
    assert all(r["status"] == "ok" for r in got), [r["error"] for r in got]


def test_a_newer_or_foreign_database_is_refused(tmp_path):
    db = tmp_path / "new.duckdb"
    open_db(db).close()
    con = duckdb.connect(str(db))
    con.execute("UPDATE fleet_meta SET value = ? WHERE key = 'schema_version'", [str(SCHEMA_VERSION + 7)])
    con.close()
    with pytest.raises(FleetError, match=f"schema version {SCHEMA_VERSION + 7} is newer"):
        open_db(db)
    foreign = tmp_path / "other.duckdb"
    con = duckdb.connect(str(foreign))
    con.execute("CREATE TABLE sales (x INTEGER)")
    con.close()
    with pytest.raises(FleetError, match="not a propwatch fleet database"):
        open_db(foreign)
    text = tmp_path / "notes.duckdb"
    text.write_text("hello\n" * 100)
    with pytest.raises(FleetError, match="notes.duckdb"):
        open_db(text)


def test_a_batch_is_committed_whole_or_not_at_all(tmp_path):
    con = open_db(tmp_path / "t.duckdb")
    good = [empty_row(Path(f"/x/{i}.tlog"), f"h{i}", 1) | {"status": "ok"} for i in range(3)]
    insert_rows(con, good[:1])
    bad = good[1:] + [empty_row(Path("/x/dup.tlog"), "h0", 1) | {"status": "ok"}]  # h0 again: primary key
    with pytest.raises(duckdb.Error):
        insert_rows(con, bad)
    assert con.execute("SELECT count(*) FROM flights").fetchone()[0] == 1
    con.close()


def test_unreachable_ray_address_fails_fast_naming_it(fleet_dir, tmp_path, capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # closed once the block ends: nothing listens there
    t0 = time.monotonic()
    code = propwatch(
        ["fleet", "ingest", str(fleet_dir / "bad"), "--db", str(tmp_path / "x.duckdb"), "--ray", f"127.0.0.1:{port}"]
    )
    assert code == 2 and time.monotonic() - t0 <= 30.0
    assert f"127.0.0.1:{port}" in capsys.readouterr().err


def test_export_parquet_holds_the_table(serial_db, fleet_dir, tmp_path, capsys):
    pq = pytest.importorskip("pyarrow.parquet")
    out = tmp_path / "out" / "fleet.parquet"
    args = ["fleet", "ingest", str(fleet_dir / "sim"), "--db", str(serial_db), "--ray", "off", "--export", str(out), "--json"]
    assert propwatch(args) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["new"] == 0 and summary["export"] == str(out)
    t = pq.read_table(out)
    assert t.num_rows == len(rows(serial_db))
    assert {"log_hash", "vehicle_id", "p_faulty", "rotor_effectiveness", "hypotheses"} <= set(t.column_names)


def test_rotor_effectiveness_and_hypotheses_are_stored_in_px4_order(serial_db):
    by_name = {Path(r["path"]).parent.name + "/" + Path(r["path"]).name: r for r in rows(serial_db)}
    bent = by_name["vehicle_2/flight_03.tlog"]  # propeller 3 bent: its rotor gives less thrust than commanded
    eff = bent["rotor_effectiveness"]
    assert eff is not None and len(eff) == 4 and len(bent["rotor_effectiveness_std"]) == 4
    assert min(range(4), key=lambda i: eff[i]) == 2 and eff[2] < 0.97
    assert 3 in json.loads(bent["hypotheses"])[0]["faulty_propellers"]
    healthy = by_name["vehicle_1/flight_01.tlog"]["rotor_effectiveness"]
    assert all(abs(e - 1.0) < 0.05 for e in healthy)


@pytest.mark.realdata
def test_real_logs_give_their_vehicle_ids(tmp_path):
    if not DATA.is_dir():
        pytest.skip(f"real data not found at {DATA}")
    s = IngestSettings(vehicle_from_dir=1)
    bin_ = DATA / "ardupilot_log171" / "log171.bin"
    ulg = DATA / "px4_ulog" / "sample_log_small.ulg"
    r1 = process_log(str(bin_), "a", bin_.stat().st_size, s)
    r2 = process_log(str(ulg), "b", ulg.stat().st_size, s)
    r3 = process_log(str(DATA / "px4_ulog" / "sample.ulg"), "c", 1, s)
    assert (r1["vehicle_id"], r1["vehicle_id_source"]) == ("004A002F3334511932383433", "dataflash:MSG board uid")
    assert r1["start_time_utc"].year == 2015 and r1["start_time_source"] == "dataflash:gps" and r1["status"] == "ok"
    assert r2["vehicle_id_source"] == "ulog:sys_uuid" and r2["start_time_utc"].year == 2021
    assert (r3["vehicle_id"], r3["vehicle_id_source"], r3["status"]) == ("px4_ulog", "dir:1", "no_verdict")
    with pytest.raises(FleetError, match="no such file"):
        ingest([str(tmp_path / "nowhere")], tmp_path / "x.duckdb", settings=PAPER, ray_address="off")


def test_ray_calls_hold_every_log_once_largest_first():
    from fleet.ingest import ray_batches

    todo = [(f"/logs/{i:02d}.tlog", f"h{i}", size) for i, size in enumerate([5, 90, 5, 40, 7, 90, 1])]
    calls = ray_batches(todo, 3)
    assert [len(c) for c in calls] == [3, 3, 1]
    flat = [job for call in calls for job in call]
    assert sorted(flat) == sorted(todo)  # each log exactly once
    assert [size for _, _, size in flat] == [90, 90, 40, 7, 5, 5, 1]  # the long logs start first
    assert flat[:2] == [todo[1], todo[5]]  # ties in path order: the same calls on every run
    assert ray_batches(todo, 0) == [[job] for job in flat]


def test_rediagnose_replaces_stale_rows_each_log_still_once(serial_db, fleet_dir, tmp_path):
    db = tmp_path / "copy.duckdb"
    shutil.copy(serial_db, db)
    before = {r["log_hash"]: r for r in rows(db)}
    con = duckdb.connect(str(db))
    stale = next(h for h, r in before.items() if r["status"] == "ok")
    con.execute("UPDATE flights SET verdict_label = 16, model_version = 'an older model' WHERE log_hash = ?", [stale])
    con.close()
    plain = ingest([str(fleet_dir / "sim")], db, settings=PAPER, ray_address="off", progress=False)
    still = {r["log_hash"]: r for r in rows(db)}[stale]
    assert plain.new == 0 and still["verdict_label"] == 16  # without the flag the stale verdict stays
    assert plain.other_model == 1 and plain.to_json()["other_model"] == 1  # ... but the run says it is another model's
    s = ingest([str(fleet_dir / "sim")], db, settings=PAPER, ray_address="off", progress=False, rediagnose=True, batch_rows=4)
    assert s.rediagnose and s.new == 6 and s.already_known == 0
    after = {r["log_hash"]: r for r in rows(db)}
    assert len(after) == len(before)  # each log exactly once
    assert after[stale]["verdict_label"] == before[stale]["verdict_label"]
    assert after[stale]["model_version"] == before[stale]["model_version"]


def test_a_replacing_batch_is_whole_or_not_at_all(tmp_path):
    con = open_db(tmp_path / "t.duckdb")
    old = [empty_row(Path(f"/x/{i}.tlog"), f"h{i}", 1) | {"status": "ok"} for i in range(2)]
    insert_rows(con, old)
    new = [r | {"status": "no_verdict"} for r in old]
    insert_rows(con, new[:1], replace=True)
    assert con.execute("SELECT status FROM flights WHERE log_hash = 'h0'").fetchone()[0] == "no_verdict"
    broken = [new[1], new[1]]  # the same log twice in one batch: the insert fails after the delete
    with pytest.raises(duckdb.Error):
        insert_rows(con, broken, replace=True)
    assert con.execute("SELECT status FROM flights WHERE log_hash = 'h1'").fetchone()[0] == "ok"  # old row kept
    con.close()


def test_model_version_covers_the_set_rule_and_the_decision_calibration_beside_the_model(tmp_path):
    # A stored verdict is stale when the set rule or the decision thresholds that made it changed, not only the
    # model file: model_version digests all three (the calibration only when it is this model's).
    import hashlib

    from fleet.worker import SHIPPED_MODELS, model_version
    from monitor.decision.hypotheses import rule_path
    from monitor.decision.thresholds import DEFAULT_CALIBRATION

    shipped = SHIPPED_MODELS[0]
    if not rule_path(shipped).is_file():
        pytest.skip("the shipped model has no set rule")
    model = tmp_path / "classifier.onnx"
    shutil.copy(shipped, model)
    shutil.copy(rule_path(shipped), rule_path(model))
    v = model_version(model)
    assert v == model_version(model) and len(v) == 12 and v == model_version(shipped)
    rule = json.loads(rule_path(model).read_text())
    rule["threshold"] = 0.5 if rule.get("threshold") != 0.5 else 0.25
    rule_path(model).write_text(json.dumps(rule))
    recalibrated = model_version(model)
    assert recalibrated != v  # the same model file, another set rule
    rule_path(model).unlink()
    assert model_version(model) not in (v, recalibrated)  # no set rule at all
    cal = json.loads(DEFAULT_CALIBRATION.read_text())
    other = tmp_path / "other.onnx"
    other.write_bytes(model.read_bytes() + b"another model")  # not the calibration's model: it is left out
    assert cal["model_sha256"] != hashlib.sha256(other.read_bytes()).hexdigest()
    assert model_version(other) == hashlib.sha256(other.read_bytes()).hexdigest()[:12]
    assert model_version(model) != hashlib.sha256(model.read_bytes()).hexdigest()[:12]  # the shipped one's is in
