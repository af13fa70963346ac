"""Trust only the autopilot: MAVLink 2 signing, allow-lists and udpin replies, over real loopback sockets.

The daemon runs in a thread on a real ``udpin`` Link; flights are sent from
real UDP sockets, signed by pymavlink's own signing where the case says so.
The forged stream claims the autopilot's ids (system 1, component 1).
"""

from __future__ import annotations

import socket
import threading
import time

import pytest
from fuzz_helpers import RecordingNotifier
from pymavlink.dialects.v20 import common as mavlink
from test_daemon_helpers import UDP_SPEED, synth_flight, toy_model

from monitor.daemon.cli import guard
from monitor.daemon.config import monitor_config_from_mapping
from monitor.daemon.events import EventWriter
from monitor.daemon.link import Link, read_signing_key
from monitor.daemon.pipeline import Pipeline
from monitor.daemon.service import Daemon
from monitor.errors import ConfigError
from monitor.esc import PAPER_ESC
from monitor.model import Classifier

KEY = bytes(range(32))
WRONG_KEY = bytes(range(1, 33))
# Take-off at 2 s, the pin's 2 s of heartbeats, a 5-s window, then about 8 s of saturated windows for the toy
# network's FAULT (the decision rule's analytic threshold): a FAULT by ~17 s, with margin.
FLIGHT_S = 24.0
SPEED = UDP_SPEED  # the daemon in a thread of this process, beside the sender


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return Classifier(toy_model(tmp_path_factory.mktemp("model") / "toy.onnx"))


@pytest.fixture(scope="module")
def flight():
    """The synthetic flight (one propeller faulty) as parsed messages with their send times."""
    p = mavlink.MAVLink(None)
    out = []
    for t, frame in synth_flight(FLIGHT_S, faulty=(3,), seed=4):
        for m in p.parse_buffer(frame) or []:
            # ESC_STATUS (id 291; UNKNOWN_291 unless a decoder registered it): not used with motor_source
            # servo, and no MAVLink 1 frame can carry it.
            if not m.get_type().startswith("UNKNOWN") and m.get_msgId() <= 255:
                out.append((t, m))
    return out


def sign_and_pack(msgs, key: bytes | None, mavlink1: bool = False, sys_id: int | None = None) -> list[tuple[float, bytes]]:
    """Re-pack every message as its own sender would, signing with ``key`` (None: unsigned); ``sys_id`` re-numbers
    the vehicle (system 1) as another."""
    senders: dict[tuple[int, int], mavlink.MAVLink] = {}
    out = []
    for t, m in msgs:
        ids = (m.get_srcSystem(), m.get_srcComponent())
        if sys_id is not None and ids[0] == 1:
            ids = (sys_id, ids[1])
        mav = senders.get(ids)
        if mav is None:
            mav = senders[ids] = mavlink.MAVLink(None, srcSystem=ids[0], srcComponent=ids[1])
            if key is not None:
                mav.signing.secret_key = key
                mav.signing.sign_outgoing = True
                mav.signing.link_id = 0
                mav.signing.timestamp = int((time.time() - 1420070400) * 100_000)
        out.append((t, bytes(m.pack(mav, force_mavlink1=mavlink1))))
    return out


def run_daemon(tmp_path, classifier, frames, config: dict, extra_senders: int = 0, sender_addr="127.0.0.1"):
    """Daemon on udpin in a thread; ``frames`` sent paced from one socket (the autopilot's)."""
    daemon, got, others_got = run_senders(tmp_path, classifier, frames, config, [(sender_addr, 0)], extra_senders)
    return daemon, got[0], others_got


