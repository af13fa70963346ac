"""The daemon's vehicle memory under attack and fault: history kept, one daemon per state dir, every flight's outcome
said, flights without a landed state ended, the vehicle's identity stable. docs/SECURITY.md's table names these."""

from __future__ import annotations

import errno
import json
import logging
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from monitor.daemon.memory_adapter import IDLE_LANDED_S, VehicleMemory
from monitor.esc import PAPER_ESC
from monitor.logs.raw import LIFT_CMD
from monitor.memory import atomic
from monitor.memory.baseline import VehicleBaseline
from monitor.memory.store import StateDir, StateDirBusy
from tests.fuzz_helpers import decoded, make_daemon, px4_stream
from tests.test_security_memory import _newer
from tests.test_vehicle_memory_daemon import RATE_HZ, fly, healthy_share

ROOT = Path(__file__).resolve().parents[1]
IDLE_RPM = float(PAPER_ESC.cmd_to_rpm(LIFT_CMD["us"]))


def learnt_three(state: Path) -> VehicleMemory:
    mem = VehicleMemory(state, RATE_HZ, idle_rpm=IDLE_RPM)
    mem.identify(sysid=1)
    for k in range(3):
        fly(mem, healthy_share(k), seed=k)
        assert mem.disarmed(None) == "learnt"
    return mem


# -- 1. history is never destroyed by the daemon ------------------------------------------------------------------


def _other_rotors(p: Path):
    d = json.loads(p.read_text())
    d["vehicle"]["motor_names"] = ["M1", "M2", "M3", "M4"]
    p.write_text(json.dumps(d))


def _command_basis(p: Path):
    d = json.loads(p.read_text())
    d["vehicle"]["basis"] = "command"
    for f in d["flights"]:
        f["summary"]["basis"] = "command"
    p.write_text(json.dumps(d))


@pytest.mark.parametrize(
    "damage,why",
    [
        (_newer, "version 99 is newer"),
        (lambda p: p.write_bytes(p.read_bytes()[:500]), "not JSON"),
        (_other_rotors, "another airframe"),
        (_command_basis, "another airframe"),
    ],
)
def test_an_unusable_baseline_pauses_learning_for_its_vehicle_is_said_and_kept(tmp_path, damage, why):
    mem = learnt_three(tmp_path)
    mem.close()
    damage(mem.path)
    before = mem.path.read_bytes()
    mem = VehicleMemory(tmp_path, RATE_HZ, idle_rpm=IDLE_RPM)  # a restart, say after a rollback
    mem.identify(sysid=1)
    status = mem.status()
    assert status.startswith("; learning paused for sysid-1:") and why in status, status
    assert f"propwatch baseline reset --state-dir {tmp_path} --vehicle sysid-1" in status
    assert fly(mem, healthy_share(5), seed=5) == []  # monitoring goes on
    assert mem.disarmed(None) == "not learnt: learning paused for sysid-1 (its baseline cannot be used)"
    assert mem.path.read_bytes() == before
    with StateDir.open(tmp_path) as sd:
        moved = sd.reset("sysid-1")
    assert moved.read_bytes() == before
    fly(mem, healthy_share(6), seed=6)  # re-read at take-off: a new history
    assert mem.disarmed(None) == "learnt" and len(VehicleBaseline.load(mem.path).flights) == 1
    assert mem.status() == "; no vehicle baseline yet for sysid-1 (1 of 3 flights)"


# -- 3. the state dir is owned; 4. one writer --------------------------------------------------------------------


def test_a_state_dir_others_can_write_turns_memory_off_and_monitoring_goes_on(tmp_path):
    state = tmp_path / "state"
    state.mkdir()
    os.chmod(state, 0o777)
    mem = VehicleMemory(state, RATE_HZ)
    mem.identify(sysid=1)
    assert mem.status().startswith("; vehicle memory off for this run: state dir") and "mode 0777" in mem.status()
    assert fly(mem, healthy_share(0)) == []
    assert mem.disarmed(None).startswith("not learnt: vehicle memory off for this run")
    assert list(state.iterdir()) == []


def test_a_crash_left_temporary_file_is_removed_at_start_and_said(tmp_path, caplog):
    mem = learnt_three(tmp_path)
    mem.close()
    (mem.path.parent / ".baseline.json.4242.tmp").write_text("half")
    with caplog.at_level(logging.WARNING, "propwatch.monitor"):
        VehicleMemory(tmp_path, RATE_HZ)
    assert "removed 1 temporary files a crash left: vehicles/sysid-1/.baseline.json.4242.tmp" in caplog.text
    assert sorted(os.listdir(mem.path.parent)) == ["baseline.json"]


