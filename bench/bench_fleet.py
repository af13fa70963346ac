"""Fleet ingest throughput: logs/s and MB/s for 200 mixed logs, serial vs Ray with 1 and 2 workers.

    python bench/bench_fleet.py [--dir /tmp/propwatch-fleet-bench] [--data ../shared/data] [--runs serial,ray1,ray2]

The 200 logs are made once into --dir and reused: simulated PX4-like .tlogs
(``offline.fleet_sim``: 12 vehicles, 20 s and 40 s flights, one vehicle bending a
propeller) plus the real logs of ../shared/data (3 PX4 ULogs, 1 ArduPilot
DataFlash, CrazyPAD motor CSVs up to 200 in all; distinct files, since ingest keys
rows by content). Each run ingests them into a fresh DuckDB file.
Figures: logs/s and MB/s over the processing time (first task submitted to last
row committed), Ray start-up apart; the re-ingest of the same 200 against the
first run; Ray's per-task overhead (1000 empty tasks on the 2-worker instance)
and the per-log overhead of a Ray worker against the serial loop. The 1-minute
load average before each run says how busy the shared machine was: on a busy
2-core machine the 2-worker figure is a lower bound of Ray's scaling.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
# One BLAS/OpenMP thread per process, as Ray gives each 1-CPU worker: the serial loop is then one
# core's worth of work too, and idle BLAS threads do not spin against the workers on a busy machine.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from fleet.ingest import ingest  # noqa: E402
from fleet.worker import IngestSettings  # noqa: E402

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
    """Worker CPU seconds per log and per minute of logged flight (load-independent, unlike wall time)."""
    import duckdb

    con = duckdb.connect(str(db), read_only=True)
    try:
        n, cpu, minutes = con.execute("SELECT count(*), sum(process_cpu_s), sum(duration_s) / 60 FROM flights").fetchone()
    finally:
        con.close()
    return dict(cpu_s_per_log=round(cpu / n, 4), cpu_s_per_flight_min=round(cpu / minutes, 4), flight_minutes=round(minutes, 1))


def ray_task_overhead_s(n: int = 1000) -> float:
    import ray

    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING)
    try:

        @ray.remote
        def nothing():
            return None

        ray.get([nothing.remote() for _ in range(50)])  # warm the workers
        t = time.perf_counter()
        ray.get([nothing.remote() for _ in range(n)])
        return (time.perf_counter() - t) / n
    finally:
        ray.shutdown()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()) / "propwatch-fleet-bench")
    p.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    p.add_argument("--runs", default="serial,ray1,ray2")
    p.add_argument("--json", type=Path, default=None, help="also write the figures here")
    a = p.parse_args(argv)
    logs = make_logs(a.dir, a.data)
    mb = sum(f.stat().st_size for f in logs) / 1e6
    print(f"{len(logs)} logs, {mb:.1f} MB, {os.cpu_count()} CPUs")
    settings = IngestSettings(csv_format="crazypad", vehicle_from_dir=1)
    results = {}
    for run in [r.strip() for r in a.runs.split(",") if r.strip()]:
        db = a.dir / f"bench-{run}.duckdb"
        db.unlink(missing_ok=True)
        load = os.getloadavg()[0]
        address, workers = ("off", None) if run == "serial" else ("auto", int(run.removeprefix("ray")))
        s = ingest([str(f) for f in logs], db, settings, ray_address=address, workers=workers, progress=False)
        again = ingest([str(f) for f in logs], db, settings, ray_address=address, workers=workers, progress=False)
        assert again.new == 0 and again.already_known == len(logs)
        cpu = cpu_cost(db)
        results[run] = dict(
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
            **cpu,
        )
        r = results[run]
        print(
            f"{run:>6}: {r['logs_per_s']:.2f} logs/s, {r['mb_per_s']:.2f} MB/s (processing {r['process_s']:.1f} s, "
            f"Ray start {r['ray_start_s']:.1f} s, total {r['total_s']:.1f} s; {r['ok']} verdicts, {r['no_verdict']} no verdict, "
            f"{r['error']} errors); re-ingest {r['reingest_s']:.2f} s = {100 * r['reingest_fraction']:.1f} % of the first run; "
            f"load {r['load_1min_before']} before; worker CPU {r['cpu_s_per_log']:.3f} s/log, "
            f"{r['cpu_s_per_flight_min']:.3f} s per flight-minute"
        )
    if "serial" in results:
        for run in ("ray1", "ray2"):
            if run in results:
                results[run]["speedup_vs_serial"] = round(results[run]["logs_per_s"] / results["serial"]["logs_per_s"], 3)
                print(f"{run} / serial throughput: {results[run]['speedup_vs_serial']:.2f}x")
        if "ray1" in results:
            per_log = (results["ray1"]["process_s"] - results["serial"]["process_s"]) / len(logs)
            results["ray_per_log_overhead_s"] = round(per_log, 4)
            print(f"Ray (1 worker) vs serial, per log: {1000 * per_log:+.1f} ms")
        results["serial_s_per_log"] = round(results["serial"]["process_s"] / len(logs), 4)
    results["ray_task_overhead_s"] = round(ray_task_overhead_s(), 6)
    print(f"Ray per-task overhead (empty task, 2 workers): {1000 * results['ray_task_overhead_s']:.2f} ms")
    results["load_1min_after"] = round(os.getloadavg()[0], 2)
    results["logs_mb"] = round(mb, 2)
    if a.json:
        a.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
