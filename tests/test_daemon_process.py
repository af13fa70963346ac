"""The daemon as a subprocess: against the replay stub over UDP loopback, on .tlog files, and on bad input.

Synthetic PX4 streams and the toy ONNX model come from ``test_daemon_helpers``;
every run is bounded in time and uses 127.0.0.1 only.
"""

from __future__ import annotations

import json
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink
from test_daemon_helpers import UDP_SPEED, synth_flight, toy_model, write_tlog

REPO = Path(__file__).resolve().parent.parent
PY = sys.executable
TAKEOFF_BOOT_MS = 102_000  # synth_flight: boot clock starts at 100 s, IN_AIR from 2 s
# A fault that the decision rule (the shares' evidence) can see: each flight first learns its baseline, the 10 s of
# windows after the first one (which ends 5 s after take-off), so the fault starts at 17 s; FAULT follows in ~4 s.
ONSET_S = 17.0
ONSET_BOOT_MS = 117_000
ALERT_FLIGHT_S = 24.0


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Proc:
    """A subprocess whose stderr is collected by a thread, so the test can wait for a line."""

    def __init__(self, args: list[str], env: dict | None = None):
        self.p = subprocess.Popen(
            args, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env={**os.environ, **(env or {})}
        )
        self.lines: list[str] = []
        self._t = threading.Thread(target=self._read, daemon=True)
        self._t.start()

    def _read(self) -> None:
        for line in self.p.stdout:
            self.lines.append(line.rstrip("\n"))

    @property
    def text(self) -> str:
        return "\n".join(self.lines)

    def wait_for(self, needle: str, timeout_s: float = 20.0) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if needle in self.text:
                return True
            if self.p.poll() is not None:
                self._t.join(2)
                return needle in self.text
            time.sleep(0.05)
        return False

    def stop(self, timeout_s: float = 10.0) -> int:
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
        try:
            rc = self.p.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.p.kill()
            rc = self.p.wait(5)
        self._t.join(2)
        return rc


def monitor_cmd(*args: str) -> list[str]:
    return [PY, "-m", "monitor", *args]


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    return toy_model(tmp_path_factory.mktemp("model") / "toy.onnx")


