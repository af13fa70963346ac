"""A pinned autopilot: spoofers and second autopilots neither redirect nor silence the monitor (docs/SECURITY.md).

Real loopback sockets, the daemon on ``udpin`` in a thread (``test_fuzz_link.run_senders``). The vehicle's
flight has propeller 3 faulty from take-off; the spoofer sits on another port and claims the vehicle's ids.
"""

from __future__ import annotations

import logging
import socket
from pathlib import Path

import pytest
import yaml
from pymavlink.dialects.v20 import common as mavlink
from test_fuzz_link import FLIGHT_S, KEY, SPEED, _key_file, flight, run_senders, sign_and_pack, toy  # noqa: F401

from monitor.daemon.link import Link, LinkGuard

ROOT = Path(__file__).resolve().parents[1]
HOST = "127.0.0.1"


def spoofer_frames(t0: float, t1: float, key: bytes | None = None) -> list[tuple[float, bytes]]:
    """System 1 / component 1 from elsewhere: a "disarmed" HEARTBEAT at 5 Hz and a junk ATTITUDE stream at 20 Hz
    whose boot times run an hour ahead."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    if key is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id = key, True, 0
        mav.signing.timestamp = 10**12
    out = []
    k = 0
    while t0 + k * 0.05 < t1:
        t = t0 + k * 0.05
        if k % 4 == 0:
            out.append((t, bytes(mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3).pack(mav))))
        boot_ms = 3_600_000 + 50 * k
        out.append((t, bytes(mavlink.MAVLink_attitude_message(boot_ms, 3.0, 1.5, 3.0, 30.0, 30.0, 30.0).pack(mav))))
        k += 1
    return out


def merged(*streams: list, offsets=None) -> list[tuple[float, bytes, int]]:
    """(time, frame, sender index) of every stream, in time order; stream k is sent from ``binds[k]``."""
    out = [(t + (offsets or [0.0] * len(streams))[k], f, k) for k, s in enumerate(streams) for t, f in s]
    return sorted(out, key=lambda e: e[0])


def _free_port_bind(port: int) -> bool:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.bind((HOST, port))
        return True
    except OSError:
        return False
    finally:
        s.close()


def _shipped_link(tmp_path) -> dict:
    """deploy/monitor.yaml's link section as shipped; only the key file's path is this test's (same key bytes on both
    ends, as `propwatch keygen` and the autopilot's SETUP_SIGNING would put them), and the pin's wait is the same
    boot time at the replay's SPEED."""
    link = yaml.safe_load((ROOT / "deploy" / "monitor.yaml").read_text())["link"]
    assert link["signing_key_path"] and link["autopilot_address"], "the shipped config must sign and pin"
    return {**link, "signing_key_path": _key_file(tmp_path, KEY), "pin_wait_s": link["pin_wait_s"] / SPEED}


@pytest.mark.parametrize("spoofer_key", [None, b"\x07" * 32], ids=["unsigned spoofer", "wrong-key spoofer"])
def test_under_the_shipped_config_a_spoofer_on_another_port_gets_nothing_and_changes_nothing(
    tmp_path,
    toy,  # noqa: F811
    flight,  # noqa: F811
    spoofer_key,
):
    link = _shipped_link(tmp_path)
    ap_host, ap_port = link["autopilot_address"].rsplit(":", 1)
    if not _free_port_bind(int(ap_port)):
        pytest.skip(f"{link['autopilot_address']} is taken on this machine")
    genuine = sign_and_pack(flight, KEY)
    spoof = spoofer_frames(genuine[0][0], genuine[-1][0], spoofer_key)
    frames = merged(genuine, spoof, offsets=[0.0, -0.5])  # the spoofer speaks first
    daemon, got, _ = run_senders(tmp_path, toy, frames, {"link": link}, [(ap_host, int(ap_port)), (HOST, 0)])
    rep = daemon.report()
    assert rep["alerts"] >= 1, rep
    assert got[0] and got[1] == []  # the autopilot hears us, the spoofer never does
    assert rep["link"]["autopilot_address"] == link["autopilot_address"]
    assert rep["blind_spells"] == 0 and rep["link"]["flight_authenticated"] is True