def test_a_second_daemon_on_the_state_dir_refuses_to_start_naming_the_first(tmp_path):
    first = VehicleMemory(tmp_path, RATE_HZ)
    with pytest.raises(StateDirBusy, match=f"in use by another propwatch monitor \\(pid {os.getpid()}\\)"):
        VehicleMemory(tmp_path, RATE_HZ)
    first.close()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "monitor.cli", "monitor", "--state-dir", str(tmp_path), "--events", str(tmp_path / "e")]
    running = subprocess.Popen([*cmd, "--connect", "udpin:127.0.0.1:14791"], env=env, stderr=subprocess.PIPE, text=True)
    try:
        for line in running.stderr:
            if "ready:" in line:
                break
        r = subprocess.run([*cmd, "--connect", "udpin:127.0.0.1:14792"], env=env, capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and f"in use by another propwatch monitor (pid {running.pid})" in r.stderr, r.stderr
        assert "Traceback" not in r.stderr
    finally:
        running.terminate()
        running.wait(timeout=30)


def test_a_full_disk_is_said_the_flight_not_learnt_and_the_next_one_is(tmp_path, monkeypatch):
    mem = learnt_three(tmp_path)
    before = mem.path.read_bytes()

    def full(fd, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(atomic.os, "write", full)
    fly(mem, healthy_share(3), seed=3)
    assert mem.disarmed(None) == "not learnt: disk full" and "disk full" in mem.status()
    assert mem.path.read_bytes() == before
    monkeypatch.undo()
    fly(mem, healthy_share(4), seed=4)
    assert mem.disarmed(None) == "learnt" and "disk full" not in mem.status()
    assert len(VehicleBaseline.load(mem.path).flights) == 4


# -- 5. every flight says what happened; a flight without a landed state ends at idle -----------------------------


def _no_landed_state_flight(hover_s: float, idle_s: float, sys_id: int = 1) -> list:
    """Armed from boot 0; hover PWM for ``hover_s``, idle PWM for ``idle_s``, then disarmed for 2 s; no
    EXTENDED_SYS_STATE at all."""
    end = hover_s + idle_s

    def pwm(t):  # never identical for a second (a frozen output is implausible)
        base = 1450 if t < hover_s else 1100
        return [int(round(base + 4 * np.sin(0.7 * t + k))) for k in range(4)]

    disarmed = decoded(mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3), sys_id)
    out, t_ms = [], 0
    for m in px4_stream(0.0, end + 2.0, pwm=pwm, sys_id=sys_id):
        kind = m.get_type()
        if kind == "EXTENDED_SYS_STATE":
            continue
        if kind == "ATTITUDE":
            t_ms = m.time_boot_ms
        out.append(disarmed if kind == "HEARTBEAT" and t_ms >= end * 1000 else m)
    return out


@pytest.mark.parametrize("idle_s,outcome", [(IDLE_LANDED_S + 1.0, "learnt"), (0.0, "not learnt: disarmed in the air")])
def test_a_flight_without_a_landed_state_ends_at_idle_then_disarm_and_says_what_it_did(tmp_path, idle_s, outcome, caplog):
    from monitor.model import Classifier
    from tests.test_daemon_helpers import toy_model

    events = tmp_path / "events.jsonl"
    d, _ = make_daemon(Classifier(toy_model(tmp_path / "toy.onnx")), events_path=str(events))
    d.memory = d.stage.memory = d.autopilot.memory = VehicleMemory(tmp_path / "state", RATE_HZ, idle_rpm=IDLE_RPM)
    with caplog.at_level(logging.INFO, "propwatch.monitor"):
        for m in _no_landed_state_flight(40.0, idle_s):
            d.handle(m, time.perf_counter())
    d.events.close()
    said = [json.loads(x) for x in events.read_text().splitlines() if '"vehicle_memory"' in x]
    assert len(said) == 1 and said[0]["flight"].startswith(outcome), said
    assert f"vehicle memory: flight {outcome}" in caplog.text


def test_a_flight_unlike_the_history_is_said_in_the_log(tmp_path, caplog):
    mem = learnt_three(tmp_path)
    share = healthy_share(9).copy()
    share[0] *= 1.025  # below the in-flight fault level, past the learning one
    with caplog.at_level(logging.INFO, "propwatch.monitor"):
        fly(mem, share, seed=9)
        what = mem.disarmed(None)
    assert what.startswith("not learnt"), what
    assert f"vehicle memory: flight {what}" in caplog.text


# -- 6. identity is stable -----------------------------------------------------------------------------------------

UID_A, UID_B = 0x5057_0000_0000_00AA, 0x5057_0000_0000_00BB


def test_a_uid_is_taken_once_per_boot_and_a_new_vehicle_after_a_reboot_is_announced(tmp_path):
    mem = VehicleMemory(tmp_path, RATE_HZ)
    assert mem.identify(sysid=1) is None and mem.key == "sysid-1"
    assert mem.identify(1, UID_A) is None and mem.key == f"uid-{UID_A:016x}"
    assert "second vehicle uid" in mem.identify(1, UID_B) and mem.key == f"uid-{UID_A:016x}"
    assert mem.identify(1, UID_A) is None
    mem.new_boot()
    notice = mem.identify(1, UID_B)
    assert "vehicle changed" in notice and mem.key == f"uid-{UID_B:016x}"
    assert f"for uid-{UID_B:016x}" in mem.status()


def _version(uid: int, sys_id: int = 1):
    return decoded(mavlink.MAVLink_autopilot_version_message(0, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, uid), sys_id)


def test_a_uid_while_armed_is_ignored_and_announced_and_a_reboot_lets_a_new_one_in(tmp_path):
    from monitor.model import Classifier
    from tests.test_daemon_helpers import toy_model

    events = tmp_path / "events.jsonl"
    d, _ = make_daemon(Classifier(toy_model(tmp_path / "toy.onnx")), events_path=str(events))
    d.memory = d.stage.memory = d.autopilot.memory = mem = VehicleMemory(tmp_path / "state", RATE_HZ)
    stream = px4_stream(0.0, 6.0)
    for m in stream[: len(stream) // 2]:
        d.handle(m, time.perf_counter())
    d.handle(_version(UID_A), time.perf_counter())  # armed, in the air: a spoofer's uid, or the board's, later
    assert mem.key == "sysid-1" and mem.needs_uid
    for m in stream[len(stream) // 2 :]:
        d.handle(m, time.perf_counter())
    d.handle(decoded(mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3)), time.perf_counter())  # disarmed
    assert d.autopilot.version_requests == 0  # asked again on the ground
    d.handle(_version(UID_A), time.perf_counter())
    assert mem.key == f"uid-{UID_A:016x}" and not mem.needs_uid
    d.handle(_version(UID_B), time.perf_counter())  # the same boot: ignored
    assert mem.key == f"uid-{UID_A:016x}"
    d.pipeline.clock_events.append("autopilot rebooted (boot time went back 5.0 s)")
    d.handle(decoded(mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3)), time.perf_counter())
    assert mem.needs_uid
    d.handle(_version(UID_B), time.perf_counter())
    assert mem.key == f"uid-{UID_B:016x}"
    d.events.close()
    said = [json.loads(x) for x in events.read_text().splitlines() if '"vehicle_identity"' in x]
    assert [
        ("while armed ignored" in s["notice"], "second vehicle uid" in s["notice"], "vehicle changed" in s["notice"])
        for s in said
    ] == [
        (True, False, False),
        (False, True, False),
        (False, False, True),
    ]


def test_with_signing_on_a_uid_comes_only_from_a_signed_frame(tmp_path):
    import socket

    from test_fuzz_link import KEY, _key_file, sign_and_pack

    from monitor.daemon.cli import guard
    from monitor.daemon.config import monitor_config_from_mapping
    from monitor.daemon.link import Link

    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.bind(("127.0.0.1", 0))
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    port = rx.getsockname()[1]
    rx.close()
    link_cfg = {"signing_key_path": str(_key_file(tmp_path, KEY)), "system_id": 1}
    link_cfg["autopilot_address"] = f"127.0.0.1:{tx.getsockname()[1]}"
    cfg = monitor_config_from_mapping({"link": link_cfg})
    link = Link(f"udpin:127.0.0.1:{port}", cfg.link.component_id, system_id=1, guard=guard(cfg))
    try:
        (_, unsigned), (_, signed) = (
            sign_and_pack([(0.0, _version(UID_B))], None)[0],
            sign_and_pack([(0.0, _version(UID_A))], KEY)[0],
        )
        for frame in (unsigned, signed):
            tx.sendto(frame, ("127.0.0.1", port))
        got, deadline = [], time.monotonic() + 5.0
        while time.monotonic() < deadline and not got:
            got += [m for m, *_ in link.read(0.1) if m.get_type() == "AUTOPILOT_VERSION"]
        assert [m.uid for m in got] == [UID_A]  # the unsigned uid never reaches the daemon's memory
    finally:
        link.close()
        tx.close()


def test_a_landing_waits_a_bounded_time_for_another_writer_and_says_so(tmp_path, monkeypatch):
    import monitor.daemon.memory_adapter as memory_module

    mem = learnt_three(tmp_path)
    monkeypatch.setattr(memory_module, "WRITE_WAIT_S", 0.2)
    with StateDir.open(tmp_path) as other, other.writing():  # `propwatch baseline note` stopped mid-write
        fly(mem, healthy_share(3), seed=3)
        what = mem.disarmed(None)
    assert what.startswith("not learnt: state dir") and f"(pid {os.getpid()})" in what, what
    fly(mem, healthy_share(4), seed=4)
    assert mem.disarmed(None) == "learnt"