def run_senders(tmp_path, classifier, frames, config: dict, binds, extra_senders: int = 0):
    """Daemon on udpin in a thread; ``frames`` are (time, frame) or (time, frame, k), sent paced from the socket
    bound to ``binds[k]`` (k = 0 when not given). Returns the daemon, what each of those sockets received, and
    how many datagrams the ``extra_senders`` (ground stations sending HEARTBEATs) received."""
    # The link is under test, not the rule: the toy network is the evidence that raises FAULT here (the default lets
    # only the omega^2 shares; the rule's own tests are in test_decision*.py and test_fuzz_daemon.py), declared the
    # synthetic vehicle's classifier (undeclared, a network is silent).
    # Replayed at SPEED: the pin waits the same boot time as at real pace (PX4's 1 Hz heartbeats, two seconds).
    link_cfg = {"pin_wait_s": 2.0 / SPEED, **config.get("link", {})}
    cfg = monitor_config_from_mapping(
        {"alerts": {"fault_evidence": "all"}, "airframe_declared": True, **config, "link": link_cfg}
    )
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    port = rx.getsockname()[1]
    rx.close()
    link = Link(f"udpin:127.0.0.1:{port}", cfg.link.component_id, system_id=cfg.link.system_id or None, guard=guard(cfg))
    events = EventWriter(tmp_path / "events.jsonl")
    daemon = Daemon(cfg, link, Pipeline(classifier, cfg, PAPER_ESC), events, RecordingNotifier())
    th = threading.Thread(target=daemon.run, daemon=True)
    th.start()
    socks = []
    for addr in binds:
        socks.append(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
        socks[-1].bind(addr)
    others = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(extra_senders)]
    gcs_hb = bytes(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(mavlink.MAVLink(None, 255, 190)))
    t0, w0 = frames[0][0], time.monotonic()
    for i, (t, frame, *k) in enumerate(frames):
        delay = w0 + (t - t0) / SPEED - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        socks[k[0] if k else 0].sendto(frame, ("127.0.0.1", port))
        if others and i % 20 == 0:
            others[(i // 20) % len(others)].sendto(gcs_hb, ("127.0.0.1", port))
    time.sleep(0.5)
    daemon.stop.set()
    th.join(10)
    link.close()
    got = [_drain(s) for s in socks]
    others_got = sum(len(_drain(s)) for s in others)
    for s in [*socks, *others]:
        s.close()
    return daemon, got, others_got


def _drain(sock) -> list[bytes]:
    sock.setblocking(False)
    out = []
    while True:
        try:
            out.append(sock.recv(65535))
        except BlockingIOError:
            return out


def _key_file(tmp_path, key: bytes, hex_: bool = False):
    p = tmp_path / "signing.key"
    if hex_:
        p.write_text(key.hex() + "\n")
    else:
        p.write_bytes(key)
    return str(p)


def test_signed_stream_is_verified_and_answered_signed_only_to_the_autopilot(tmp_path, toy, flight):
    cfg = {"link": {"signing_key_path": _key_file(tmp_path, KEY, hex_=True), "max_peers": 4}}
    daemon, got, others_got = run_daemon(tmp_path, toy, sign_and_pack(flight, KEY), cfg, extra_senders=12)
    rep = daemon.report()
    assert rep["pipeline"]["classified"] > 0 and rep["alerts"] >= 1, rep
    assert rep["link"]["signing"]["good"] > 0 and rep["link"]["peers_remembered"] <= 4
    # Replies go to the autopilot's address only, and they are signed with our key.
    assert got and others_got == 0
    parser = mavlink.MAVLink(None)
    parser.signing.secret_key = KEY
    replies = [parser.decode(bytearray(b)) for b in got]
    assert {m.get_type() for m in replies} <= {"HEARTBEAT", "STATUSTEXT", "COMMAND_LONG"}
    assert all(b[0] == 0xFD and b[2] & 0x01 for b in got)  # MAVLink 2, incompat flag SIGNED


@pytest.mark.parametrize("forgery", ["unsigned", "wrong key", "mavlink1"])
def test_forged_stream_with_signing_on_gives_no_classification_and_no_alert(tmp_path, toy, flight, forgery):
    cfg = {"link": {"signing_key_path": _key_file(tmp_path, KEY)}}
    key = {"unsigned": None, "wrong key": WRONG_KEY, "mavlink1": None}[forgery]
    frames = sign_and_pack(flight, key, mavlink1=forgery == "mavlink1")
    daemon, got, _ = run_daemon(tmp_path, toy, frames, cfg)
    rep = daemon.report()
    assert rep["pipeline"]["classified"] == 0 and rep["alerts"] == 0, rep
    # Every frame that arrived was refused (loopback UDP may drop some on a busy machine).
    assert rep["pipeline"]["steps"] == 0 and rep["messages"] == 0
    assert rep["link"]["rejected"]["invalid or missing signature"] > len(frames) * 0.5
    assert got == []  # nothing is ever sent to a forger
    assert not (tmp_path / "events.jsonl").read_text()


def test_allow_lists_by_address_and_by_source(tmp_path, toy, flight):
    frames = sign_and_pack(flight, None)
    daemon, got, _ = run_daemon(tmp_path, toy, frames, {"link": {"allow_addresses": ["127.0.0.2"]}})
    rep = daemon.report()
    assert rep["messages"] == 0 and rep["link"]["rejected"]["address not allowed"] == len(frames) and got == []
    daemon, _, _ = run_daemon(tmp_path, toy, frames, {"link": {"allow_sources": ["1/1"]}})
    rep = daemon.report()
    assert rep["alerts"] >= 1 and rep["link"]["rejected"]["source not allowed"] > 0  # the GCS on 255/190
    assert not rep["ignored"]  # nothing from another source reached the decoder


def test_signing_key_file_and_allow_list_syntax_are_checked(tmp_path):
    bad = tmp_path / "short.key"
    bad.write_bytes(b"abc")
    with pytest.raises(ConfigError, match="32 raw bytes or 64 hex digits"):
        read_signing_key(bad)
    assert read_signing_key(_key_file(tmp_path, KEY, hex_=True)) == KEY
    with pytest.raises(ConfigError, match="allow_sources"):
        monitor_config_from_mapping({"link": {"allow_sources": ["1-1"]}})
    with pytest.raises(ConfigError, match="allow_addresses"):
        monitor_config_from_mapping({"link": {"allow_addresses": ["127.0.0.1:99999"]}})


def test_forged_signed_frames_from_many_streams_leave_no_signing_state(tmp_path):
    from monitor.daemon.link import LinkGuard
    from monitor.daemon.signing import MAX_STREAMS

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    port = rx.getsockname()[1]
    rx.close()
    link = Link(f"udpin:127.0.0.1:{port}", 191, guard=LinkGuard(signing_key=KEY))
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    hb = mavlink.MAVLink_heartbeat_message(2, 12, 129, 0, 4, 3)
    n = 0
    try:
        for link_id in range(3):
            for sys_id in range(1, 255):
                mav = mavlink.MAVLink(None, srcSystem=sys_id, srcComponent=1)
                mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id = WRONG_KEY, True, link_id
                mav.signing.timestamp = int((time.time() - 1420070400) * 100_000)
                tx.sendto(bytes(hb.pack(mav)), ("127.0.0.1", port))
                n += 1
                if n % 50 == 0:
                    while link.read(0.01):
                        pass
        while link.read(0.05):
            pass
        # Only verified streams are remembered: frames signed with another key leave no state at all.
        assert len(link.gate.streams) == 0 and MAX_STREAMS >= 1
        assert link.rejected["invalid or missing signature"] > 0.9 * n
    finally:
        tx.close()
        link.close()
