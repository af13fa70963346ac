"""Throughput of ``propwatch diagnose`` on a 30-minute simulated tlog, as a user runs it, in multiples of real time.

    python -m bench.bench_diagnose [--tlog PATH] [--minutes 30] [--repeat 3] [--against REV] [--stages]

Without --tlog it simulates one flight with ``propwatch simulate --format tlog`` (a PX4-like stream: 50 Hz
ATTITUDE, SERVO_OUTPUT_RAW, LOCAL_POSITION_NED, HIGHRES_IMU, ESC_STATUS; 1-2 Hz status), once, into a temporary
directory. Timed in the same run, best of --repeat (wall, and CPU: on a shared machine the wall clock also counts
other people's jobs, so CPU is the figure to compare):

* ``propwatch diagnose LOG --json`` as a fresh process from this tree (process start, imports and output included);
* the same command from the tree of git revision ``--against`` (``git archive``, same interpreter), and whether its
  JSON is byte-identical to this tree's;
* pymavlink's parse alone of the same file (``mavutil``, every message), the reference a user would otherwise run.

``--stages`` adds where this tree's CPU goes, in-process: imports, model load, read (tlog -> streams), grid (the
20 Hz table), features, network, the decision replay, and the rest of the command (verdict, physics, output).
The target: >= 1,000x real time for the whole command.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench import REPO


def simulate(minutes: float, out: Path) -> Path:
    cmd = [sys.executable, "-m", "monitor.cli", "simulate", "--out", str(out), "--format", "tlog"]
    cmd += ["--duration-s", str(int(minutes * 60)), "--label", "4", "--propellers", "quadratic", "--seed", "1"]
    subprocess.run(cmd, check=True, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return out / "flight_000.tlog"


def log_seconds(tlog: Path) -> float:
    """The log's length: the span of its ATTITUDE samples on the autopilot's boot clock."""
    from monitor.logs import read_raw

    t_us = read_raw(tlog, "tlog", extras=False).attitude_rad.t_us
    return float(t_us[-1] - t_us[0]) / 1e6


def child_cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_command(tree: Path, tlog: Path, model: Path | None, repeat: int) -> tuple[float, float, bytes]:
    """(best wall s, best CPU s, stdout) of ``propwatch diagnose TLOG --json`` run from ``tree`` (its own monitor
    package: the working directory comes first on ``python -m``'s path)."""
    cmd = [sys.executable, "-m", "monitor.cli", "diagnose", str(tlog), "--json"] + (["--model", str(model)] if model else [])
    walls, cpus, out = [], [], b""
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), child_cpu_s()
        done = subprocess.run(cmd, cwd=tree, capture_output=True)
        walls.append(time.perf_counter() - t0)
        cpus.append(child_cpu_s() - c0)
        if done.returncode not in (0, 3):  # 3: a fault found
            raise SystemExit(f"{tree}: diagnose exited {done.returncode}: {done.stderr.decode()[-500:]}")
        out = done.stdout
    return min(walls), min(cpus), out


def pymavlink_parse_only(path: Path) -> int:
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(path), dialect="common")
    n = 0
    while conn.recv_match() is not None:
        n += 1
    conn.close()
    return n


def best(fn, repeat: int):
    """(best wall s, best CPU s, result) of ``fn`` in this process."""
    walls, cpus, out = [], [], None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return min(walls), min(cpus), out


