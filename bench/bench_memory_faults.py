"""A vehicle's history under faults: SIGKILL at random moments of landings, two daemons at once, a disk filling.

    python -m bench.bench_memory_faults                        # all three, sized for a 2-core machine (~3 minutes)
    python -m bench.bench_memory_faults --only kill9 --landings 30
    python -m bench.bench_memory_faults --only daemons --pairs 5
    python -m bench.bench_memory_faults --only diskfull
    python -m bench.bench_memory_faults --only rss --landings 150
    python -m bench.bench_memory_faults --only judged

Each starts from a state dir holding one vehicle's 200-flight baseline (synthetic healthy flights of one quirky
airframe, the summaries of ``monitor.memory.summary`` as the daemon makes them).

- ``kill9``: a process lands flights one after another through the daemon's memory (``VehicleMemory``: identify,
  20 Hz steps, disarm, learn) and prints each result; it is killed with SIGKILL after a random delay (up to twice a
  landing's time), then restarted, until ``--landings`` landings have begun. After every kill: the file loads, holds
  every flight reported learnt, and at most the one flight in progress more.
- ``daemons``: ``--pairs`` times, two ``propwatch monitor`` processes started at once on one state dir (udpin on
  loopback, nothing sent): exactly one runs; the other exits 2 naming the first's pid.
- ``rss``: ``--landings`` landings in one process through the daemon's memory, from an empty history: the
  process's RSS every 25 landings and per landing (what the soak with learning at every landing grows by), and the
  Python heap left (``tracemalloc`` is not used: it changes what it measures; ``--heap`` adds it, slower).
- ``judged``: why some of ``kill9``'s landings are "not learnt: not healthy against the vehicle's history": 100
  flights the bench flies and 100 new flights of the generator that seeded the history, each judged as a landing
  judges it (the whole flight and its ends, ``monitor.memory.through_time``) against a seeded history of 3, 20 and 200 flights: how many the landing would refuse, how many pass
  the suspect and the fault level, the statistic's median and 95th percentile.
- ``diskfull``: the state dir on a tmpfs (in a user and mount namespace: ``unshare``) with room for the baseline
  but not for a second copy of it: a landing is "not learnt: disk full", the file is unchanged and loads, no
  temporary file is left; with room made, the next landing is learnt.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

RATE_HZ = 20.0
KEY = "sysid-1"
QUIRKY = np.array([1.03, 0.97, 0.95, 1.05])
ROOT = Path(__file__).resolve().parents[1]


def flight_summary(k: int, seconds: float = 40.0):
    """The summary a healthy flight of the quirky airframe leaves (seeded by ``k``)."""
    return flight_accumulator(k, seconds).summary


def flight_accumulator(k: int, seconds: float = 40.0):
    """``flight_summary``'s flight, its summary and 2-s marks (``monitor.memory.summary.ShareAccumulator``)."""
    from monitor.memory.summary import ShareAccumulator

    rng = np.random.default_rng(1000 + k)
    n = int(seconds * RATE_HZ)
    share = QUIRKY * (1 + 0.003 * rng.standard_normal(4))
    x = 36.0 * share * (1 + 0.01 * rng.standard_normal((n, 4)))
    acc = ShareAccumulator("omega2", RATE_HZ)
    acc.table(x, 0.01 * rng.standard_normal(n), 0.01 * rng.standard_normal(n), np.ones(n, dtype=bool))
    return acc


def seed_state(root: Path, flights: int = 200) -> Path:
    """A state dir with one vehicle's ``flights``-flight baseline; returns the baseline's path."""
    from monitor.memory.baseline import VehicleBaseline
    from monitor.memory.store import StateDir

    b = VehicleBaseline(KEY, "daemon", ("1", "2", "3", "4"), "omega2")
    for k in range(flights):
        b.add(f"flight {k + 1}", "2026-05-01", flight_summary(k), "no fault")
    with StateDir.open(root) as sd:
        sd.update(KEY, lambda _: b)
        return sd.path(KEY)