def test_without_signing_a_spoofer_after_the_autopilot_cannot_redirect_or_silence_the_monitor(
    tmp_path,
    toy,  # noqa: F811
    flight,  # noqa: F811
):
    genuine = sign_and_pack(flight, None)
    spoof = spoofer_frames(genuine[0][0] + 3.0, genuine[-1][0])  # once the autopilot is pinned (2 s of heartbeats)
    frames = merged(genuine, spoof)
    daemon, got, _ = run_senders(tmp_path, toy, frames, {}, [(HOST, 0), (HOST, 0)])
    rep = daemon.report()
    assert rep["alerts"] >= 1, rep
    assert got[0] and got[1] == []
    assert rep["link"]["pin"]["refused"]["not the pinned autopilot link"] > 0.5 * len(spoof)
    assert rep["link"]["flight_authenticated"] is False  # unsigned: never a vehicle's history


def _two_vehicles(flight):  # noqa: F811
    """Vehicle 1 (propeller 3 faulty) and vehicle 2 (healthy, system 2), vehicle 2's first HEARTBEAT first."""
    from test_daemon_helpers import synth_flight

    p = mavlink.MAVLink(None)
    healthy = [
        (t, m)
        for t, frame in synth_flight(FLIGHT_S, faulty=(), seed=9)
        for m in p.parse_buffer(frame) or []
        if not m.get_type().startswith("UNKNOWN") and m.get_msgId() <= 255
    ]
    return sign_and_pack(flight, None), sign_and_pack(healthy, None, sys_id=2)


def test_two_autopilots_on_one_link_are_each_monitored_and_the_alert_names_the_damaged_ones_system(
    tmp_path,
    toy,  # noqa: F811
    flight,  # noqa: F811
    caplog,
):
    """One router, two vehicles, vehicle 2 (healthy) heard first: each is pinned and monitored as its own vehicle;
    vehicle 1's damaged propeller raises a FAULT that names system 1, answered as system 1 to its address."""
    import json

    caplog.set_level(logging.INFO)
    v1, v2 = _two_vehicles(flight)
    # One router, both vehicles; vehicle 2 three seconds ahead. Which is pinned first (the report's system_id) is
    # decided by the daemon's clock: each is pinned at the first heartbeat that spans pin_wait_s of its own, so a
    # lead shorter than one heartbeat period left it to the senders' pacing (0.3 s failed once on a loaded machine).
    frames = [(t, f, 0) for t, f, _ in merged(v1, v2, offsets=[0.0, -3.0])]
    daemon, got, _ = run_senders(tmp_path, toy, frames, {}, [(HOST, 0)])
    rep = daemon.report()
    assert rep["link"]["pin"]["system_id"] == 2 and set(rep["link"]["pin"]["vehicles"]) == {"1", "2"}
    assert rep["system_id"] == 2 and set(rep["other_vehicles"]) == {"1"}
    one = rep["other_vehicles"]["1"]
    assert one["system_id"] == 1 and one["pipeline"]["classified"] > 0 and rep["pipeline"]["classified"] > 0
    events = [json.loads(x) for x in (tmp_path / "events.jsonl").read_text().splitlines()]
    faults = [e for e in events if e["event"] == "alert" and e["level"] == "fault"]
    assert faults and {e["system_id"] for e in faults} == {1} and faults[0]["faulty_propellers"] == [3]
    assert rep["alerts"] == 0 and one["alerts"] >= 1  # the healthy vehicle 2 raised nothing
    p = mavlink.MAVLink(None)
    sent = [m for f in got[0] for m in p.parse_buffer(f) or []]
    texts = [m for m in sent if m.get_type() == "STATUSTEXT" and "FAULT" in m.text]
    assert texts and {m.get_srcSystem() for m in texts} == {1}  # from vehicle 1's companion, as its ground station sees
    assert {m.get_srcSystem() for m in sent if m.get_type() == "HEARTBEAT"} == {1, 2}
    said = [r.getMessage() for r in caplog.records if "monitored as its own vehicle" in r.getMessage()]
    assert len(said) == 1 and "system 1" in said[0]


