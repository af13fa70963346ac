"""Two vehicles on one link each keep their own history (docs/SECURITY.md, docs/VEHICLE_MEMORY.md): a recording of
two autopilots through one router, each flight landed and disarmed, read by the daemon with a state dir."""

from __future__ import annotations

import json
import os
import socket
import struct
import subprocess
import sys
import threading

import pytest
from pymavlink.dialects.v20 import common as mavlink

from monitor.mavlink.player import read_tlog
from monitor.memory.baseline import VehicleBaseline


def _as_system(frames, sys_id: int, shift_s: float):
    """Vehicle 1's frames re-numbered as system ``sys_id``, ``shift_s`` later (its AUTOPILOT_VERSION left out)."""
    senders: dict[int, mavlink.MAVLink] = {}
    out = []
    for t, _, m in frames:
        if m.get_type() == "AUTOPILOT_VERSION":
            continue
        comp = m.get_srcComponent()
        mav = senders.setdefault(
            comp, mavlink.MAVLink(None, srcSystem=sys_id if m.get_srcSystem() == 1 else 255, srcComponent=comp)
        )
        out.append((t + shift_s, bytes(m.pack(mav))))
    return out


@pytest.fixture(scope="module")
def two_vehicles(tmp_path_factory):
    """A recording of two autopilots through one router, read by the daemon with a state dir, under a systemd
    notify socket: (the run, the state dir, the events file, every STATUS it sent)."""
    from offline.vehicles.ours import write_fleet

    tmp_path = tmp_path_factory.mktemp("two")
    fleet = write_fleet(tmp_path / "fleet", 2, seed=5, duration_s=45.0)  # two healthy reference flights
    one = read_tlog(fleet / "ours_vehicles_0000.tlog")
    two = read_tlog(fleet / "ours_vehicles_0001.tlog")
    merged = _as_system(one, 1, 0.0) + _as_system(two, 2, one[0][0] - two[0][0] + 0.3)  # the same hour, one router
    tlog = tmp_path / "two.tlog"
    with open(tlog, "wb") as fh:
        for t, frame in sorted(merged, key=lambda e: e[0]):
            fh.write(struct.pack(">Q", int(t * 1e6)) + frame)
    state, ev = tmp_path / "state", tmp_path / "events.jsonl"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(tmp_path / "notify"))
    sock.settimeout(0.2)
    sent: list[str] = []
    done = threading.Event()

    def listen() -> None:
        while not done.is_set():
            try:
                sent.append(sock.recv(65536).decode())
            except TimeoutError:
                continue

    listener = threading.Thread(target=listen)
    listener.start()
    cmd = [sys.executable, "-m", "monitor.cli", "monitor", "--connect", str(tlog), "--tlog-speed", "0"]
    env = {**os.environ, "NOTIFY_SOCKET": str(tmp_path / "notify")}
    try:
        r = subprocess.run(
            [*cmd, "--state-dir", str(state), "--events", str(ev)], capture_output=True, text=True, timeout=300, env=env
        )
    finally:
        done.set()
        listener.join()
        sock.close()
    statuses = [line.removeprefix("STATUS=") for m in sent for line in m.splitlines() if line.startswith("STATUS=")]
    return r, state, ev, statuses


def test_two_autopilots_through_one_router_each_land_a_flight_into_their_own_history(two_vehicles):
    r, state, ev, _ = two_vehicles
    assert r.returncode == 0, r.stderr[-2000:]
    assert "system 2 monitored as its own vehicle" in r.stderr or "system 1 monitored as its own vehicle" in r.stderr
    for key in ("sysid-1", "sysid-2"):
        b = VehicleBaseline.load(state / "vehicles" / key / "baseline.json")
        assert len(b.flights) == 1, key  # each vehicle's landing into its own file, never the other's
    learnt = [e for e in map(json.loads, ev.read_text().splitlines()) if e.get("event") == "vehicle_memory"]
    assert sorted(e["status"].split(" for ")[-1].split(" ")[0] for e in learnt) == ["sysid-1", "sysid-2"], learnt
    assert all(e["flight"] == "learnt" for e in learnt)


def test_with_two_autopilots_status_names_each_vehicle_and_its_memory(two_vehicles):
    r, _, _, statuses = two_vehicles
    assert r.returncode == 0, r.stderr[-2000:]
    both = [s for s in statuses if "system 1 (sysid-1: " in s and "system 2 (sysid-2: " in s]
    assert both, statuses[-5:]
    # each vehicle's memory as it learns: no history yet, then its one learnt flight
    assert any("(sysid-2: 0 of 3 flights)" in s for s in both), both[:5]
    assert any("(sysid-1: 1 of 3 flights)" in s for s in both) and any("(sysid-2: 1 of 3 flights)" in s for s in both), both[-5:]
    # each vehicle's own state after its name (the second's first clause: airborne, on the ground, an alert)
    assert all(s.split(" | ")[1].split("): ", 1)[1] for s in both), both[-5:]
