"""Vehicle memory (monitor.memory): summaries, the baseline file, learning, the judgement, the CLI, and one verdict
from `diagnose --baseline` and `fleet ingest` on the same history."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from monitor.flight import FlightTable
from monitor.memory import thresholds as th
from monitor.memory.baseline import BaselineError, VehicleBaseline
from monitor.memory.judge import judge
from monitor.memory.learn import HealthyOutlierError, learn_baseline
from monitor.memory.normal import normal_of
from monitor.memory.summary import ShareAccumulator, rotor_values, summarize

RATE_HZ = 20.0


def table(share, seconds=60.0, seed=0, noise=0.01, names=("1", "2", "3", "4")) -> FlightTable:
    """A hover whose rotors' omega^2 shares are ``share`` (4,) plus white noise of ``noise`` per step."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE_HZ)
    s = np.asarray(share, dtype=float) * (1 + noise * rng.standard_normal((n, 4)))
    rpm = 6000.0 * np.sqrt(s)
    z = np.zeros(n)
    return FlightTable(
        timestamp_us=np.arange(n, dtype=np.int64) * 50_000,
        motor_cmd=np.full((n, 4), 1500.0),
        motor_rpm=rpm,
        roll_rad=0.01 * rng.standard_normal(n),
        pitch_rad=0.01 * rng.standard_normal(n),
        yaw_rad=z,
        roll_rate_rad_s=z,
        pitch_rate_rad_s=z,
        yaw_rate_rad_s=z,
        battery_v=np.full(n, 16.0),
        airborne=np.ones(n, dtype=bool),
        rate_hz=RATE_HZ,
        source=f"synthetic-{seed}",
        motor_names=names,
    )


QUIRKY = np.array([1.03, 0.97, 0.95, 1.05])  # a vehicle whose CG and motors make its own normal


def healthy(k: int, seconds=60.0):
    # flight-to-flight wander of about a third of the population's spread
    wander = np.random.default_rng(100 + k).normal(0, 0.003, 4)
    return table(QUIRKY + wander, seconds, seed=k)


def damaged(rotor: int, loss: float, k: int = 50):
    share = QUIRKY.copy()
    share[rotor - 1] /= 1.0 - loss  # same thrust from a weaker propeller: omega^2 up by 1 / (1 - loss)
    return table(share, seed=k)


def test_step_by_step_equals_whole_table():
    t = healthy(0, 30.0)
    x, basis = rotor_values(t)
    acc = ShareAccumulator(basis, RATE_HZ)
    air = t.airborne.copy()
    air[200:240] = False  # a landing and a second take-off: the settle time restarts
    for i in range(len(t)):
        acc.step(x[i], t.roll_rad[i], t.pitch_rad[i], bool(air[i]))
    whole = ShareAccumulator(basis, RATE_HZ)
    whole.table(x[:300], t.roll_rad[:300], t.pitch_rad[:300], air[:300])  # and in two chunks
    whole.table(x[300:], t.roll_rad[300:], t.pitch_rad[300:], air[300:])
    a, b = acc.summary.to_dict(), whole.summary.to_dict()
    assert a.pop("basis") == b.pop("basis") == "omega2"
    for k in a:
        np.testing.assert_allclose(np.asarray(a[k], dtype=float), np.asarray(b[k], dtype=float), rtol=1e-12, atol=1e-12)
    # 600 steps, less the 2-s settle after each of the two take-offs and the 40 on the ground
    assert a["n"] == 600 - 40 - 2 * 40


def test_summary_of_a_known_share():
    share = QUIRKY + np.random.default_rng(101).normal(0, 0.003, 4)
    np.testing.assert_allclose(summarize(healthy(1)).mean_share(), share / share.mean(), atol=2e-3)


def baseline_of(n=3) -> VehicleBaseline:
    return learn_baseline(
        [healthy(k) for k in range(n)],
        [f"h{k}" for k in range(n)],
        vehicle_id="uid:1",
        dates=[f"2026-05-0{k + 1}" for k in range(n)],
    )


@pytest.mark.parametrize("rotor", [1, 2, 3, 4])
def test_a_quirky_vehicle_names_a_propeller_damaged_from_take_off(rotor):
    b = baseline_of()
    v = judge(b.normal(), summarize(damaged(rotor, 0.08)))
    assert (v["faulty_propellers"], v["confidence"]) == ([rotor], "confident")
    if rotor == 3:  # against the nominal airframe (equal shares) the quirk outweighs the damage: rotor 4 looks worst
        assert int(np.argmax(summarize(damaged(rotor, 0.08)).mean_share())) + 1 == 4


