"""Heavier variants of the hardening fuzz tests (tests/test_fuzz_*.py), with the issue's sizes.

    python -m bench.bench_hardening                 # all four, issue sizes (~2 minutes)
    python -m bench.bench_hardening --only flood --seconds 10
    python -m bench.bench_hardening --only future --seconds 30

- ``flood``: the daemon on udpin receives ~20 000 messages/s for ``--seconds``,
  ATTITUDE and SERVO_OUTPUT_RAW on one repeated timestamp (a frozen autopilot
  clock) after a short normal flight; its RSS from /proc before and after
  (was 81 -> 151 MB in 10 s).
- ``senders``: ``--senders`` distinct local sockets (default 2000) each send a
  ground-station HEARTBEAT while a normal flight plays at real pace; the
  daemon's CPU share and how many of those sockets got anything back (was
  3.8 % -> 48 % CPU, every sender added to the output list).
- ``zeros``: ``propwatch diagnose`` on 200 MB of zeros behind a tlog header,
  a DataFlash header, a whole ULog and a whole CSV: wall time, peak RSS, exit
  code (tlog/DataFlash was 165 s, ~480 MB; ULog 276 s; CSV 1.23 GB).
- ``future``: a ``--seconds`` flight (propeller 3 faulty) sent at real pace
  from the autopilot's socket, twice with a fresh daemon each: alone (the
  reference), then with ATTITUDE of the autopilot's ids whose boot times run
  hours to weeks ahead at 100 messages/s interleaved; the daemon's CPU share,
  grid steps and alerts of both (was 63-100 % of a core, 446,591 steps from
  2,000 messages).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from bench import REPO
from bench.bench_daemon import build_inputs, cpu_seconds, free_udp_port, rss_mb


def start_daemon(work: Path, model: Path, port: int) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "monitor", "--connect", f"udpin:127.0.0.1:{port}", "--model", str(model)]
    cmd += ["--report", str(work / "report.json"), "--log-level", "WARNING"]
    d = subprocess.Popen(cmd, cwd=REPO, stderr=subprocess.DEVNULL)
    time.sleep(3.0)
    return d


def stop(d: subprocess.Popen, work: Path) -> dict:
    d.send_signal(signal.SIGTERM)
    d.wait(30)
    return json.loads((work / "report.json").read_text())


def flood(args, work: Path, model: Path) -> dict:
    from pymavlink.dialects.v20 import common as mavlink

    from tests.test_daemon_helpers import synth_flight

    port = free_udp_port()
    d = start_daemon(work, model, port)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for _, frame in synth_flight(3.0):
        s.sendto(frame, ("127.0.0.1", port))
        time.sleep(0.0005)
    ap = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    att = bytes(mavlink.MAVLink_attitude_message(102_990, 0.01, 0.01, 0.3, 0.0, 0.0, 0.0).pack(ap))
    srv = bytes(mavlink.MAVLink_servo_output_raw_message(102_990_000, 0, *[1450] * 8).pack(ap))
    batch = (att + srv) * 20  # 40 messages per datagram
    rss0 = rss_mb(d.pid)
    end, sent, t0 = time.monotonic() + args.seconds, 0, time.monotonic()
    while time.monotonic() < end:
        s.sendto(batch, ("127.0.0.1", port))
        sent += 40
        time.sleep(max(0.0, t0 + sent / 20_000.0 - time.monotonic()))
    time.sleep(1.0)
    rss1 = rss_mb(d.pid)
    rep = stop(d, work)
    return {
        "messages_sent": sent,
        "rate_msg_s": round(sent / args.seconds),
        "rss_before_mb": round(rss0, 1),
        "rss_after_mb": round(rss1, 1),
        "blind": rep.get("blind_now"),
        "hold_overflow": rep.get("hold_overflow"),
    }


def senders(args, work: Path, model: Path) -> dict:
    from pymavlink.dialects.v20 import common as mavlink

    model, tlog = build_inputs(argparse.Namespace(model=str(model), tlog=None, minutes=args.seconds / 60, seed=0), work)
    port = free_udp_port()
    d = start_daemon(work, model, port)
    hb = bytes(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(mavlink.MAVLink(None, 255, 190)))
    socks = []
    for _ in range(args.senders):
        x = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        x.bind(("127.0.0.1", 0))
        x.sendto(hb, ("127.0.0.1", port))
        socks.append(x)
    stop_flag = threading.Event()

    def keep_talking():
        while not stop_flag.is_set():
            for x in socks:
                x.sendto(hb, ("127.0.0.1", port))
            time.sleep(1.0)

    threading.Thread(target=keep_talking, daemon=True).start()
    cpu0, t0 = cpu_seconds(d.pid), time.monotonic()
    replay = [sys.executable, "-m", "monitor.cli", "replay", str(tlog), "--connect", f"udpout:127.0.0.1:{port}"]
    subprocess.run(replay + ["--speed", "1", "--linger", "0.5", "--log-level", "WARNING"], cwd=REPO, check=True)
    cpu1, t1 = cpu_seconds(d.pid), time.monotonic()
    stop_flag.set()
    rep = stop(d, work)
    answered = 0
    for x in socks:
        x.setblocking(False)
        try:
            x.recv(65535)
            answered += 1
        except BlockingIOError:
            pass
        x.close()
    return {
        "senders": args.senders,
        "cpu_percent": round(100.0 * (cpu1 - cpu0) / (t1 - t0), 2),
        "senders_answered": answered,
        "peers_remembered": rep.get("link", {}).get("peers_remembered"),  # absent from a daemon before the hardening
        "classified_steps": rep["pipeline"]["classified"],
    }


def zeros(args, work: Path, model: Path) -> dict:
    import struct

    from tests.test_daemon_helpers import synth_flight, write_tlog

    sys.path.insert(0, str(REPO / "tests"))  # the tests' own writers (they import each other by module name)
    from test_logs_ulog import write_ulog
    from test_security_readers import _csv

    heads = {
        "tlog": write_tlog(work / "h.tlog", synth_flight(1.0)).read_bytes()[:3000],
        "dataflash": b"\xa3\x95\x80" + struct.pack("<BB4s16s64s", 128, 89, b"FMT", b"BBnNZ", b"Type,Length,Name,Format,Columns"),
        "ulog": write_ulog(work / "h.ulg")[0].read_bytes(),  # a whole (short) flight, then the zeros
        "csv": _csv(work / "h.csv").read_bytes(),
    }
    suffix = {"tlog": "tlog", "dataflash": "bin", "ulog": "ulg", "csv": "csv"}
    out = {}
    for name, head in heads.items():
        p = work / f"zeros.{suffix[name]}"
        with open(p, "wb") as fh:
            fh.write(head)
            for _ in range(args.zeros_mb):
                fh.write(bytes(1_000_000))
        t0 = time.monotonic()
        cmd = [sys.executable, "-m", "monitor.cli", "diagnose", str(p), "--json", "--model", str(model)]
        cmd += ["--format", "propwatch"] if name == "csv" else []
        r = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
        wall = time.monotonic() - t0
        out[name] = {
            "mb": args.zeros_mb,
            "exit": r.returncode,
            "wall_s": round(wall, 2),
            "stdout_is_json": _is_json(r.stdout),
            "error": (json.loads(r.stdout).get("error") if _is_json(r.stdout) else r.stdout[-200:]),
        }
        p.unlink()
    out["children_peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0, 1)
    return out


def future(args, work: Path, model: Path) -> dict:
    import numpy as np
    from pymavlink.dialects.v20 import common as mavlink

    from tests.test_daemon_helpers import synth_flight

    flight = synth_flight(args.seconds, faulty=(3,), seed=1)
    rng = np.random.default_rng(0)
    ap = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    t0, t1 = flight[0][0], flight[-1][0]
    forged = [
        (
            t0 + k / 100.0,
            bytes(mavlink.MAVLink_attitude_message(int(rng.integers(3_600_000, 2**32 - 1)), 0.01, 0.01, 0.3, 0, 0, 0).pack(ap)),
        )
        for k in range(int((t1 - t0) * 100))
    ]
    out = {}
    for name, frames in (("clean", flight), ("forged", sorted(flight + forged, key=lambda f: f[0]))):
        port = free_udp_port()
        d = start_daemon(work, model, port)
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        cpu0, w0 = cpu_seconds(d.pid), time.monotonic()
        for t, frame in frames:
            time.sleep(max(0.0, w0 + (t - t0) - time.monotonic()))
            s.sendto(frame, ("127.0.0.1", port))
        cpu1, w1 = cpu_seconds(d.pid), time.monotonic()
        s.close()
        rep = stop(d, work)
        out[name] = {
            "messages_sent": len(frames),
            "cpu_percent": round(100.0 * (cpu1 - cpu0) / (w1 - w0), 2),
            "steps": rep["pipeline"]["steps"],
            "alerts": rep["alerts"],
            "clock_events": rep["pipeline"].get("clock_resets", 0) + rep["pipeline"].get("clock_jumps", 0),
        }
    return out


def _is_json(text: str) -> bool:
    try:
        json.loads(text)
        return True
    except ValueError:
        return False


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--only", choices=["flood", "senders", "zeros", "future"])
    p.add_argument("--seconds", type=float, default=10.0, help="flood / senders duration")
    p.add_argument("--senders", type=int, default=2000)
    p.add_argument("--zeros-mb", type=int, default=200)
    p.add_argument("--model", help="ONNX model (default models/classifier.onnx, else the tests' toy model)")
    args = p.parse_args(argv)
    res = {"load_average": os.getloadavg()}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        model, _ = build_inputs(argparse.Namespace(model=args.model, tlog="unused", minutes=0, seed=0), work)
        for name, fn in (("flood", flood), ("senders", senders), ("zeros", zeros), ("future", future)):
            if args.only in (None, name):
                res[name] = fn(args, work, model)
    print(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
