"""Fleet ingest throughput: logs/s and MB/s for 200 mixed logs, serial vs Ray with 1 and 2 workers.

    python -m bench.bench_fleet [--dir /tmp/propwatch-fleet-bench] [--data ../shared/data]
                                [--runs serial,ray1,ray2] [--json out.json]

The 200 logs are made once into --dir and reused: simulated PX4-like .tlogs
(``offline.fleet_sim``: 12 vehicles, 20 s and 40 s flights, one vehicle bending a
propeller) plus the real logs of ../shared/data (3 PX4 ULogs, 1 ArduPilot
DataFlash, CrazyPAD motor CSVs up to 200 in all; distinct files, since ingest keys
rows by content). Each run ingests them into a fresh DuckDB file.
Figures: logs/s and MB/s over the processing time (first worker started to last
row committed: the Ray workers' imports and model loads are inside it, Ray's own
start-up is apart); the re-ingest of the same 200 against the first run; Ray's
overhead per empty task and per empty actor call (1000 on a warm 2-worker
instance) and the per-log difference of 1 Ray worker against the serial loop.
Every process runs one compute thread (onnxruntime intra-op 1 always; the
BLAS/OpenMP variables below, which the Ray workers inherit), so the serial loop
is one core's worth of work and N workers are N.

The machine is shared: for each run the bench reports the CPU seconds other
users' processes took meanwhile (/proc/stat minus this bench's process tree) and
the cores its workers kept busy on logs. ``--runs ...,pool2`` adds a control: the
same worker class on a plain 2-process pool, no Ray, i.e. what this machine gives
two processes at that moment. A name given twice is run twice; ratios use medians.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import shutil
import tempfile
import time
from pathlib import Path

from bench import REPO

# One BLAS/OpenMP thread per process, as Ray gives each 1-CPU worker: the serial loop is then one
# core's worth of work too, and idle BLAS threads do not spin against the workers on a busy machine.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from fleet.ingest import LOGS_PER_CALL, ingest, ray_batches  # noqa: E402
from fleet.worker import IngestSettings, LogWorker  # noqa: E402

N_LOGS = 200
STAMP = "bench-logs.json"


def make_logs(root: Path, data: Path) -> list[Path]:
    """Write (once) and list the 200 logs."""
    if (root / STAMP).is_file():
        return [root / p for p in json.loads((root / STAMP).read_text())["logs"]]
    from offline.fleet_sim import FleetSpec, write_fleet

    root.mkdir(parents=True, exist_ok=True)
    logs: list[Path] = []
    real = root / "real"
    real.mkdir(exist_ok=True)
    for src in sorted((data / "px4_ulog").glob("*.ulg")) + [data / "ardupilot_log171" / "log171.bin"]:
        if src.is_file():
            shutil.copy(src, real / src.name)
            logs.append(real / src.name)
    csvs = sorted((data / "crazypad" / "motor").rglob("*.csv.gz"))[:20]
    for i, src in enumerate(csvs):
        dst = real / "crazypad" / f"{i:02d}_{src.parent.name}_{src.name}"
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(src, dst)
        logs.append(dst)
    n_sim = N_LOGS - len(logs)
    per = n_sim // 12
    extra = n_sim - 12 * per
    t = time.perf_counter()
    logs += write_fleet(root / "sim", FleetSpec(vehicles=6, flights=per, duration_s=20.0, seed=1))
    logs += write_fleet(
        root / "sim",
        FleetSpec(
            vehicles=6, flights=per, duration_s=40.0, seed=2, first_vehicle=6, faulty_vehicle=2, fault_from_flight=per // 2
        ),
    )
    if extra:
        logs += write_fleet(root / "sim", FleetSpec(vehicles=1, flights=extra, duration_s=30.0, seed=3, first_vehicle=12))
    print(f"simulated {n_sim} flights in {time.perf_counter() - t:.0f} s into {root}")
    (root / STAMP).write_text(json.dumps({"logs": [str(p.relative_to(root)) for p in logs]}))
    return logs


def cpu_cost(db: Path) -> dict:
    """Worker CPU seconds per log and per minute of logged flight (less load-dependent than wall time, though it
    still grows when other work shares the cores and their caches)."""
    import duckdb

    con = duckdb.connect(str(db), read_only=True)
    try:
        n, cpu, minutes = con.execute("SELECT count(*), sum(process_cpu_s), sum(duration_s) / 60 FROM flights").fetchone()
    finally:
        con.close()
    return dict(cpu_s_per_log=round(cpu / n, 4), cpu_s_per_flight_min=round(cpu / minutes, 4), flight_minutes=round(minutes, 1))


def _process_name(pid: int) -> str:
    """``ray::<task or actor>`` as Ray titles its workers, else the program's file name (gcs_server, raylet, python)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            argv = f.read().decode(errors="replace").split("\0")
    except OSError:
        return "?"
    if argv[0].startswith("ray::"):
        return argv[0].split()[0].split(".")[0].removesuffix("()")
    script = next((a for a in argv[1:3] if a.endswith(".py")), "")
    return Path(script or argv[0]).name or "?"