def stages(tlog: Path, model: Path | None) -> list[tuple[str, float]]:
    """CPU seconds per stage of one diagnosis in this process (imports measured in a fresh interpreter)."""
    c0 = child_cpu_s()
    subprocess.run([sys.executable, "-c", "import monitor.cli, monitor.diagnose.cli"], cwd=REPO, check=True)
    out = [("process start and imports", child_cpu_s() - c0)]
    from monitor.decision.config import DecisionConfig
    from monitor.diagnose import engine
    from monitor.diagnose.engine import default_model
    from monitor.features import compute_features
    from monitor.logs import read_raw, to_flight_table
    from monitor.model import Classifier, choose_esc

    c = time.process_time()

    def mark(name):
        nonlocal c
        now = time.process_time()
        out.append((name, now - c))
        c = now

    clf = Classifier(model or default_model(None))
    esc = choose_esc(clf, "")
    mark("model load")
    raw = read_raw(tlog, None, extras=False)
    mark("read (tlog -> streams)")
    table = to_flight_table(raw, esc=esc, rate_hz=clf.info.sample_rate_hz)
    mark("grid (streams -> 20 Hz table)")
    feats = compute_features(table.signals(), clf.info.features)
    ends = engine.window_ends(table, feats, clf.info.window, 20)
    mark("features and usable windows")
    labels, faults = engine.predict_at(clf, feats, ends, clf.info.window, engine.PREDICT_BATCH_WINDOWS)
    mark(f"network ({len(ends)} windows)")
    engine.replay_decision(table, clf, DecisionConfig(), ends, labels, faults)
    mark("decision replay")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tlog", type=Path)
    p.add_argument("--minutes", type=float, default=30.0)
    p.add_argument("--model", type=Path, default=None, help="default: the command's own (models/classifier.onnx)")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--against", default="", help="a git revision whose tree runs the same command beside this one")
    p.add_argument("--stages", action="store_true", help="also where this tree's CPU goes, stage by stage")
    args = p.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        model = args.model
        if model is None and not (REPO / "models" / "classifier.onnx").is_file():
            from tests.test_diagnose_fixtures import build_model

            model = build_model(Path(tmp) / "fixture.onnx")
            print(f"(no models/classifier.onnx: using the test fixture model {model})")
        tlog = args.tlog
        if tlog is None:
            t0 = time.perf_counter()
            tlog = simulate(args.minutes, Path(tmp) / "sim")
            print(f"simulated {args.minutes:g} min tlog in {time.perf_counter() - t0:.0f} s")
        rows = [("propwatch diagnose --json (this tree)", *run_command(REPO, tlog, model, args.repeat))]
        same = None
        if args.against:
            other = Path(tmp) / "against"
            other.mkdir()
            archive = subprocess.run(["git", "-C", str(REPO), "archive", args.against], check=True, capture_output=True)
            subprocess.run(["tar", "-x", "-C", str(other)], input=archive.stdout, check=True)
            rows.append((f"propwatch diagnose --json ({args.against})", *run_command(other, tlog, model, args.repeat)))
            same = rows[0][3] == rows[1][3]
        t_pm, c_pm, n_msgs = best(lambda: pymavlink_parse_only(tlog), 1)
        rows.append(("pymavlink parse only (all messages)", t_pm, c_pm, b""))
        size_mb = tlog.stat().st_size / 1e6
        log_s = log_seconds(tlog)
        profile = stages(tlog, model) if args.stages else []

    print(f"tlog: {tlog.name}, {size_mb:.1f} MB, {log_s:.0f} s of log, {n_msgs} MAVLink messages")
    print(f"{'':<44}{'wall s':>9}{'x real':>8}{'CPU s':>9}{'x real':>8}")
    for name, wall, cpu, _ in rows:
        print(f"{name:<44}{wall:9.3f}{log_s / wall:8.0f}{cpu:9.3f}{log_s / max(cpu, 1e-9):8.0f}")
    if same is not None:
        print(f"JSON identical to {args.against}'s: {'yes' if same else 'NO'}", end="")
        if not same:
            ours, theirs = (json.loads(r[3]) for r in rows[:2])
            keys = sorted(k for k in set(ours) | set(theirs) if ours.get(k) != theirs.get(k))
            print(f" (top-level keys that differ: {', '.join(keys)})", end="")
        print()
    if profile:
        total = rows[0][2]
        print(f"where this tree's CPU goes (of {total:.3f} s):")
        for name, cpu in profile:
            print(f"  {name:<42}{cpu:9.3f}")
        print(f"  {'rest (verdict, physics, output)':<42}{total - sum(c for _, c in profile):9.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
