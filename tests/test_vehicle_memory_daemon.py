"""The daemon's vehicle memory (monitor.daemon.memory_adapter): learns landed, disarmed, quiet flights; judges from
take-off."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

from monitor.daemon.memory_adapter import MIN_LEARN_S, VehicleMemory
from monitor.memory.baseline import VehicleBaseline

RATE_HZ = 20.0
QUIRKY = np.array([1.03, 0.97, 0.95, 1.05])


def fly(mem: VehicleMemory, share, seconds=60.0, seed=0, ground_s=2.0, load=1.0):
    """Steps of one flight (ground, airborne ``seconds``, ground), the collective ``load`` times the references';
    returns the announcements."""
    rng = np.random.default_rng(seed)
    out = []
    n_air, n_gnd = int(seconds * RATE_HZ), int(ground_s * RATE_HZ)
    t = 0.0
    for i in range(n_gnd + n_air + n_gnd):
        air = n_gnd <= i < n_gnd + n_air
        s = np.asarray(share) * (1 + 0.01 * rng.standard_normal(4))
        rpm = 6000.0 * np.sqrt(load * s) if air else np.full(4, 1000.0)
        a = mem.step(t, air, rpm, 0.01 * rng.standard_normal(), 0.01 * rng.standard_normal())
        if a is not None:
            out.append((t - n_gnd / RATE_HZ, a))
        t += 1 / RATE_HZ
    return out


def healthy_share(k):
    return QUIRKY + np.random.default_rng(100 + k).normal(0, 0.003, 4)


def test_learns_three_flights_then_names_damage_present_at_take_off(tmp_path):
    mem = VehicleMemory(tmp_path / "state", RATE_HZ)
    mem.identify(sysid=1)
    assert mem.status() == "; no vehicle baseline yet for sysid-1 (0 of 3 flights)"
    for k in range(3):
        assert fly(mem, healthy_share(k), seed=k) == []
        assert mem.disarmed(None) == "learnt"
        assert mem.status() == f"; no vehicle baseline yet for sysid-1 ({k + 1} of 3 flights)" or k == 2
    assert mem.status().startswith("; vehicle sysid-1: against 3 healthy flights of this vehicle")
    assert (tmp_path / "state" / "vehicles" / "sysid-1" / "baseline.json").is_file()
    share = QUIRKY.copy()
    share[2] /= 1 - 0.08  # propeller 3 damaged before take-off
    alerts = fly(mem, share, seed=50)
    assert alerts, "no alert on a flight damaged from take-off"
    t, a = alerts[0]
    assert a.level == "fault" and a.propellers == (3,) and t <= 15.0, (t, a.text)
    assert mem.disarmed(None) == "not learnt: it raised an alert"
    assert len(VehicleBaseline.load(mem.path).active()) == 3
    for k in range(3, 8):  # later healthy flights stay quiet and are learnt
        assert fly(mem, healthy_share(k), seed=k) == []
        assert mem.disarmed(None) == "learnt"


def test_a_load_off_centre_is_said_as_a_suspect_and_not_learnt(tmp_path):
    mem = VehicleMemory(tmp_path / "state", RATE_HZ)
    mem.identify(sysid=1)
    for k in range(3):
        fly(mem, healthy_share(k), seed=k)
        assert mem.disarmed(None) == "learnt"
    moved = QUIRKY * np.array([1.12, 0.88, 1.0, 1.0])  # the CG moved 0.06 arm toward rotor 1: shares +-2 x 0.06
    heavier = fly(mem, moved, seed=60, load=1.25)  # with 25 % more load: the load explains it
    assert heavier and {a.level for _, a in heavier} == {"suspect"}, [a.text for _, a in heavier]
    assert mem.disarmed(None) == "not learnt: it raised an alert"
    same = fly(mem, moved, seed=61)  # at the references' load: rotor 1 works harder, a damaged propeller
    assert any(a.level == "fault" and a.propellers == (1,) for _, a in same), [a.text for _, a in same]


def test_never_learns_a_stopped_stream_a_short_or_an_unverified_flight(tmp_path):
    mem = VehicleMemory(tmp_path, RATE_HZ)
    mem.identify(sysid=7)
    fly(mem, healthy_share(0), seconds=MIN_LEARN_S - 5)
    assert mem.disarmed(None).startswith("not learnt: too short")
    fly(mem, healthy_share(1), seed=1)
    assert mem.disarmed(False) == "not learnt: not every frame was signed and verified"
    # a stream that stops in the air: no landing, no disarm of a landed flight
    for i in range(int(60 * RATE_HZ)):
        mem.step(i / RATE_HZ, True, 6000 * np.sqrt(healthy_share(2)), 0.0, 0.0)
    mem.discard("autopilot rebooted")
    assert mem.disarmed(None) == "no flight"
    assert not (tmp_path / "vehicles").exists()


def test_each_vehicle_its_own_baseline_and_notes_are_kept(tmp_path):
    mem = VehicleMemory(tmp_path, RATE_HZ)
    mem.identify(sysid=1)
    fly(mem, healthy_share(0))
    assert mem.disarmed(None) == "learnt"
    mem.identify(sysid=1, uid=0x5057000000000002)
    assert mem.status() == "; no vehicle baseline yet for uid-5057000000000002 (0 of 3 flights)"  # another file
    fly(mem, healthy_share(1), seed=1)
    assert mem.disarmed(None) == "learnt"
    p = tmp_path / "vehicles" / "uid-5057000000000002" / "baseline.json"
    r = subprocess.run(
        [sys.executable, "-m", "monitor.cli", "baseline", "note", str(p), "--event", "props-replaced"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    fly(mem, healthy_share(2), seed=2)
    assert mem.disarmed(None) == "learnt"
    b = VehicleBaseline.load(p)
    assert [e["event"] for e in b.events] == ["props-replaced"] and len(b.active()) == 1 and len(b.flights) == 2


def test_a_state_dir_that_cannot_be_written_is_said_and_monitoring_goes_on(tmp_path):
    (tmp_path / "file").write_text("not a folder")
    mem = VehicleMemory(tmp_path / "file", RATE_HZ)
    mem.identify(sysid=1)
    fly(mem, healthy_share(0))
    what = mem.disarmed(None)
    assert what.startswith("not learnt: vehicle memory off for this run: state dir") and "Not a directory" in what
    assert mem.status() == f"; {what.removeprefix('not learnt: ')}"
    assert fly(mem, healthy_share(1), seed=1) == []  # still judging (nothing to judge against), no exception


def test_a_failed_write_leaves_the_old_baseline(tmp_path, monkeypatch):
    mem = VehicleMemory(tmp_path, RATE_HZ)
    mem.identify(sysid=1)
    fly(mem, healthy_share(0))
    assert mem.disarmed(None) == "learnt"
    before = mem.path.read_bytes()

    def power_cut(fd):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(os, "fsync", power_cut)
    fly(mem, healthy_share(1), seed=1)
    assert mem.disarmed(None).startswith("not learnt: state dir not writable")
    assert mem.path.read_bytes() == before and [p.name for p in mem.path.parent.iterdir()] == ["baseline.json"]


def test_daemon_process_learns_and_alerts_from_take_off(tmp_path):
    """The real daemon over replayed logs: 3 references learnt at landing and disarm, then a flight damaged from
    take-off alerted by the vehicle memory within 15 s, naming its propeller; STATUS before the baseline exists."""
    from offline.vehicles.ours import write_fleet

    fleet = tmp_path / "fleet"
    write_fleet(fleet, 5, seed=5, duration_s=45.0)  # 3 references, a healthy later flight, rotor 2 damaged
    state = tmp_path / "state"

    def replay(i):
        ev = tmp_path / f"ev{i}.jsonl"
        cmd = [sys.executable, "-m", "monitor.cli", "monitor", "--connect", str(fleet / f"ours_vehicles_{i:04d}.tlog")]
        r = subprocess.run(
            [*cmd, "--tlog-speed", "0", "--state-dir", str(state), "--events", str(ev)],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert r.returncode == 0, r.stderr[-2000:]
        return r.stderr, [json.loads(x) for x in ev.read_text().splitlines()] if ev.exists() else []

    err, _ = replay(0)
    assert "no vehicle baseline yet for sysid-1 (1 of 3 flights)" in err
    for i in (1, 2, 3):
        err, events = replay(i)
        assert not [e for e in events if e.get("event") == "alert"], events
    err, events = replay(4)
    faults = [e for e in events if e.get("level") == "fault"]
    assert faults and faults[0]["faulty_propellers"] == [2] and faults[0]["evidence"] == "vehicle memory"
    assert faults[0]["time_boot_ms"] / 1000 < 5.1 + 15  # take-off at the log's first airborne step (boot 5.05 s)
    b = VehicleBaseline.load(state / "vehicles" / "sysid-1" / "baseline.json")
    assert len(b.active()) == 4  # the references and the healthy later flight, never the damaged one


def test_the_daemon_asks_the_autopilot_for_its_uid_at_most_three_times_and_keys_the_memory_by_it(tmp_path):
    """AUTOPILOT_VERSION carries the board's uid: the daemon asks for it (a few times, not forever), and once it comes
    the vehicle's memory is that board's, not the system id's."""
    import time

    from pymavlink.dialects.v20 import common as mavlink

    from monitor.daemon.autopilot import AUTOPILOT_VERSION_ID, VERSION_REQUESTS
    from monitor.model import Classifier
    from tests.fuzz_helpers import FakeLink, decoded, make_daemon, px4_stream
    from tests.test_daemon_helpers import toy_model

    class AskingLink(FakeLink):
        def request_message(self, *args) -> None:
            self.sent.append(("REQUEST_MESSAGE", *args))

    def asked(link):
        return [s for s in link.sent if s[0] == "REQUEST_MESSAGE"]

    d, _ = make_daemon(Classifier(toy_model(tmp_path / "toy.onnx")))
    d.link = d.autopilot.link = link = AskingLink()
    d.memory = d.stage.memory = d.autopilot.memory = mem = VehicleMemory(tmp_path / "state", RATE_HZ)
    for m in px4_stream(0.0, 2.0, sys_id=7):
        d.handle(m, time.perf_counter())
    assert mem.sysid == 7 and mem.uid is None
    sysid_path = mem.path
    for k in range(10):  # ten housekeeping turns, each past the retry period
        d.tick(1e6 * (k + 1))
    assert len(asked(link)) == VERSION_REQUESTS
    assert all(a[1:] == (7, 1, AUTOPILOT_VERSION_ID) for a in asked(link))
    uid = 0x1234_5678_9ABC
    version = mavlink.MAVLink_autopilot_version_message(0, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, uid)
    disarmed = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3)
    d.handle(decoded(disarmed, 7), time.perf_counter())  # on the ground: a uid is taken (in flight it is not)
    d.handle(decoded(version, 7), time.perf_counter())
    assert mem.uid == uid and mem.path != sysid_path and f"{uid:016x}" in str(mem.path)
    link.sent.clear()
    # even a fresh budget asks no more once the uid is known
    d.autopilot.version_requests, d.autopilot.next_version_request = 0, 0.0
    d.tick(1e7)
    assert asked(link) == []


