"""Where the daemon's CPU goes at real pace: its own thread time per phase, over a replayed flight.

    python -m bench.bench_daemon_phases                 # 1-minute synthetic flight at real pace
    python -m bench.bench_daemon_phases --minutes 10
    python -m bench.bench_daemon_phases --floor         # only select() + recvfrom() of the same datagram rate

``bench/bench_daemon.py`` gives the daemon's total CPU share; this splits it. The daemon
runs in this process (``propwatch monitor`` on udpin, as deployed) with a thread-time
counter around each phase, and ``propwatch replay`` plays the flight to it over UDP:

- ``read``: the loop's ``Link.read`` (select, recvfrom, pymavlink parsing of the datagram);
- ``handle``: ``Daemon.handle`` without the inference (decode, plausibility, hold, features,
  decision, hypothesis sets), with two parts of it shown alone: ``step`` (a grid step's
  features and ring, without the inference) and ``decide`` (the decision layer per step);
- ``inference``: onnxruntime;
- ``tick``: the loop's housekeeping.

Each is thread CPU seconds and the share of one core over the replay. ``--floor`` is the
cost of waking up for the datagrams alone on this machine: a Python loop doing nothing but
select() and recvfrom() at the flight's datagram rate (106 a second for the synthetic flight).
"""

from __future__ import annotations

import argparse
import json
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from bench.bench_daemon import REPO, build_inputs, free_udp_port

PHASES = ("read", "handle", "step", "decide", "inference", "tick")


def instrument() -> dict[str, list[float]]:
    """Wrap each phase's method with a thread-time counter; ``handle`` and ``step`` exclude the inference."""
    from monitor.daemon import decide, link, pipeline, service
    from monitor.model import Classifier

    acc = {k: [0.0, 0] for k in PHASES}

    def wrap(cls, name: str, key: str, exclude_inference: bool = True) -> None:
        orig = getattr(cls, name)

        def timed(*a, **k):
            inf0 = acc["inference"][0]
            c0 = time.thread_time()
            try:
                return orig(*a, **k)
            finally:
                spent = time.thread_time() - c0
                if exclude_inference:
                    spent -= acc["inference"][0] - inf0
                acc[key][0] += spent
                acc[key][1] += 1

        setattr(cls, name, timed)

    wrap(Classifier, "predict", "inference", exclude_inference=False)
    wrap(link.Link, "read", "read")
    wrap(service.Daemon, "handle", "handle")
    wrap(pipeline.Pipeline, "_step", "step")
    wrap(decide.DecisionStage, "step", "decide")
    wrap(service.Daemon, "tick", "tick")
    return acc


def phases(args) -> dict:
    from monitor.cli import main as propwatch

    acc = instrument()
    out: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        model, tlog = build_inputs(args, work)
        port = free_udp_port()

        def play() -> None:  # beside the daemon, which keeps the main thread (it installs signal handlers)
            time.sleep(3.0)  # start-up: model load and imports are not the steady cost
            for v in acc.values():
                v[:] = [0.0, 0]
            cpu0, t0 = time.process_time(), time.monotonic()
            replay = [sys.executable, "-m", "monitor.cli", "replay", str(tlog), "--connect", f"udpout:127.0.0.1:{port}"]
            subprocess.run([*replay, "--speed", "1", "--linger", "0.5", "--log-level", "WARNING"], cwd=REPO, check=True)
            out["wall_s"], out["cpu_s"] = time.monotonic() - t0, time.process_time() - cpu0
            os.kill(os.getpid(), signal.SIGTERM)

        threading.Thread(target=play, daemon=True).start()
        propwatch(["monitor", "--connect", f"udpin:127.0.0.1:{port}", "--model", str(model), "--log-level", "WARNING"])
    wall = out["wall_s"]
    return {
        "wall_s": round(wall, 1),
        "process_cpu_percent": round(100.0 * out["cpu_s"] / wall, 2),
        "percent_of_a_core": {k: round(100.0 * v[0] / wall, 2) for k, v in acc.items()},
        "calls": {k: v[1] for k, v in acc.items()},
        "us_per_call": {k: round(1e6 * v[0] / max(v[1], 1), 1) for k, v in acc.items()},
        "note": "step and decide are parts of handle; handle and step exclude the inference",
        "load_average": os.getloadavg(),
    }


def floor(args) -> dict:
    """A loop that only wakes for datagrams: select() + recvfrom() at ``rate`` a second for ``seconds``."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    port = rx.getsockname()[1]
    code = (
        "import socket, time\n"
        "s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); t0 = time.monotonic(); n = 0\n"
        f"while time.monotonic() - t0 < {args.seconds}:\n"
        f"    s.sendto(b'x' * 40, ('127.0.0.1', {port})); n += 1\n"
        f"    time.sleep(max(0.0, t0 + n / {args.rate} - time.monotonic()))\n"
    )
    sender = subprocess.Popen([sys.executable, "-c", code])
    c0, t0, n = time.process_time(), time.monotonic(), 0
    while sender.poll() is None:
        if select.select([rx], [], [], 0.1)[0]:
            try:
                rx.recvfrom(65535)
                n += 1
            except BlockingIOError:
                pass
    cpu, wall = time.process_time() - c0, time.monotonic() - t0
    return {
        "datagrams": n,
        "wall_s": round(wall, 1),
        "cpu_percent": round(100 * cpu / wall, 2),
        "us_per_datagram": round(1e6 * cpu / max(n, 1)),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, default=1.0, help="synthetic flight length, played at real pace")
    p.add_argument("--tlog", help="replay this .tlog instead of a synthetic flight")
    p.add_argument("--model", help="ONNX model (default models/classifier.onnx, else the tests' toy model)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--floor", action="store_true", help="only the cost of waking for datagrams (select + recvfrom)")
    p.add_argument("--rate", type=float, default=106.0, help="--floor: datagrams a second")
    p.add_argument("--seconds", type=float, default=20.0, help="--floor: how long")
    args = p.parse_args(argv)
    print(json.dumps(floor(args) if args.floor else phases(args), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