def fly(mem, k: int, seconds: float = 35.0) -> None:
    """One flight through the daemon's memory: 2 s on the ground, ``seconds`` airborne, 3 s on the ground at idle."""
    rng = np.random.default_rng(5000 + k)
    share = QUIRKY * (1 + 0.003 * rng.standard_normal(4))
    n_gnd, n_air = int(2 * RATE_HZ), int(seconds * RATE_HZ)
    for i in range(n_gnd + n_air + int(3 * RATE_HZ)):
        air = n_gnd <= i < n_gnd + n_air
        rpm = 6000.0 * np.sqrt(share * (1 + 0.01 * rng.standard_normal(4))) if air else np.full(4, 1000.0)
        mem.step(i / RATE_HZ, air, rpm, 0.01 * rng.standard_normal(), 0.01 * rng.standard_normal())


def child_landings(state: Path, first: int) -> None:
    """Land flights forever (killed from outside): 'landing K' before each disarm, then 'RESULT|FLIGHTS'."""
    from monitor.daemon.memory_adapter import VehicleMemory

    mem = VehicleMemory(state, RATE_HZ)
    mem.identify(sysid=1)
    print("ready", flush=True)
    k = first
    while True:
        fly(mem, k)
        print(f"landing {k}", flush=True)
        what = mem.disarmed(None)
        n = mem.history.flights if mem.history is not None else -1
        print(f"{what}|{n}", flush=True)
        k += 1


def _rss_kb() -> int:
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("VmRSS"))


def bench_rss(landings: int, heap: bool) -> dict:
    import gc
    import tracemalloc

    from monitor.daemon.memory_adapter import VehicleMemory

    work = Path(tempfile.mkdtemp(prefix="pw-rss-"))
    mem = VehicleMemory(work / "state", RATE_HZ)
    mem.identify(sysid=1)
    for k in range(5):  # warm-up: imports, first allocations, a normal
        fly(mem, 90000 + k)
        mem.disarmed(None)
    gc.collect()
    if heap:
        tracemalloc.start()
    heap0 = tracemalloc.get_traced_memory()[0] if heap else 0
    rss = [(0, _rss_kb())]
    outcomes: dict[str, int] = {}
    cpu0 = time.process_time()
    for k in range(landings):
        fly(mem, k)
        what = mem.disarmed(None)
        outcomes[what] = outcomes.get(what, 0) + 1
        if (k + 1) % 25 == 0 or k + 1 == landings:
            rss.append((k + 1, _rss_kb()))
    cpu_s = time.process_time() - cpu0
    gc.collect()
    out = {
        "landings": landings,
        "outcomes": outcomes,
        "flights_in_file": len(json.loads(mem.path.read_text())["flights"]),
        "rss_kb_by_landings": rss,
        "rss_kb_per_landing": round((rss[-1][1] - rss[0][1]) / landings, 1),
        "cpu_s": round(cpu_s, 1),
    }
    if heap:
        out["heap_kb_per_landing"] = round((tracemalloc.get_traced_memory()[0] - heap0) / 1024 / landings, 2)
    mem.close()
    shutil.rmtree(work, ignore_errors=True)
    return out


def bench_judged(sizes=(3, 20, 200), flights: int = 100) -> dict:
    from monitor.daemon.memory_adapter import VehicleMemory
    from monitor.memory import thresholds as th
    from monitor.memory.through_time import judge_through_time

    def verdicts(normal, accs) -> dict:
        vs = [judge_through_time(normal, a.summary, a.marks) for a in accs]
        st = np.array([v["fault_statistic"] for v in vs])
        refused = sum(v["label"] != 1 or v["confidence"] == "suspect" or bool(v.get("imbalance_rotors")) for v in vs)
        return {
            "refused_by_a_landing": int(refused),
            "past_suspect": int((st >= th.SUSPECT_STATISTIC).sum()),
            "past_fault": int((st >= th.FAULT_STATISTIC).sum()),
            "statistic_p50": round(float(np.median(st)), 2),
            "statistic_p95": round(float(np.percentile(st, 95)), 2),
        }

    out: dict = {"flights_each": flights, "suspect_statistic": th.SUSPECT_STATISTIC, "fault_statistic": th.FAULT_STATISTIC}
    for size in sizes:
        work = Path(tempfile.mkdtemp(prefix="pw-judged-"))
        seed_state(work / "state", size)
        mem = VehicleMemory(work / "state", RATE_HZ)
        mem.identify(sysid=1)
        flown = []
        for k in range(flights):
            fly(mem, k)
            flown.append(mem.acc)
            mem.discard("judged, not learnt")
        out[f"history_{size}"] = {
            "seeding_generator_new_flights": verdicts(mem.normal, [flight_accumulator(k) for k in range(1000, 1000 + flights)]),
            "flown_by_the_bench": verdicts(mem.normal, flown),
            "own_spread_of_shares": np.sqrt(np.diag(mem.normal.own_cov)).round(5).tolist(),
            "spread_judged_with": np.sqrt(np.diag(mem.normal.cov)).round(5).tolist(),
        }
        mem.close()
        shutil.rmtree(work, ignore_errors=True)
    return out