def _busy_cpu_s() -> float:
    """CPU seconds the whole machine has been busy since boot (/proc/stat: user, nice, system, irq, softirq;
    guest time is inside user, steal is the hypervisor's)."""
    with open("/proc/stat") as f:
        user, nice, system, _idle, _iowait, irq, softirq = (int(x) for x in f.readline().split()[1:8])
    return (user + nice + system + irq + softirq) / os.sysconf("SC_CLK_TCK")


class CpuShare:
    """CPU seconds this bench's own processes (it and every descendant: Ray's raylet, GCS, workers) took
    during a run, against the whole machine's: the rest is other users' work competing for the same cores.

    Own processes are sampled every ``interval_s`` from /proc (one that ends between two samples loses at
    most that much); the machine's total comes from /proc/stat and misses nothing.
    """

    def __init__(self, interval_s: float = 0.5):
        self.interval_s = interval_s
        self.hz = os.sysconf("SC_CLK_TCK")
        self.me = os.getpid()
        self.first: dict[tuple[int, int], float] = {}
        self.last: dict[tuple[int, int], float] = {}
        self.name: dict[tuple[int, int], str] = {}

    def _sample(self) -> None:
        parent, cpu = {}, {}
        for pid in filter(str.isdigit, os.listdir("/proc")):
            try:
                with open(f"/proc/{pid}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            key = (int(pid), int(fields[19]))  # (pid, start time): a reused pid is another process
            parent[key[0]] = int(fields[1])
            cpu[key] = (int(fields[11]) + int(fields[12])) / self.hz
        for key, c in cpu.items():
            pid = key[0]
            while pid > 1 and pid != self.me:
                pid = parent.get(pid, 0)
            if pid == self.me:
                # a process born during the run counts from zero; one alive at the start from its CPU then
                self.first.setdefault(key, c if self.started is None else 0.0)
                self.last[key] = c
                if self.name.get(key, "ray::IDLE") == "ray::IDLE":  # a worker is titled by what it runs
                    self.name[key] = _process_name(key[0])

    def _loop(self) -> None:
        while not self.stop.wait(self.interval_s):
            self._sample()

    def __enter__(self):
        import threading

        self.started = None
        self._sample()
        self.started = time.perf_counter()
        self.busy0 = _busy_cpu_s()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join()
        self._sample()
        self.wall_s = time.perf_counter() - self.started
        self.machine_cpu_s = _busy_cpu_s() - self.busy0
        self.own_cpu_s = sum(self.last[k] - self.first[k] for k in self.last)
        self.own_by_name: dict[str, float] = {}
        for k in self.last:
            self.own_by_name[self.name[k]] = self.own_by_name.get(self.name[k], 0.0) + self.last[k] - self.first[k]

    def figures(self) -> dict:
        others = max(0.0, self.machine_cpu_s - self.own_cpu_s)
        return dict(
            wall_s=round(self.wall_s, 2),
            own_cpu_s=round(self.own_cpu_s, 2),
            others_cpu_s=round(others, 2),
            others_cores=round(others / self.wall_s, 2),  # mean cores other users kept busy during the run
            own_cpu_s_by_process={
                k: round(v, 2) for k, v in sorted(self.own_by_name.items(), key=lambda kv: -kv[1]) if v >= 0.05
            },
        )


def ray_call_overheads_s(n: int = 1000) -> dict:
    """Seconds per empty Ray task and per empty call to an actor (2 workers, warm), as ingest's calls pay them."""
    import ray

    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING)
    try:

        @ray.remote
        def nothing():
            return None

        @ray.remote(num_cpus=1)
        class Nothing:
            def call(self):
                return None

        ray.get([nothing.remote() for _ in range(50)])  # warm the workers
        t = time.perf_counter()
        ray.get([nothing.remote() for _ in range(n)])
        task_s = (time.perf_counter() - t) / n
        actors = [Nothing.remote() for _ in range(2)]
        ray.get([a.call.remote() for a in actors])
        t = time.perf_counter()
        ray.get([actors[i % 2].call.remote() for i in range(n)])
        return dict(ray_task_overhead_s=round(task_s, 6), ray_actor_call_overhead_s=round((time.perf_counter() - t) / n, 6))
    finally:
        ray.shutdown()