def test_with_one_vehicle_allowed_the_first_heard_is_kept_and_the_other_announced(
    tmp_path,
    toy,  # noqa: F811
    flight,  # noqa: F811
    caplog,
):
    caplog.set_level(logging.INFO)
    v1, v2 = _two_vehicles(flight)
    frames = [(t, f, 0) for t, f, _ in merged(v1, v2, offsets=[0.0, -0.3])]
    daemon, got, _ = run_senders(tmp_path, toy, frames, {"link": {"max_vehicles": 1}}, [(HOST, 0)])
    rep = daemon.report()
    assert rep["link"]["pin"]["system_id"] == 2 and rep["other_vehicles"] == {}  # heard first; monitoring goes on
    assert rep["link"]["pin"]["conflict"].startswith("system 1 ") and "system 2 " in rep["link"]["pin"]["conflict"]
    assert rep["pipeline"]["steps"] > 0 and got[0]
    said = [r.getMessage() for r in caplog.records if "refused: another autopilot, heard after system 2" in r.getMessage()]
    assert len(said) == 1 and "link.system_id" in said[0]


@pytest.mark.parametrize("pin", ["system_id", "autopilot_address"])
def test_two_autopilots_the_pinned_one_keeps_its_alerts_and_the_other_is_announced(
    tmp_path,
    toy,  # noqa: F811
    flight,  # noqa: F811
    caplog,
    pin,
):
    caplog.set_level(logging.INFO)
    v1, v2 = _two_vehicles(flight)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((HOST, 0))
    v1_port = s.getsockname()[1]
    s.close()
    if pin == "system_id":  # both through one router: told apart by system id
        frames, binds, cfg = [(t, f, 0) for t, f, _ in merged(v1, v2, offsets=[0.0, -0.3])], [(HOST, v1_port)], {"system_id": 1}
    else:  # each on its own port: told apart by the pinned address
        frames, binds, cfg = (
            merged(v1, v2, offsets=[0.0, -0.3]),
            [(HOST, v1_port), (HOST, 0)],
            {"autopilot_address": f"{HOST}:{v1_port}"},
        )
    daemon, got, _ = run_senders(tmp_path, toy, frames, {"link": cfg}, binds)
    rep = daemon.report()
    assert rep["alerts"] >= 1, rep
    assert rep["link"]["pin"]["system_id"] == 1 and got[0]
    if pin == "autopilot_address":
        assert got[1] == []
    said = [r.getMessage() for r in caplog.records if r.getMessage().startswith(("refused: another", "refused: not the"))]
    assert len(said) == 1, said  # announced once


def test_a_network_link_without_signing_warns_once_that_it_trusts_the_network(caplog):
    caplog.set_level(logging.INFO)
    links = [Link(f"udpin:{HOST}:0", 191), Link(f"udpin:{HOST}:0", 191, guard=LinkGuard(signing_key=KEY))]
    for link in links:
        link.read(0.01)
        link.close()
    said = [r for r in caplog.records if "TRUSTS THE NETWORK" in r.getMessage()]
    assert len(said) == 1 and said[0].levelno == logging.WARNING
    assert "autopilot_address" in said[0].getMessage()


# -- the pin cannot be silenced: one packet, a second address, another computer --------------------------------


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _beat(sys_id: int = 1):
    from fuzz_helpers import decoded

    return decoded(mavlink.MAVLink_heartbeat_message(2, 12, 128 | 1, 0, 4, 3), sys_id)


def _pin(**kw):
    from monitor.daemon.pin import AutopilotPin

    clock = _Clock()
    return AutopilotPin(kw.pop("system_id", None), 1, kw.pop("address", None), 2.0, clock=clock, **kw), clock