def _child(args: list[str], **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "bench.bench_memory_faults", *args], env=env, text=True, **kw)


def bench_kill9(landings: int, seed: int) -> dict:
    from monitor.memory.baseline import VehicleBaseline
    from monitor.memory.store import StateDir

    rng = random.Random(seed)
    work = Path(tempfile.mkdtemp(prefix="pw-kill9-"))
    path = seed_state(work / "state")
    reported = len(VehicleBaseline.load(path).flights)
    begun, kills, lost, unreadable, learnt, not_learnt, stale, mid_landing = 0, 0, 0, 0, 0, 0, 0, 0
    why_not: dict[str, int] = {}  # each "not learnt" reason (its text up to the first colon after the verdict)
    landing_s = 2.5  # refined from the first landings
    t_start = time.monotonic()
    while begun < landings:
        p = _child(["--child-landings", str(work / "state"), str(1000 * kills)], stdout=subprocess.PIPE)
        assert p.stdout.readline().strip() == "ready"
        lines: list[str] = []
        reader = threading.Thread(target=lines.extend, args=(p.stdout,), daemon=True)
        reader.start()
        time.sleep(rng.uniform(0.0, 2.0 * landing_s))
        p.send_signal(signal.SIGKILL)
        p.wait()
        reader.join(timeout=10)
        kills += 1
        mid = False  # killed between a landing's disarm and its result: while learning or writing
        for line in lines:
            line = line.strip()
            mid = line.startswith("landing")
            if line.startswith("landing"):
                begun += 1
            elif "|" in line:
                what, n = line.rsplit("|", 1)
                if what == "learnt":
                    learnt += 1
                    reported = max(reported, int(n))
                else:
                    not_learnt += 1
                    why = ":".join(what.split(":")[:2]).strip()
                    why_not[why] = why_not.get(why, 0) + 1
        mid_landing += mid
        stale += sum(1 for q in path.parent.iterdir() if q.name.endswith(".tmp"))
        try:
            now = len(VehicleBaseline.load(path).flights)
        except Exception:  # noqa: BLE001 - counted: the figure this bench is for
            unreadable += 1
            continue
        if now < reported:
            lost += reported - now
        reported = max(reported, now)
        if begun and learnt:
            landing_s = (time.monotonic() - t_start) / max(begun, 1)
    with StateDir.open(work / "state") as sd:
        removed = sd.hold()
        final = len(sd.load(KEY).flights)
    shutil.rmtree(work, ignore_errors=True)
    return {
        "landings_begun": begun,
        "kills": kills,
        "kills_mid_landing": mid_landing,
        "reported_learnt": learnt,
        "reported_not_learnt": not_learnt,
        "not_learnt_because": why_not,
        "learnt_flights_lost": lost,
        "unreadable_after_a_kill": unreadable,
        "temporary_files_seen_after_kills": stale,
        "temporary_files_removed_at_next_start": len(removed),
        "flights_in_file_at_end": final,
    }


def bench_daemons(pairs: int) -> dict:
    work = Path(tempfile.mkdtemp(prefix="pw-daemons-"))
    seed_state(work / "state")
    ran, refused, named, both_ran = 0, 0, 0, 0
    for i in range(pairs):
        procs = [
            _daemon(work / "state", 14700 + 2 * i + j, work / f"ev{i}{j}.jsonl") for j in range(2)
        ]  # started within a millisecond of each other
        time.sleep(4.0)
        codes = [p.poll() for p in procs]
        for p in procs:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        outs = [p.communicate(timeout=30)[1] for p in procs]
        running = [j for j, c in enumerate(codes) if c is None]
        ran += len(running)
        both_ran += len(running) == 2
        for j, c in enumerate(codes):
            if c == 2:
                refused += 1
                other = procs[1 - j].pid
                named += f"pid {other}" in outs[j]
    shutil.rmtree(work, ignore_errors=True)
    return {"pairs": pairs, "ran": ran, "refused_exit_2": refused, "refusal_named_the_holder": named, "both_ran": both_ran}