def test_healthy_later_flights_stay_quiet_and_say_what_they_exclude():
    b = baseline_of()
    for k in range(10, 20):
        v = judge(b.normal(), summarize(healthy(k)))
        assert v["label"] == 1 and v["faulty_propellers"] == []
        assert v["confidence"] in ("confident", "ambiguous")
        assert 0 < v["detectable_loss"] <= 0.06 or v["confidence"] != "confident"


def test_never_confident_healthy_where_a_rotor_is_beyond_its_spread():
    b = baseline_of()
    normal = b.normal()
    sigma = np.sqrt(np.diag(normal.deviation_cov(summarize(healthy(30)))))
    for rotor in range(1, 5):
        for spreads in (4.0, 6.0, 10.0):
            share = QUIRKY.copy()
            share[rotor - 1] += spreads * sigma[rotor - 1] * np.mean(QUIRKY)
            v = judge(normal, summarize(table(share, seed=60 + rotor)))
            assert not (v["label"] == 1 and v["confidence"] == "confident"), (rotor, spreads, v["rule"])


def test_round_trip_and_bad_files(tmp_path):
    b = baseline_of()
    p = b.save(tmp_path / "B.json")
    c = VehicleBaseline.load(p)
    assert c.to_dict() == json.loads(json.dumps(b.to_dict()))
    np.testing.assert_allclose(c.normal().intercept, b.normal().intercept)
    (tmp_path / "bad.json").write_text(p.read_text()[:200])
    with pytest.raises(BaselineError, match="bad.json: corrupt"):
        VehicleBaseline.load(tmp_path / "bad.json")
    d = json.loads(p.read_text())
    d["version"] = 99
    (tmp_path / "future.json").write_text(json.dumps(d))
    with pytest.raises(BaselineError, match="version 99 is newer"):
        VehicleBaseline.load(tmp_path / "future.json")
    d["version"], d["flights"][0]["summary"]["sum_share"] = 1, [1, 2, "x", 4]
    (tmp_path / "field.json").write_text(json.dumps(d))
    with pytest.raises(BaselineError, match="field.json"):
        VehicleBaseline.load(tmp_path / "field.json")


def test_learning_refuses_too_few_a_damaged_flight_and_another_airframe():
    with pytest.raises(BaselineError, match="at least 3 flights"):
        learn_baseline([healthy(0), healthy(1)], ["a", "b"], vehicle_id="v")
    with pytest.raises(HealthyOutlierError, match="d.tlog: given as healthy.*rotor 3"):
        learn_baseline([healthy(0), healthy(1), healthy(2), damaged(3, 0.10)], ["a", "b", "c", "d.tlog"], vehicle_id="v")
    other = table(QUIRKY, names=("M1", "M2", "M3", "M4"))
    with pytest.raises(BaselineError, match="mix airframes"):
        learn_baseline([healthy(0), healthy(1), other], ["a", "b", "c"], vehicle_id="v")
    b = baseline_of()
    with pytest.raises(BaselineError, match="vehicle uid:2, but the baseline is of vehicle uid:1"):
        b.check_vehicle("uid:2", ("1", "2", "3", "4"), "omega2", "x.tlog")


def test_maintenance_restarts_the_normal():
    b = baseline_of()
    assert b.ready
    assert b.note("battery-replaced", "2026-05-04") is False and b.ready
    assert b.note("props-replaced", "2026-05-05") is True and not b.ready
    for k in range(3):
        b.add(f"n{k}", None, summarize(healthy(40 + k)), "no fault")
    assert b.ready and b.compared_with()["flights"] == 3
    with pytest.raises(BaselineError, match="unknown event 'washed'"):
        b.note("washed", None)


def test_the_prior_weighs_as_stated():
    # With one flight the spread is the prior's; with many identical ones it shrinks toward the vehicle's own.
    one = normal_of([summarize(healthy(0))])
    np.testing.assert_allclose(one.cov, np.asarray(th.PRIOR_COV))


# -- the CLI and one verdict across diagnose and the fleet ----------------------------------------------------------


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """One vehicle of our simulator: 3 healthy references, then 5 later flights (2 damaged from take-off)."""
    from offline.vehicles.ours import write_fleet

    out = tmp_path_factory.mktemp("vehicle") / "vehicle_a"
    write_fleet(out, 8, seed=5, duration_s=30.0)
    return out


