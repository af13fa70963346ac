"""Throughput of ``propwatch diagnose`` on a 30-minute simulated tlog, as a multiple of real time.

    python -m bench.bench_diagnose [--tlog PATH] [--minutes 30] [--hop 20] [--model PATH]

Without --tlog it simulates one flight with ``propwatch simulate --format tlog``
(issue 2's PX4-like stream: 50 Hz ATTITUDE, SERVO_OUTPUT_RAW, LOCAL_POSITION_NED,
HIGHRES_IMU, ESC_STATUS; 1-2 Hz status), once, into a temporary directory.
Stages timed (best of --repeat runs, single thread):
  parse     tlog -> FlightTable (frame walk, pymavlink decode of the needed ids, shared decoder, 20 Hz grid)
  features  monitor.features on the whole table
  inference usable windows every --hop steps through the classifier
and, in the same run, pymavlink's parse-only time (mavutil, every message) for the same file.
Issue 6 targets: >= 500x real time in total; features + inference <= 20 % of the total.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench import REPO


def simulate(minutes: float, out: Path) -> Path:
    cmd = [
        sys.executable,
        "-m",
        "monitor.cli",
        "simulate",
        "--out",
        str(out),
        "--format",
        "tlog",
        "--duration-s",
        str(int(minutes * 60)),
        "--label",
        "4",
        "--propellers",
        "quadratic",
        "--seed",
        "1",
    ]
    subprocess.run(cmd, check=True, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return out / "flight_000.tlog"


def best(fn, repeat: int):
    """(best wall s, best CPU s, result). CPU time is what this process used: on a
    shared machine the wall clock also counts other people's jobs."""
    walls, cpus, out = [], [], None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return min(walls), min(cpus), out


def pymavlink_parse_only(path: Path) -> int:
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(path), dialect="common")
    n = 0
    while conn.recv_match() is not None:
        n += 1
    conn.close()
    return n


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tlog", type=Path)
    p.add_argument("--minutes", type=float, default=30.0)
    p.add_argument("--hop", type=int, default=20, help="as propwatch diagnose (default 20 steps = 1 s)")
    p.add_argument("--model", type=Path, default=REPO / "models" / "classifier.onnx")
    p.add_argument("--repeat", type=int, default=2)
    args = p.parse_args(argv)

    from monitor.diagnose.engine import predict_at, window_ends
    from monitor.features import compute_features
    from monitor.logs import read_log
    from monitor.model import Classifier, choose_esc

    with tempfile.TemporaryDirectory() as tmp:
        model = args.model
        if not model.is_file():
            from tests.test_diagnose_fixtures import build_model

            model = build_model(Path(tmp) / "fixture.onnx")
            print(f"(no {args.model}: using the test fixture model)")
        clf = Classifier(model, threads=1)
        esc = choose_esc(clf, "")
        if args.tlog:
            tlog = args.tlog
        else:
            t0 = time.perf_counter()
            tlog = simulate(args.minutes, Path(tmp) / "sim")
            print(f"simulated {args.minutes:g} min tlog in {time.perf_counter() - t0:.0f} s")
        size_mb = tlog.stat().st_size / 1e6

        t_parse, c_parse, table = best(
            lambda: read_log(tlog, esc=esc, rate_hz=clf.info.sample_rate_hz, extras=False), args.repeat
        )
        flight_s = len(table) / table.rate_hz
        t_feat, c_feat, feats = best(lambda: compute_features(table.signals(), clf.info.features), args.repeat)

        def infer():
            ends = window_ends(table, feats, clf.info.window, args.hop)
            return predict_at(clf, feats, ends, clf.info.window, batch=4096), len(ends)

        t_inf, c_inf, (_, n_windows) = best(infer, args.repeat)
        t_pm, c_pm, n_msgs = best(lambda: pymavlink_parse_only(tlog), 1)

    total, ctotal = t_parse + t_feat + t_inf, c_parse + c_feat + c_inf
    print(f"tlog: {tlog.name}, {size_mb:.1f} MB, {flight_s:.0f} s of flight, {n_msgs} MAVLink messages")
    print(f"{'stage':<34}{'wall s':>9}{'x real':>8}{'CPU s':>9}{'x real':>8}")

    def row(name, w, c):
        print(f"{name:<34}{w:9.3f}{flight_s / w:8.0f}{c:9.3f}{flight_s / max(c, 1e-9):8.0f}")

    row("parse (tlog -> 20 Hz table)", t_parse, c_parse)
    row("features", t_feat, c_feat)
    row(f"inference ({n_windows} windows, hop {args.hop})", t_inf, c_inf)
    row("total (target >= 500x)", total, ctotal)
    row("pymavlink parse-only (all msgs)", t_pm, c_pm)
    print(
        f"features + inference: {100 * (t_feat + t_inf) / total:.1f} % of wall, "
        f"{100 * (c_feat + c_inf) / ctotal:.1f} % of CPU (target <= 20 %)"
    )
    print(f"pymavlink parse-only takes {c_pm / c_parse:.1f}x our parse CPU time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