_POOL_WORKER = None


def _pool_init(settings: IngestSettings) -> None:
    global _POOL_WORKER
    _POOL_WORKER = LogWorker(settings)


def _pool_batch(jobs: list) -> list[dict]:
    return _POOL_WORKER.process_batch(jobs)


def pool_ingest(logs: list[Path], db: Path, settings: IngestSettings, workers: int) -> tuple[float, list[dict]]:
    """Control run without Ray: the same worker class and calls on a plain process pool, rows inserted by
    this process. What it gets over the serial loop is what this machine allows now, whatever Ray adds."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    from fleet.discover import content_hash
    from fleet.schema import insert_rows, open_db

    todo = [(str(f), content_hash(f), f.stat().st_size) for f in logs]
    con = open_db(db)
    rows: list[dict] = []
    t = time.perf_counter()
    try:
        pool = ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn"), initializer=_pool_init, initargs=(settings,))
        with pool:
            for batch in pool.map(_pool_batch, ray_batches(todo, LOGS_PER_CALL)):
                for row in batch:
                    row["mtime_ns"] = None
                rows += batch
                insert_rows(con, batch)
    finally:
        con.close()
    return time.perf_counter() - t, rows


def median(xs: list[float]) -> float:
    xs = sorted(xs)
    return (xs[(len(xs) - 1) // 2] + xs[len(xs) // 2]) / 2


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()) / "propwatch-fleet-bench")
    p.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    p.add_argument("--runs", default="serial,ray1,ray2", help="in this order; a name repeated is run again (medians)")
    p.add_argument("--json", type=Path, default=None, help="also write the figures here")
    a = p.parse_args(argv)
    logs = make_logs(a.dir, a.data)
    mb = sum(f.stat().st_size for f in logs) / 1e6
    print(f"{len(logs)} logs, {mb:.1f} MB, {os.cpu_count()} CPUs")
    settings = IngestSettings(csv_format="crazypad", vehicle_from_dir=1)
    results: dict = {"runs": []}
    for run in [r.strip() for r in a.runs.split(",") if r.strip()]:
        db = a.dir / f"bench-{run}.duckdb"
        db.unlink(missing_ok=True)
        load = os.getloadavg()[0]
        if run.startswith("pool"):
            with CpuShare() as share:
                took_s, rows = pool_ingest(logs, db, settings, int(run.removeprefix("pool")))
            r = dict(run=run, load_1min_before=round(load, 2), logs=len(rows), process_s=round(took_s, 2))
            r.update(logs_per_s=round(len(rows) / took_s, 3), mb_per_s=round(mb / took_s, 3), **cpu_cost(db), **share.figures())
            r["worker_cores"] = round(r["cpu_s_per_log"] * r["logs"] / took_s, 2)
            results["runs"].append(r)
            print(
                f"{run:>6}: {r['logs_per_s']:.2f} logs/s (processing {took_s:.1f} s, no Ray: a process pool, the control); "
                f"load {r['load_1min_before']} before; worker CPU {r['cpu_s_per_log']:.3f} s/log, "
                f"{r['worker_cores']:.2f} cores busy on logs; "
                f"other users {r['others_cpu_s']:.1f} CPU-s ({r['others_cores']:.2f} cores) in its {r['wall_s']:.1f} s",
                flush=True,
            )
            continue
        address, workers = ("off", None) if run == "serial" else ("auto", int(run.removeprefix("ray")))
        with CpuShare() as share:
            s = ingest([str(f) for f in logs], db, settings, ray_address=address, workers=workers, progress=False)
        again = ingest([str(f) for f in logs], db, settings, ray_address=address, workers=workers, progress=False)
        assert again.new == 0 and again.already_known == len(logs)
        r = dict(
            run=run,
            load_1min_before=round(load, 2),
            logs=s.new,
            ok=s.ok,
            no_verdict=s.no_verdict,
            error=s.error,
            process_s=round(s.process_s, 2),
            ray_start_s=round(s.ray_start_s, 2),
            total_s=round(s.total_s, 2),
            logs_per_s=round(s.new / s.process_s, 3),
            mb_per_s=round(mb / s.process_s, 3),
            reingest_s=round(again.total_s, 3),
            reingest_fraction=round(again.total_s / s.total_s, 4),
            **cpu_cost(db),
            **share.figures(),
        )
        r["worker_cores"] = round(r["cpu_s_per_log"] * r["logs"] / r["process_s"], 2)  # mean cores diagnosing logs
        results["runs"].append(r)
        print(
            f"{run:>6}: {r['logs_per_s']:.2f} logs/s, {r['mb_per_s']:.2f} MB/s (processing {r['process_s']:.1f} s, "
            f"Ray start {r['ray_start_s']:.1f} s, total {r['total_s']:.1f} s; {r['ok']} verdicts, {r['no_verdict']} no verdict, "
            f"{r['error']} errors); re-ingest {r['reingest_s']:.2f} s = {100 * r['reingest_fraction']:.1f} % of the first run; "
            f"load {r['load_1min_before']} before; worker CPU {r['cpu_s_per_log']:.3f} s/log, "
            f"{r['cpu_s_per_flight_min']:.3f} s per flight-minute, {r['worker_cores']:.2f} cores busy on logs; this bench {r['own_cpu_s']:.1f} CPU-s, "
            f"other users {r['others_cpu_s']:.1f} CPU-s ({r['others_cores']:.2f} cores) in its {r['wall_s']:.1f} s",
            flush=True,
        )
    rate = {k: median([r["logs_per_s"] for r in results["runs"] if r["run"] == k]) for k in {r["run"] for r in results["runs"]}}
    results["median_logs_per_s"] = rate
    if "serial" in rate:
        for run in sorted(k for k in rate if k != "serial"):
            if run in rate:
                results[f"{run}_speedup_vs_serial"] = round(rate[run] / rate["serial"], 3)
                print(f"{run} / serial throughput (medians): {results[f'{run}_speedup_vs_serial']:.2f}x")
        if "ray1" in rate:
            per_log = 1 / rate["ray1"] - 1 / rate["serial"]
            results["ray_per_log_overhead_s"] = round(per_log, 4)
            print(f"Ray (1 worker) vs serial, per log: {1000 * per_log:+.1f} ms")
        results["serial_s_per_log"] = round(1 / rate["serial"], 4)
    results.update(ray_call_overheads_s())
    print(
        f"Ray per-call overhead (empty, 2 workers): task {1000 * results['ray_task_overhead_s']:.2f} ms, "
        f"actor call {1000 * results['ray_actor_call_overhead_s']:.2f} ms"
    )
    results["load_1min_after"] = round(os.getloadavg()[0], 2)
    results["logs_mb"] = round(mb, 2)
    if a.json:
        a.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
