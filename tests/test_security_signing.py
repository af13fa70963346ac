"""MAVLink 2 signing that one forged frame cannot poison (docs/SECURITY.md, attacks S1-S5).

The daemon runs on a real ``udpin`` link (``test_fuzz_link.run_daemon``); the
genuine flight is signed with the shared key, the forger's frames claim the
autopilot's ids (system 1, component 1, link id 0) without the key.
"""

from __future__ import annotations

import logging
import subprocess
import sys

import pytest
from pymavlink.dialects.v20 import common as mavlink
from test_fuzz_link import KEY, WRONG_KEY, _key_file, flight, run_daemon, sign_and_pack, toy  # noqa: F401

from monitor.daemon.link import read_signing_key
from monitor.daemon.signing import FUTURE_SLACK_S, REANCHOR_S, TIMESTAMP_UNITS_PER_S, SignatureGate

FAR_FUTURE = 2**48 - 2  # the largest signing timestamp but one


def forged_far_future_heartbeat() -> bytes:
    """A HEARTBEAT of system 1 / component 1 carrying a signature block with timestamp 2^48-2 and a junk
    signature (its CRC is right: the signature block is outside it)."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id = WRONG_KEY, True, 0
    mav.signing.timestamp = FAR_FUTURE
    frame = bytearray(mavlink.MAVLink_heartbeat_message(2, 12, 129, 0, 4, 3).pack(mav))
    frame[-6:] = b"\xa5" * 6
    return bytes(frame)


def _frame(key: bytes, stamp: int, link_id: int = 0, sys_id: int = 1) -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=sys_id, srcComponent=1)
    mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id = key, True, link_id
    mav.signing.timestamp = stamp
    return bytes(mavlink.MAVLink_heartbeat_message(2, 12, 129, 0, 4, 3).pack(mav))


def test_one_forged_far_future_frame_does_not_stop_the_signed_flight(tmp_path, toy, flight, caplog):  # noqa: F811
    caplog.set_level(logging.INFO)
    genuine = sign_and_pack(flight, KEY)
    frames = [(genuine[0][0] - 0.01, forged_far_future_heartbeat()), *genuine]
    daemon, got, _ = run_daemon(tmp_path, toy, frames, {"link": {"signing_key_path": _key_file(tmp_path, KEY)}})
    rep = daemon.report()
    assert rep["alerts"] >= 1, rep
    assert rep["link"]["signing"]["refused"] == {"bad signature": 1}
    assert rep["link"]["flight_authenticated"] is True
    assert got  # the autopilot hears us
    # Refused frames are counted, never one journal line each (pymavlink's own 'sig mismatch' lines included).
    assert not [r for r in caplog.records if r.name.startswith("pymavlink")]


def test_a_wrong_key_stream_from_start_up_neither_hides_the_autopilot_nor_floods_the_journal(
    tmp_path,
    toy,  # noqa: F811
    flight,  # noqa: F811
    caplog,
):
    caplog.set_level(logging.INFO)
    genuine = sign_and_pack(flight, KEY)
    now = genuine[0][1]
    stamp0 = int.from_bytes(now[-12:-6], "little") + 3600 * TIMESTAMP_UNITS_PER_S  # an hour ahead, the genuine ids
    frames = []
    for i, (t, f) in enumerate(genuine):
        if i % 5 == 0:
            frames.append((t, _frame(WRONG_KEY, stamp0 + i)))
        frames.append((t, f))
    daemon, _, _ = run_daemon(tmp_path, toy, frames, {"link": {"signing_key_path": _key_file(tmp_path, KEY)}})
    rep = daemon.report()
    assert rep["alerts"] >= 1, rep
    assert rep["link"]["pin"]["system_id"] == 1
    forged = sum(1 for i in range(len(genuine)) if i % 5 == 0)
    assert rep["link"]["signing"]["refused"]["bad signature"] > 0.5 * forged
    told = [r.getMessage() for r in caplog.records if "bad signature frames from 127.0.0.1:" in r.getMessage()]
    assert len(told) == 1, told  # announced once, then counted
    assert len(caplog.records) < 60  # the journal holds a page, not a line per refused frame


def test_timestamps_are_bounded_by_the_last_verified_one_plus_elapsed_time_per_stream():
    now = [1000.0]
    gate = SignatureGate(KEY, clock=lambda: now[0])
    t0 = 300_000_000_000
    assert gate.check(_frame(KEY, t0), 1, 1) == ""
    assert gate.check(_frame(KEY, t0), 1, 1) == "replayed"
    assert gate.check(_frame(KEY, t0 - 5), 1, 1) == "replayed"
    ahead = t0 + int((FUTURE_SLACK_S + 10.0) * TIMESTAMP_UNITS_PER_S)
    assert gate.check(_frame(KEY, ahead), 1, 1) == "timestamp ahead"
    now[0] += 11.0  # the sender's clock may have run on since: the same timestamp is now within bounds
    assert gate.check(_frame(KEY, ahead), 1, 1) == ""
    # Streams are (link id, system, component): another link id keeps its own last timestamp (here 50 s behind the
    # first stream's, within the spec's minute for a new stream) ...
    assert gate.check(_frame(KEY, ahead - 50 * TIMESTAMP_UNITS_PER_S, link_id=3), 1, 1) == ""
    # ... and a new stream far behind (or far ahead of) the verified clock is refused.
    assert gate.check(_frame(KEY, t0 - 10_000_000, sys_id=2), 2, 1) == "stale new stream"
    assert gate.check(_frame(KEY, ahead + 10**9, sys_id=2), 2, 1) == "timestamp ahead"
    assert gate.check(_frame(WRONG_KEY, ahead + 100), 1, 1) == "bad signature"
    assert gate.check(_frame(KEY, ahead + 100)[:-13], 1, 1) == "unsigned"
    assert set(gate.streams) == {(0, 1, 1), (3, 1, 1)}


def test_a_genuine_signing_clock_that_jumps_forward_is_followed_after_it_keeps_to_it():
    now = [0.0]
    gate = SignatureGate(KEY, clock=lambda: now[0])
    t0 = 100_000_000
    assert gate.check(_frame(KEY, t0), 1, 1) == ""
    jumped = t0 + 86_400 * TIMESTAMP_UNITS_PER_S  # GPS time arrives at the autopilot: a day forward
    refused = 0
    for k in range(40):
        now[0] = 0.1 * (k + 1)
        stamp = jumped + int(now[0] * TIMESTAMP_UNITS_PER_S)
        refused += gate.check(_frame(KEY, stamp), 1, 1) != ""
    assert gate.jumps == 1
    assert refused == pytest.approx(REANCHOR_S / 0.1, abs=1)  # refused only until it kept the new clock for REANCHOR_S
    assert gate.check(_frame(KEY, t0 + 10), 1, 1) == "replayed"


@pytest.mark.parametrize("case", ["missing", "unreadable"])
def test_a_missing_or_unreadable_signing_key_exits_2_naming_the_path(tmp_path, case):
    key_path = tmp_path / "nowhere" / "signing.key"
    if case == "unreadable":  # a directory where the key should be (tests run as root: modes would not stop a read)
        key_path.mkdir(parents=True)
    cfg = tmp_path / "monitor.yaml"
    cfg.write_text(f"link:\n  signing_key_path: {key_path}\n")
    r = subprocess.run(
        [sys.executable, "-m", "monitor", "--connect", "udpin:127.0.0.1:0", "--config", str(cfg)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2, r.stderr
    assert str(key_path) in r.stderr and "signing key" in r.stderr


def test_keygen_writes_a_private_key_the_daemon_reads_and_never_overwrites_one(tmp_path):
    path = tmp_path / "signing.key"
    run = [sys.executable, "-m", "monitor.cli", "keygen", str(path)]
    r = subprocess.run(run, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    first = read_signing_key(path)
    assert len(first) == 32 and (path.stat().st_mode & 0o777) == 0o600
    r = subprocess.run(run, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and str(path) in r.stderr and read_signing_key(path) == first
    r = subprocess.run([*run, "--force"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and read_signing_key(path) != first