def write_config(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def fly_over_udp(tmp_path, model, frames, speed, config_text="", extra=()):
    """Daemon on udpin, replay stub on udpout; returns (daemon, replay, events, requests, received, report)."""
    port = free_udp_port()
    tlog = write_tlog(tmp_path / "flight.tlog", frames)
    text = config_text
    # The autopilot is pinned after 2 s of its heartbeats at real pace: the same boot time at the replay's speed.
    pin = f"  pin_wait_s: {2.0 / speed:g}\n"
    if "pin_wait_s" not in text:
        text = text.replace("link:\n", "link:\n" + pin, 1) if "link:\n" in text else text + "link:\n" + pin
    cfg = write_config(tmp_path / "monitor.yaml", text)
    paths = {k: tmp_path / f"{k}.jsonl" for k in ("events", "requests", "received")}
    report = tmp_path / "report.json"
    d = Proc(
        monitor_cmd(
            "--connect",
            f"udpin:127.0.0.1:{port}",
            "--config",
            str(cfg),
            "--model",
            str(model),
            "--events",
            str(paths["events"]),
            "--report",
            str(report),
            *extra,
        )
    )
    assert d.wait_for("ready:"), d.text
    r = Proc(
        [
            PY,
            "-m",
            "monitor.cli",
            "replay",
            str(tlog),
            "--connect",
            f"udpout:127.0.0.1:{port}",
            "--speed",
            str(speed),
            "--requests",
            str(paths["requests"]),
            "--received",
            str(paths["received"]),
            "--linger",
            "1.5",
        ]
    )
    assert r.p.wait(120) == 0, r.text
    rc = d.stop()
    assert rc == 0, d.text
    assert "Traceback" not in d.text and "stopped:" in d.text, d.text

    def jsonl(p):
        return [json.loads(x) for x in p.read_text().splitlines()] if p.exists() else []

    alerts = [e for e in jsonl(paths["events"]) if e.get("event") == "alert"]  # blind/recovered lines aside
    return d, r, alerts, jsonl(paths["requests"]), jsonl(paths["received"]), json.loads(report.read_text())


def test_faulty_propeller_alert_over_udp_against_the_replay_stub(tmp_path, model):
    frames = synth_flight(ALERT_FLIGHT_S, faulty=(3,), fault_from_s=ONSET_S)
    d, _, events, requests, received, report = fly_over_udp(tmp_path, model, frames, speed=UDP_SPEED)
    faults = [e for e in events if e["level"] == "fault"]
    assert faults, d.text
    first = faults[0]
    assert first["faulty_propellers"] == [3] and first["text"].startswith("PROP 3 FAULT p=")
    assert set(first) >= {"time_boot_ms", "level", "faulty_propellers", "probabilities", "text", "statistic"}
    assert 0 < first["time_boot_ms"] - ONSET_BOOT_MS <= 6_000  # within 6 s of the onset
    assert all(e["faulty_propellers"] == [3] and e["time_boot_ms"] > ONSET_BOOT_MS for e in events)  # suspect too
    assert 15.0 < first["battery_v"] < 16.5  # BATTERY_STATUS cells of the synthetic pack, summed
    # A good MAVLink component: heartbeats as an onboard controller on the autopilot's system, compid 191.
    hb = [m for m in received if m["mavpackettype"] == "HEARTBEAT"]
    assert hb and all(m["_from"] == [1, 191] and m["type"] == 18 for m in hb)
    texts = [m for m in received if m["mavpackettype"] == "STATUSTEXT" and m["text"].startswith("PROP ")]
    assert texts and all(t["text"].startswith("PROP 3 ") for t in texts), texts
    assert any(t["text"].startswith("PROP 3 FAULT p=") and t["severity"] in (2, 4) for t in texts), texts
    assert all(len(t["text"]) <= 50 for t in texts)
    # Only stream-rate requests, at >= 20 Hz for the fast streams, each acknowledged. This flight's streams are fast
    # enough: whether the rate window that straddles the pin saw them slow, and so asked, is the machine's timing; the
    # slow stream below is always asked for.
    assert all(m["command"] == 511 for m in received if m["mavpackettype"] == "COMMAND_LONG"), d.text
    assert all(r["interval_us"] <= 50_000 for r in requests if r["message_id"] in (30, 36)), requests
    assert all(r["from"] == [1, 191] and r["result"] == 0 for r in requests)
    assert report["acks"].get("0", 0) == len(requests)
    assert {m["mavpackettype"] for m in received} <= {"HEARTBEAT", "STATUSTEXT", "COMMAND_LONG", "NAMED_VALUE_FLOAT"}
    assert report["ignored"].get("255/190", 0) > 0  # the ground station's heartbeats


def test_healthy_flight_raises_no_alert_and_no_requests_when_switched_off(tmp_path, model):
    cfg = "link:\n  request_streams: false\nalerts:\n  named_value_float: true\n"
    d, _, events, requests, received, report = fly_over_udp(tmp_path, model, synth_flight(30.0, seed=7), UDP_SPEED, cfg)
    assert events == [] and report["alerts"] == 0
    assert report["pipeline"]["classified"] > 300  # it did classify the flight
    assert not [m for m in received if m["mavpackettype"] == "COMMAND_LONG"]
    # No alert text; a NOTICE (severity 5) may say the monitor went blind when the replay stopped.
    assert not [m for m in received if m["mavpackettype"] == "STATUSTEXT" and m["severity"] < 5]
    assert requests == []
    nvf = [m for m in received if m["mavpackettype"] == "NAMED_VALUE_FLOAT"]
    assert {m["name"] for m in nvf} == {"PWF1", "PWF2", "PWF3", "PWF4"} and max(m["value"] for m in nvf) < 0.8


def test_link_drop_and_return_and_a_stream_that_stops(tmp_path, model):
    # The hole starts after the autopilot was pinned (its heartbeats over 2 s of boot time, link.pin_wait_s).
    frames = synth_flight(10.0, faulty=(2,), hole_s=(3.0, 5.5))
    servo = mavlink.MAVLink(None)
    # SERVO_OUTPUT_RAW (id 36) stops for good at 7.5 s of flight.
    cut = frames[0][0] + 7.5
    frames = [(t, f) for t, f in frames if not (t > cut and servo.decode(bytearray(f)).get_type() == "SERVO_OUTPUT_RAW")]
    cfg = "link:\n  link_timeout_s: 1.0\n  rate_check_period_s: 1.0\n  pin_wait_s: 0.5\n"
    d, *_, report = fly_over_udp(tmp_path, model, frames, speed=1.5, config_text=cfg)
    text = d.text
    assert "link lost" in text and text.count("link up") >= 2, text
    assert "stream SERVO_OUTPUT_RAW missing" in text, text
    assert "motor missing, stale or NaN" in text, text
    assert report["pipeline"]["classified"] == 0  # never 100 clean steps in a row: nothing invented


def test_runs_without_torch_on_a_tlog(tmp_path, model):
    tlog = write_tlog(tmp_path / "f.tlog", synth_flight(ALERT_FLIGHT_S, faulty=(1,), fault_from_s=ONSET_S))
    events = tmp_path / "ev.jsonl"
    code = (
        "import sys; sys.modules['torch'] = None\n"
        "from monitor.cli import main\n"
        f"rc = main(['monitor', '--connect', {str(tlog)!r}, '--model', {str(model)!r}, '--tlog-speed', '0',"
        f" '--events', {str(events)!r}])\n"
        "assert 'offline' not in sys.modules and sys.modules['torch'] is None\n"
        "sys.exit(rc)\n"
    )
    p = subprocess.run([PY, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    ev = [json.loads(x) for x in events.read_text().splitlines()]
    faults = [e for e in ev if e.get("level") == "fault"]
    assert faults and faults[0]["faulty_propellers"] == [1], ev


def test_garbage_corrupt_and_truncated_packets_and_nan_in_a_tlog(tmp_path, model):
    rng = random.Random(3)
    frames = synth_flight(ALERT_FLIGHT_S, faulty=(4,), nan_window_s=(3.0, 3.4), fault_from_s=ONSET_S)
    bad = []
    for i in range(50, len(frames), 97):
        kind = i % 3
        if kind == 0:
            bad.append((i, bytes(rng.randrange(256) for _ in range(rng.randrange(1, 60)))))  # random bytes
        elif kind == 1:
            t, f = frames[i - 1]
            frames[i - 1] = (t, f[:-3] + bytes([f[-3] ^ 0xFF]) + f[-2:])  # payload flipped: CRC fails
        else:
            t, f = frames[i - 1]
            frames[i - 1] = (t, f[: len(f) // 2])  # truncated
    tlog = write_tlog(tmp_path / "bad.tlog", frames, garbage=bad)
    report = tmp_path / "r.json"
    p = subprocess.run(
        monitor_cmd(
            "--connect",
            str(tlog),
            "--model",
            str(model),
            "--tlog-speed",
            "0",
            "--events",
            str(tmp_path / "ev.jsonl"),
            "--report",
            str(report),
        ),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert "attitude missing, stale or NaN" in p.stderr
    ev = [json.loads(x) for x in (tmp_path / "ev.jsonl").read_text().splitlines()]
    alerts = [e for e in ev if e.get("event") == "alert"]
    assert any(e["level"] == "fault" for e in alerts) and all(e["faulty_propellers"] == [4] for e in alerts), ev
    r = json.loads(report.read_text())
    assert r["pipeline"]["resets"] >= 1


def test_random_bytes_on_the_udp_port_do_not_crash_it(tmp_path, model):
    port = free_udp_port()
    d = Proc(monitor_cmd("--connect", f"udpin:127.0.0.1:{port}", "--model", str(model)))
    assert d.wait_for("ready:"), d.text
    rng = random.Random(1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for _ in range(300):
            payload = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300)))
            if rng.random() < 0.3:
                payload = b"\xfd" + payload  # looks like the start of a MAVLink 2 frame
            s.sendto(payload, ("127.0.0.1", port))
    assert d.wait_for("unparseable", 10.0), d.text
    assert d.p.poll() is None  # still running
    assert d.stop() == 0 and "Traceback" not in d.text


@pytest.mark.parametrize(
    "case,expect",
    [
        ("missing", "model file not found"),
        ("text", "not a loadable ONNX model"),
        ("no_meta", "not a propwatch model"),
    ],
)
def test_wrong_or_missing_model_is_one_clear_line(tmp_path, case, expect):
    path = tmp_path / "m.onnx"
    if case == "text":
        path.write_text("not a model")
    elif case == "no_meta":
        import onnx

        m = onnx.load(str(toy_model(tmp_path / "src.onnx")))
        del m.metadata_props[:]
        onnx.save(m, str(path))
    p = subprocess.run(
        monitor_cmd("--connect", "udpin:127.0.0.1:9", "--model", str(path)), cwd=REPO, capture_output=True, text=True, timeout=60
    )
    assert p.returncode == 2 and expect in p.stderr and str(path) in p.stderr and "Traceback" not in p.stderr, p.stderr


@pytest.mark.parametrize(
    "text,expect",
    [
        ("alerts:\n  treshold: 0.9\n", "treshold"),
        ("link: [1, 2\n", "invalid YAML"),
        ("input:\n  motor_source: pwm\n", "input.motor_source"),
        ("alerts:\n  rule: consecutive\n", "alerts.rule: 'consecutive' is no longer an onboard rule; use 'sequential'"),
    ],
)
def test_bad_config_is_one_clear_line(tmp_path, model, text, expect):
    cfg = write_config(tmp_path / "bad.yaml", text)
    p = subprocess.run(
        monitor_cmd("--connect", "udpin:127.0.0.1:9", "--config", str(cfg), "--model", str(model)),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == 2 and expect in p.stderr and str(cfg) in p.stderr and "Traceback" not in p.stderr, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1, p.stderr


def test_systemd_notify_watchdog_and_clean_sigterm(tmp_path, model):
    """Under systemd (Type=notify, WatchdogSec): READY=1, WATCHDOG=1 from the loop, STOPPING=1 and exit 0 on SIGTERM."""
    sock_path = str(tmp_path / "notify.sock")
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    srv.bind(sock_path)
    srv.settimeout(10.0)
    port = free_udp_port()
    d = Proc(
        monitor_cmd("--connect", f"udpin:127.0.0.1:{port}", "--model", str(model)),
        env={"NOTIFY_SOCKET": sock_path, "WATCHDOG_USEC": "400000"},
    )
    try:
        got = []
        while not any(m.startswith(b"WATCHDOG=1") for m in got) or len(got) < 3:
            got.append(srv.recv(256))
        assert got[0].startswith(b"READY=1") and got.count(b"WATCHDOG=1") >= 2
    finally:
        rc = d.stop()
    assert rc == 0 and "signal 15: stopping" in d.text and "stopped:" in d.text, d.text
    rest = []
    srv.settimeout(0.5)
    try:
        while True:
            rest.append(srv.recv(256))
    except TimeoutError:
        pass
    srv.close()
    assert b"STOPPING=1" in rest


def test_tcp_link_that_is_not_there_yet_then_comes_and_goes(tmp_path, model):
    """tcp: the daemon starts before its peer, connects when it appears, and survives it closing."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    # 20 s of flight: what is sent before the daemon's next connection attempt (<= 1 s) is lost, as with PX4.
    tlog = write_tlog(tmp_path / "f.tlog", synth_flight(20.0, faulty=(2,)))
    report = tmp_path / "report.json"
    cfg = write_config(tmp_path / "monitor.yaml", "link:\n  pin_wait_s: 0.4\n")  # 2 s of boot at 5x
    d = Proc(
        monitor_cmd("--connect", f"tcp:127.0.0.1:{port}", "--model", str(model), "--report", str(report), "--config", str(cfg))
    )
    try:
        assert d.wait_for("cannot open"), d.text
        r = subprocess.run(
            [
                PY,
                "-m",
                "monitor.cli",
                "replay",
                str(tlog),
                "--connect",
                f"tcpin:127.0.0.1:{port}",
                "--speed",
                "5",
                "--linger",
                "0.5",
            ],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert r.returncode == 0, r.stderr
        # The peer's close reaches the daemon as an end of stream (FIN), or as a reset (RST) where the replay closed
        # with the daemon's heartbeats unread in its buffer: the kernel's choice, not the daemon's. Either way the
        # daemon says so, reopens and goes on.
        assert d.wait_for("reopening"), d.text
        assert "connection closed by the peer" in d.text or "Connection reset by peer" in d.text, d.text
        assert d.p.poll() is None
    finally:
        rc = d.stop()
    assert rc == 0 and "Traceback" not in d.text, d.text
    # The link is under test: what came over TCP was decoded and classified (faulty rotor 2 the most likely).
    assert "autopilot: system 1 component 1" in d.text, d.text
    assert json.loads(report.read_text())["pipeline"]["classified"] > 40, d.text


def test_serial_device_with_baud_rate(tmp_path, model):
    """``/dev/...,921600`` through pyserial, on a pseudo-terminal standing in for the autopilot's UART."""
    import select
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    dev = os.ttyname(slave)
    report = tmp_path / "report.json"
    cfg = write_config(tmp_path / "monitor.yaml", "link:\n  pin_wait_s: 0.4\n")  # 2 s of boot at 5x
    d = Proc(monitor_cmd("--connect", f"{dev},921600", "--model", str(model), "--report", str(report), "--config", str(cfg)))
    heard = b""
    try:
        assert d.wait_for("ready:"), d.text
        frames = synth_flight(10.0, faulty=(1,))
        t0_log, t0 = frames[0][0], time.monotonic()
        for t, f in frames:
            while time.monotonic() < t0 + (t - t0_log) / 5.0:  # 5x the recorded pace
                if select.select([master], [], [], 0.005)[0]:
                    heard += os.read(master, 4096)
            os.write(master, f)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            if select.select([master], [], [], 0.05)[0]:
                heard += os.read(master, 4096)
    finally:
        rc = d.stop()
        os.close(master)
        os.close(slave)
    assert rc == 0 and "Traceback" not in d.text, d.text
    # The link is under test (alerts over UDP are above): read from the UART and classified, written back to it.
    # (one window proves the UART was read: on a loaded machine the 5x pace outruns the pseudo-terminal)
    assert json.loads(report.read_text())["pipeline"]["classified"] > 0, d.text
    p = mavlink.MAVLink(None)
    p.robust_parsing = True
    back = [m for m in (p.parse_buffer(heard) or []) if m.get_type() != "BAD_DATA"]
    assert any(m.get_type() == "HEARTBEAT" and m.type == 18 and m.get_srcComponent() == 191 for m in back)
    assert any(m.get_type() == "COMMAND_LONG" and m.command == 511 for m in back)  # the stream requests


def test_udpout_daemon_announces_itself_to_a_listening_autopilot(tmp_path, model):
    """With udpout the daemon speaks first (heartbeat), so an autopilot listening on udpin can answer."""
    port = free_udp_port()
    tlog = write_tlog(tmp_path / "f.tlog", synth_flight(20.0, faulty=(4,)))
    received = tmp_path / "received.jsonl"
    report = tmp_path / "report.json"
    r = Proc(
        [
            PY,
            "-m",
            "monitor.cli",
            "replay",
            str(tlog),
            "--connect",
            f"udpin:127.0.0.1:{port}",
            "--speed",
            str(UDP_SPEED),
            "--linger",
            "1.0",
            "--received",
            str(received),
        ]
    )
    d = Proc(monitor_cmd("--connect", f"udpout:127.0.0.1:{port}", "--model", str(model), "--report", str(report)))
    try:
        assert r.p.wait(60) == 0, r.text
    finally:
        rc = d.stop()
    assert rc == 0 and "Traceback" not in d.text, d.text
    got = [json.loads(x) for x in received.read_text().splitlines()]
    assert any(m["mavpackettype"] == "HEARTBEAT" and m["_from"] == [1, 191] for m in got)
    # ... and the autopilot's streams came back to it: the stream requests were answered, the flight classified.
    rep = json.loads(report.read_text())
    assert rep["acks"].get("0", 0) >= 2 and rep["pipeline"]["classified"] > 40, rep


def test_slow_stream_is_reported_and_requested_again(tmp_path, model):
    """PX4's onboard default SERVO_OUTPUT_RAW rate (10 Hz) is below the grid: warn, and ask again."""
    cfg = "link:\n  rate_check_period_s: 1.0\n  request_retry_s: 1.0\n"
    d, _, _, requests, received, report = fly_over_udp(
        tmp_path, model, synth_flight(6.0, servo_hz=10.0), speed=1, config_text=cfg
    )
    assert "stream SERVO_OUTPUT_RAW at" in d.text and "need >= 16 Hz" in d.text, d.text
    servo = [r for r in requests if r["message_id"] == 36]
    assert len(servo) >= 2 and all(r["interval_us"] <= 50_000 for r in servo)
    # Only stream-rate requests, from the monitor's component, each acknowledged.
    cmds = [m for m in received if m["mavpackettype"] == "COMMAND_LONG"]
    assert cmds and all(m["command"] == 511 and m["_from"] == [1, 191] for m in cmds), cmds
    assert all(r["from"] == [1, 191] and r["result"] == 0 for r in requests)
    assert report["acks"].get("0", 0) == len(requests)
    # 50 Hz is fine: it may only look slow in the one 1 s rate window that straddles the end of the
    # replay (a partial window); a real misreport would repeat in every window of the 6 s flight.
    assert d.text.count("stream ATTITUDE at") <= 1, d.text