def run(*args):
    return subprocess.run([sys.executable, "-m", "monitor.cli", *args], capture_output=True, text=True, timeout=300)


def test_cli_learn_show_note_and_bad_input(fleet, tmp_path):
    logs = [str(fleet / f"ours_vehicles_{i:04d}.tlog") for i in range(3)]
    r = run("baseline", "learn", *logs, "--out", str(tmp_path / "B.json"))
    assert r.returncode == 0, r.stderr
    assert "against 3 healthy flights of this vehicle, 2024-06-01 to 2024-06-03" in r.stdout
    shown = json.loads(run("baseline", "show", str(tmp_path / "B.json"), "--json").stdout)
    assert shown["compared_with"] == {"flights": 3, "first": "2024-06-01", "last": "2024-06-03"}
    before = (tmp_path / "B.json").read_bytes()
    r = run("baseline", "note", str(tmp_path / "B.json"), "--event", "washed")
    assert r.returncode == 2 and "washed" in r.stderr and (tmp_path / "B.json").read_bytes() == before
    r = run("baseline", "learn", logs[0], logs[1], "--out", str(tmp_path / "C.json"))
    assert r.returncode == 2 and "at least 3 flights" in r.stderr and not (tmp_path / "C.json").exists()
    damaged_log = str(fleet / "ours_vehicles_0004.tlog")  # rotor 2 damaged
    r = run("baseline", "learn", *logs, damaged_log, "--out", str(tmp_path / "D.json"))
    assert r.returncode == 2 and "ours_vehicles_0004.tlog: given as healthy" in r.stderr and "rotor 2" in r.stderr
    r = run("baseline", "note", str(tmp_path / "B.json"), "--event", "props-replaced", "--date", "2024-06-09")
    assert r.returncode == 0 and "restarts" in r.stdout
    assert "no vehicle baseline yet (0 of 3 flights)" in run("baseline", "show", str(tmp_path / "B.json")).stdout


def test_diagnose_and_fleet_give_one_verdict_on_the_same_history(fleet, tmp_path):
    pytest.importorskip("duckdb")
    import duckdb

    from fleet.ingest import ingest

    ingest([str(fleet)], tmp_path / "f.duckdb", ray_address="off", progress=False)
    con = duckdb.connect(str(tmp_path / "f.duckdb"), read_only=True)
    rows = con.execute(
        "SELECT path, log_hash, verdict_label, confidence, baseline_flights, compared_with_logs FROM flights ORDER BY start_time_utc"
    ).fetchall()
    paths = {h: p for p, h, *_ in rows}
    truth = {r[0]: json.loads(Path(r[0]).with_suffix(".json").read_text())["faulty_propellers"] for r in rows}
    judged = [r for r in rows if r[4] >= 3]
    assert len(judged) == 5
    for path, _, label, conf, n, hist in judged:
        b = tmp_path / f"{Path(path).stem}.B.json"
        r = run("baseline", "learn", *[paths[h] for h in hist], "--out", str(b))
        assert r.returncode == 0, r.stderr
        r = run("diagnose", path, "--baseline", str(b), "--json")
        out = json.loads(r.stdout)
        assert (out["verdict"]["label"], out["verdict"]["confidence"]) == (label, conf), path
        assert out["baseline"]["compared_with"]["flights"] == n
        # and the verdict is right: the damaged propeller named, the healthy flights healthy
        from monitor.labels import LABEL_TABLE

        assert list(LABEL_TABLE[label]) == truth[path], (path, label, conf)
        # confident, except a healthy call on a flight that carried another load than its references: a load off
        # centre could hide a damaged propeller's share move (monitor.memory.load)
        load = out["baseline"]["load"]["change"]
        assert conf == "confident" or (truth[path] == [] and abs(load) > 0.05), (path, label, conf, load)


def test_diagnose_refuses_another_vehicles_baseline(fleet, tmp_path):
    logs = [str(fleet / f"ours_vehicles_{i:04d}.tlog") for i in range(3)]
    assert run("baseline", "learn", *logs, "--out", str(tmp_path / "B.json")).returncode == 0
    d = json.loads((tmp_path / "B.json").read_text())
    d["vehicle"]["id"] = "someone-else"
    (tmp_path / "O.json").write_text(json.dumps(d))
    r = run("diagnose", str(fleet / "ours_vehicles_0005.tlog"), "--baseline", str(tmp_path / "O.json"))
    assert r.returncode == 2 and "but the baseline is of vehicle someone-else" in r.stderr
    shutil.copy(tmp_path / "B.json", tmp_path / "E.json")
    (tmp_path / "E.json").write_text("{")
    r = run("diagnose", str(fleet / "ours_vehicles_0005.tlog"), "--baseline", str(tmp_path / "E.json"))
    assert r.returncode == 2 and "E.json: corrupt vehicle baseline" in r.stderr