def _daemon(state: Path, port: int, events: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "monitor.cli", "monitor", "--connect", f"udpin:127.0.0.1:{port}"]
    cmd += ["--state-dir", str(state), "--events", str(events)]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def bench_diskfull() -> dict:
    """Re-run inside a user and mount namespace where a tmpfs can be mounted."""
    if shutil.which("unshare") is None:
        return {"skipped": "no unshare(1)"}
    r = subprocess.run(
        [
            "unshare",
            "--user",
            "--map-root-user",
            "--mount",
            sys.executable,
            "-m",
            "bench.bench_memory_faults",
            "--inside-diskfull",
        ],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=600,
    )
    if r.returncode != 0:
        return {"skipped": f"unshare failed: {r.stderr.strip()[-300:]}"}
    return json.loads(r.stdout.strip().splitlines()[-1])


def inside_diskfull() -> dict:
    from monitor.daemon.memory_adapter import VehicleMemory
    from monitor.memory.baseline import VehicleBaseline

    mnt = Path(tempfile.mkdtemp(prefix="pw-tmpfs-"))
    seeded = Path(tempfile.mkdtemp(prefix="pw-seed-")) / "state"
    size = seed_state(seeded).stat().st_size
    # Room for the file and more than another copy; a filler leaves a third of one: the next write must fail.
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={int(size * 2.5) + 65536}", "tmpfs", str(mnt)], check=True)
    state = mnt / "state"
    shutil.copytree(seeded, state)
    os.chmod(state, 0o700)
    path = state / "vehicles" / KEY / "baseline.json"
    before = path.read_bytes()
    filler = mnt / "filler"
    free = shutil.disk_usage(mnt).free
    filler.write_bytes(b"\0" * max(free - int(size * 0.33), 0))
    mem = VehicleMemory(state, RATE_HZ)
    mem.identify(sysid=1)
    fly(mem, 1)
    full = mem.disarmed(None)
    unchanged = path.read_bytes() == before
    loads = len(VehicleBaseline.load(path).flights)
    left = [q.name for q in path.parent.iterdir() if q.name != "baseline.json"]
    filler.unlink()
    fly(mem, 2)
    after = mem.disarmed(None)
    n_after = len(VehicleBaseline.load(path).flights)
    subprocess.run(["umount", str(mnt)], check=False)
    return {
        "baseline_bytes": size,
        "landing_on_a_full_disk": full,
        "file_unchanged": unchanged,
        "flights_in_file": loads,
        "temporary_files_left": left,
        "landing_with_room_again": after,
        "flights_after": n_after,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.bench_memory_faults", description=__doc__.split("\n\n")[0])
    p.add_argument("--only", choices=("kill9", "daemons", "diskfull", "rss", "judged"), action="append")
    p.add_argument("--landings", type=int, default=30, help="kill9: landings begun (each ~2 s of CPU at 200 flights)")
    p.add_argument("--heap", action="store_true", help="rss: also the Python heap left per landing (tracemalloc)")
    p.add_argument("--pairs", type=int, default=5, help="daemons: pairs started at once")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--child-landings", nargs=2, metavar=("STATE", "FIRST"), help=argparse.SUPPRESS)
    p.add_argument("--inside-diskfull", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.child_landings:
        child_landings(Path(a.child_landings[0]), int(a.child_landings[1]))
        return 0
    if a.inside_diskfull:
        print(json.dumps(inside_diskfull()))
        return 0
    out = {}
    for name in a.only or ("kill9", "daemons", "diskfull"):
        t = time.monotonic()
        if name == "kill9":
            out[name] = bench_kill9(a.landings, a.seed)
        elif name == "daemons":
            out[name] = bench_daemons(a.pairs)
        elif name == "rss":
            out[name] = bench_rss(a.landings, a.heap)
        elif name == "judged":
            out[name] = bench_judged()
        else:
            out[name] = bench_diskfull()
        out[name]["wall_s"] = round(time.monotonic() - t, 1)
        print(json.dumps({name: out[name]}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