AUTOPILOT, SECOND = ("127.0.0.1", 14580), ("127.0.0.1", 40404)


def test_the_same_system_from_a_second_address_is_announced_and_ignored_and_the_first_stays_pinned(caplog):
    pin, clock = _pin()
    for k in range(4):  # the autopilot, then a copy of its heartbeat from another port, each second
        clock.t = float(k)
        assert pin.admit(_beat(), AUTOPILOT) == (k >= 2)
        assert not pin.admit(_beat(), SECOND)
    assert pin.system_id == 1 and pin.address == AUTOPILOT
    said = [r.getMessage() for r in caplog.records if "the same system from another address" in r.getMessage()]
    assert len(said) == 1 and "127.0.0.1:40404" in said[0] and "link.autopilot_address" in said[0]


def test_one_packet_first_cannot_hold_the_pin():
    pin, clock = _pin()
    assert not pin.admit(_beat(1), SECOND)  # a spoofer's single heartbeat, heard first
    for k in range(1, 10):
        clock.t = float(k)
        pin.admit(_beat(1), AUTOPILOT)
    assert pin.pinned and pin.address == AUTOPILOT  # forgotten once silent, the autopilot pinned after it


def test_a_flood_of_forged_system_ids_pins_at_most_max_vehicles_and_each_refusal_is_announced_once(caplog):
    pin, clock = _pin(max_vehicles=3)
    for k in range(6):
        clock.t = float(k)
        for sys_id in range(1, 201):  # 200 system ids' autopilot heartbeats, each second, from one router
            pin.admit(_beat(sys_id), AUTOPILOT)
    assert len(pin.vehicles) == 3 and set(pin.vehicles.values()) == {AUTOPILOT}
    assert len(pin._candidates) <= 16 and len(pin.announced) <= 64
    said = [r.getMessage() for r in caplog.records if "past the 3 monitored (link.max_vehicles)" in r.getMessage()]
    assert said and len(said) == len(set(said))
    assert pin.admit(_beat(2), AUTOPILOT) == (2 in pin.vehicles)


def test_a_second_vehicle_from_its_own_port_is_pinned_there_and_its_system_from_elsewhere_refused(caplog):
    pin, clock = _pin()
    for k in range(4):
        clock.t = float(k)
        pin.admit(_beat(1), AUTOPILOT)
        pin.admit(_beat(2), SECOND)
    assert pin.vehicles == {1: AUTOPILOT, 2: SECOND} and pin.address_of(2) == SECOND and pin.address_of(None) == AUTOPILOT
    assert not pin.admit(_beat(2), AUTOPILOT)  # vehicle 2's system from vehicle 1's address
    assert any(
        "the same system from another address, heard after system 2 at 127.0.0.1:40404" in r.getMessage() for r in caplog.records
    )


def test_by_default_only_an_autopilot_on_this_computer_is_listened_to(caplog):
    pin, clock = _pin()
    for k in range(4):
        clock.t = float(k)
        assert not pin.admit(_beat(), ("10.0.0.5", 14550))
    assert not pin.pinned
    assert any("an autopilot on another computer" in r.getMessage() for r in caplog.records)
    pin, clock = _pin(address=("10.0.0.5", 14550))  # named: listened to
    for k in range(4):
        clock.t = float(k)
        pin.admit(_beat(), ("10.0.0.5", 14550))
    assert pin.pinned


def test_every_example_and_default_listens_on_loopback():
    import re

    from monitor.daemon.config import MonitorConfig

    where = ["monitor/daemon/cli.py", "deploy/README.md", "deploy/propwatch-monitor.service", "deploy/monitor.yaml", "README.md"]
    where += [str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md") if p.name != "SECURITY.md"]  # it cites the old
    texts = [(ROOT / p).read_text() for p in where]
    listens = [m for t in texts for m in re.findall(r"udpin:([\w.]+):\d+", t)]
    assert listens and set(listens) == {"127.0.0.1"}, listens
    assert MonitorConfig().link.autopilot_address == ""  # '' = the one loopback address that pins first