def test_fleet_an_older_log_changes_judged_verdicts_only_with_rediagnose(fleet, tmp_path):
    """Later flights first (two damaged from take-off among them, before any normal exists), then the three older
    references: judged rows stand until --rediagnose; a damaged flight never stays in a history that is used."""
    pytest.importorskip("duckdb")
    import duckdb

    from fleet.ingest import ingest

    later, refs = tmp_path / "later", tmp_path / "refs"
    later.mkdir()
    refs.mkdir()
    for i in range(8):
        shutil.copy(fleet / f"ours_vehicles_{i:04d}.tlog", (refs if i < 3 else later) / f"f{i}.tlog")
    damaged = {"f4.tlog": [2], "f5.tlog": [3], "f7.tlog": [1]}
    db = tmp_path / "f.duckdb"

    def rows():
        con = duckdb.connect(str(db), read_only=True)
        try:
            q = "SELECT path, log_hash, baseline_flights, faulty_propellers, confidence, compared_with_logs FROM flights"
            out = con.execute(q).fetchall()
        finally:
            con.close()
        names = {h: Path(p).name for p, h, *_ in out}
        return {Path(p).name: (n, fp, conf, sorted(names[x] for x in (hist or []))) for p, _, n, fp, conf, hist in out}

    ingest([str(later)], db, ray_address="off", progress=False)
    first = rows()
    for name, (n, fp, conf, hist) in first.items():
        if n >= 3:  # judged by the vehicle's memory (before: the nominal verdict, whatever it says)
            assert not set(hist) & set(damaged), (name, hist)
            assert not (conf == "confident" and fp) or fp == damaged.get(name), (name, fp)
    ingest([str(refs)], db, ray_address="off", progress=False)  # three older flights arrive later
    second = rows()
    assert all(second[k] == first[k] for k in first)  # judged verdicts stand
    ingest([str(refs), str(later)], db, ray_address="off", progress=False, rediagnose=True)
    third = rows()
    for name in ("f3.tlog", "f4.tlog", "f5.tlog", "f6.tlog", "f7.tlog"):
        n, fp, conf, hist = third[name]
        assert n >= 3 and not set(hist) & set(damaged), (name, hist)
        assert (fp, conf) == (damaged.get(name, []), "confident") or (not fp and name not in damaged), (name, fp, conf)


def _without_vehicle_id(src: Path, dst: Path) -> Path:
    """A copy of ``src`` with its appended AUTOPILOT_VERSION record (the last one) cut off."""
    data = src.read_bytes()
    at = data.rfind(b"\xfd")
    while at >= 0 and data[at + 7 : at + 10] != b"\x94\x00\x00":  # MAVLink 2 frame of message 148
        at = data.rfind(b"\xfd", 0, at)
    assert at > 8
    dst.write_bytes(data[: at - 8])
    return dst


def test_cli_learn_needs_one_identified_vehicle(fleet, tmp_path):
    from offline.fleet_sim import append_autopilot_version

    logs = [fleet / f"ours_vehicles_{i:04d}.tlog" for i in range(3)]
    anon = [_without_vehicle_id(p, tmp_path / f"anon{i}.tlog") for i, p in enumerate(logs)]
    r = run("baseline", "learn", *map(str, anon), "--out", str(tmp_path / "A.json"))
    assert r.returncode == 2 and "no vehicle identity in the log: give --vehicle-id" in r.stderr
    assert not (tmp_path / "A.json").exists()
    r = run("baseline", "learn", *map(str, anon), "--out", str(tmp_path / "A.json"), "--vehicle-id", "quad-7")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "A.json").read_text())["vehicle"]["id"] == "quad-7"
    other = _without_vehicle_id(logs[2], tmp_path / "other.tlog")
    append_autopilot_version(other, 0x1234)
    r = run("baseline", "learn", str(logs[0]), str(logs[1]), str(other), "--out", str(tmp_path / "B.json"))
    assert r.returncode == 2 and "the logs are of 2 vehicles" in r.stderr and not (tmp_path / "B.json").exists()