def test_a_landing_reads_the_history_once_inside_its_write_and_keeps_none_of_it(tmp_path, monkeypatch):
    """Between landings the daemon holds the normal and the counts STATUS shows, not every past flight's record
    (its RSS grew with the history); a landing reads the file once, under the write lock, and learns from that."""
    mem = VehicleMemory(tmp_path / "state", RATE_HZ)
    mem.identify(sysid=1)
    for k in range(4):
        fly(mem, healthy_share(k), seed=k)
        assert mem.disarmed(None) == "learnt"
    reads = []
    real = VehicleBaseline.from_text.__func__
    monkeypatch.setattr(VehicleBaseline, "from_text", classmethod(lambda cls, *a: reads.append(a[1]) or real(cls, *a)))
    fly(mem, healthy_share(4), seed=4)
    reads.clear()  # the take-off's read (notes made on the ground)
    assert mem.disarmed(None) == "learnt"
    assert len(reads) == 1, reads
    assert not [k for k, v in vars(mem).items() if isinstance(v, VehicleBaseline)]
    assert mem.history.flights == 5 and mem.history.active == 5 and mem.normal.n_flights == 5
    assert mem.status().startswith("; vehicle sysid-1: against 5 healthy flights of this vehicle")
    assert len(VehicleBaseline.load(mem.path).flights) == 5