def test_an_airframe_where_cg_and_damage_look_alike_gets_an_imbalance_never_a_propeller():
    """CrazyPAD: a mass near a rotor and a cut propeller on it move the shares alike (offline/crazypad/README.md);
    a baseline that says so turns a propeller verdict into an imbalance naming both causes and no propeller."""
    from monitor.diagnose.engine import Diagnosis
    from monitor.diagnose.memory_adapter import judge_flight

    b = baseline_of()
    t = damaged(2, 0.10)
    d = Diagnosis(source="cut", verdict=None, windows=0, warnings=[])
    out = judge_flight(d, t, b, None)
    assert d.verdict["faulty_propellers"] == [2] and d.verdict["confidence"] == "confident"
    b.cg_damage_separable = False
    d = Diagnosis(source="cut", verdict=None, windows=0, warnings=[])
    out = judge_flight(d, t, b, None)
    assert d.verdict["faulty_propellers"] == [] and d.verdict["confidence"] == "ambiguous"
    assert out["imbalance_rotors"] == [2] and any("CG offset toward rotor 2" in h.get("cause", "") for h in d.hypotheses)
    assert VehicleBaseline.from_dict(json.loads(json.dumps(b.to_dict())), "x").cg_damage_separable is False


CRAZYPAD = Path(__file__).resolve().parents[2] / "shared" / "data" / "crazypad"


@pytest.mark.realdata
@pytest.mark.skipif(not (CRAZYPAD / "motor").is_dir(), reason=f"CrazyPAD data not found at {CRAZYPAD}")
def test_real_crazypad_flights_against_their_airframes_own_history():
    """E8's even-numbered healthy logs as its history (real Crazyflie flights): a 3 mm cut on M3 (PX4 rotor 2) puts
    rotor 2 first past the fault level; the odd-numbered healthy logs are not called faulty; with the airframe's
    finding that a CG offset and damage look alike, the cut is an imbalance and no propeller is named. The real
    sessions drift: E8_log00 is itself beyond the other three by this rule, and learning it as declared is refused."""
    from monitor.diagnose.engine import Diagnosis
    from monitor.diagnose.memory_adapter import judge_flight
    from monitor.logs import read_log
    from monitor.vehicle import REPO_ROOT, load_vehicle

    esc = load_vehicle(REPO_ROOT / "models" / "crazyflie.yaml").esc
    e8 = CRAZYPAD / "motor" / "normal_flight"
    read = lambda p: read_log(p, fmt="crazypad", esc=esc)  # noqa: E731
    cal = [read(e8 / f"E8_log0{i}.csv.gz") for i in (0, 2, 4, 6)]
    with pytest.raises(HealthyOutlierError, match="E8_log00.csv.gz: given as healthy"):
        learn_baseline(cal, [f"E8_log0{i}.csv.gz" for i in (0, 2, 4, 6)], vehicle_id="E8")
    b = learn_baseline(cal, [f"E8_log0{i}.csv.gz" for i in (0, 2, 4, 6)], vehicle_id="E8", check_healthy=False)
    cut = judge(b.normal(), summarize(read(CRAZYPAD / "motor" / "cut_propeller_M3_3mm" / "E8_log02.csv.gz")))
    assert cut["fault_statistic"] >= th.FAULT_STATISTIC and cut["hypotheses"][0]["faulty_propellers"] == [2]
    for i in (1, 3, 5):
        v = judge(b.normal(), summarize(read(e8 / f"E8_log0{i}.csv.gz")))
        assert v["faulty_propellers"] == [], (i, v["rule"])
    b.cg_damage_separable = False
    d = Diagnosis(source="cut", verdict=None, windows=0, warnings=[])
    out = judge_flight(d, read(CRAZYPAD / "motor" / "cut_propeller_M3_3mm" / "E8_log02.csv.gz"), b, None)
    assert d.verdict["faulty_propellers"] == [] and 2 in out["imbalance_rotors"]


def test_an_adapt_folder_with_an_older_baseline_is_refused_naming_the_way_out(fleet, tmp_path):
    d = tmp_path / "adapted"
    d.mkdir()
    (d / "baseline.json").write_text(json.dumps({"basis": "omega2", "shares_mean": [1, 1, 1, 1], "n_flights": 3}))
    r = run("diagnose", str(fleet / "ours_vehicles_0004.tlog"), "--vehicle", str(d))
    assert r.returncode == 2 and "baseline.json: an adapt baseline from before vehicle memory" in r.stderr
    assert "propwatch baseline learn" in r.stderr
