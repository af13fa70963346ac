"""``fleet ingest``: new logs -> diagnose (serial or Ray actors) -> rows committed per batch.

The driver is the only writer. It finds the logs, hashes their content, skips
hashes already in the database (a re-run is incremental and idempotent), runs
``fleet.worker.process_log`` on the rest (in this process, or in one
``LogWorker`` Ray actor per worker CPU that loads the models once and takes a
few logs per call; a call whose worker process dies is run again on the
restarted actor) and inserts the rows it gets back in transactions of
``batch_rows``. A log that fails even after the retries becomes an error row;
nothing crashes the run.
"""

from __future__ import annotations

import sys
import time
from collections import deque
from dataclasses import asdict, dataclass, field
from pathlib import Path

from fleet.discover import content_hash, find_logs
from fleet.memory_adapter import judge_store
from fleet.raycluster import cluster_cpus, ray_session
from fleet.schema import (
    export_parquet,
    forget_errors,
    insert_rows,
    known_files,
    model_versions,
    open_db,
    update_mtimes,
)
from fleet.worker import IngestSettings, LogWorker, empty_row, model_version, process_log, utc_naive

TASK_MAX_RETRIES = 3  # a worker killed mid-log (OOM killer, preempted node) costs a re-run, not a row
LOGS_PER_CALL = 4  # logs per actor call: ~0.1-3 s of work against Ray's ~1 ms per call, a short tail
CALLS_IN_FLIGHT_PER_WORKER = 2  # the next call is queued at the actor while it runs one


@dataclass
class IngestSummary:
    db: str
    found: int = 0
    hashed: int = 0  # files read to hash them (the others kept path, size and mtime since ingest)
    already_known: int = 0
    other_model: int = 0  # of those, rows made by a model other than this run's (``--rediagnose`` refreshes them)
    duplicate_content: int = 0  # same bytes under two paths in this run: one row
    new: int = 0  # logs run this time (with rediagnose: known ones too)
    rediagnose: bool = False  # known logs were run again and their rows replaced
    ok: int = 0
    no_verdict: int = 0
    error: int = 0
    bytes_new: int = 0
    mode: str = "serial"
    workers: int = 1
    ray_start_s: float = 0.0
    process_s: float = 0.0  # first task submitted -> last row committed
    total_s: float = 0.0
    worker_pids: list[int] = field(default_factory=list)
    export: str | None = None
    memory_judged: int = 0  # rows judged against their vehicle's healthy flights before them (fleet.memory_adapter)

    def to_json(self) -> dict:
        out = asdict(self)
        out["logs_per_s"] = round(self.new / self.process_s, 3) if self.process_s > 0 else None
        out["mb_per_s"] = round(self.bytes_new / 1e6 / self.process_s, 3) if self.process_s > 0 else None
        return out


def _progress(total: int, enabled: bool):
    try:
        from tqdm import tqdm
    except ImportError:
        enabled = False
        tqdm = None
    if not enabled or tqdm is None:

        class _Null:
            def update(self, n=1):
                pass

            def close(self):
                pass

        return _Null()
    return tqdm(total=total, unit="log", desc="ingest", file=sys.stderr, dynamic_ncols=True, smoothing=0.1)


def ingest(
    paths: list[str],
    db: str | Path,
    settings: IngestSettings | None = None,
    ray_address: str | None = "auto",
    workers: int | None = None,
    batch_rows: int = 32,
    progress: bool = True,
    export: str | Path | None = None,
    retry_errors: bool = False,
    rehash: bool = False,
    rediagnose: bool = False,
    logs_per_call: int = LOGS_PER_CALL,
) -> IngestSummary:
    """Ingest every new log under ``paths`` into ``db``. ``ray_address`` None or "off": in this process.

    ``rehash``: read every file to hash it, even one whose path, size and mtime match its row.
    ``rediagnose``: run every found log again, known or not, and replace its row batch by batch (after a new
    propwatch, model or set rule: a stored verdict says which model made it, not whether it is stale).
    ``logs_per_call``: logs per call to a Ray worker (rows do not depend on it, nor on the number of workers).
    """
    t0 = time.perf_counter()
    settings = settings or IngestSettings()
    summary = IngestSummary(db=str(db), rediagnose=rediagnose)
    mtime_of: dict[str, int] = {}
    logs = find_logs(paths)
    summary.found = len(logs)
    con = open_db(db)
    try:
        seen_files = {} if rehash else known_files(con)
        hashed = []
        for p in logs:
            st = p.stat()
            stored = seen_files.get(str(p))
            if stored and stored[:2] == (st.st_size, st.st_mtime_ns):
                h = stored[2]  # same path, size and modification time as when ingested: not re-read
            else:
                h = content_hash(p)
                summary.hashed += 1
            mtime_of[str(p)] = st.st_mtime_ns
            hashed.append((p, h, st.st_size))
        if retry_errors:
            forget_errors(con, {h for _, h, _ in hashed})
        known = model_versions(con)  # every known log's hash -> the model that made its row
        current = {model_version(m) for m in settings.model_paths() if m.is_file()}
        todo, seen, touched = [], set(), []
        for p, h, size in hashed:
            if h in known and not rediagnose:
                summary.already_known += 1
                summary.other_model += known[h] is not None and known[h] not in current
                if str(p) in seen_files and seen_files[str(p)][2] == h and seen_files[str(p)][1] != mtime_of[str(p)]:
                    touched.append((mtime_of[str(p)], h))  # same bytes, new mtime: remember it, skip re-reading next time
            elif h in seen:
                summary.duplicate_content += 1
            else:
                seen.add(h)
                todo.append((str(p), h, size))
        update_mtimes(con, touched)
        summary.new = len(todo)
        summary.bytes_new = sum(s for _, _, s in todo)
        if todo:
            if ray_address in (None, "off"):
                _run_serial(con, todo, settings, summary, batch_rows, progress, mtime_of)
            else:
                _run_ray(con, todo, settings, summary, batch_rows, progress, mtime_of, ray_address, workers, logs_per_call)
        summary.memory_judged = judge_store(con, rediagnose)
        if export:
            summary.export = str(export_parquet(con, export))
    finally:
        con.close()
    summary.total_s = time.perf_counter() - t0
    return summary


class _Writer:
    """Buffers rows and commits them per batch; counts statuses."""

    def __init__(self, con, summary: IngestSummary, batch_rows: int, bar, mtime_of: dict[str, int]):
        self.con, self.summary, self.batch_rows, self.bar = con, summary, max(1, batch_rows), bar
        self.mtime_of = mtime_of
        self.rows: list[dict] = []
        self.pids: set[int] = set()

    def add(self, row: dict) -> None:
        row["mtime_ns"] = self.mtime_of.get(row["path"])  # as the driver saw it when hashing
        self.rows.append(row)
        setattr(self.summary, row["status"], getattr(self.summary, row["status"]) + 1)
        if row.get("worker_pid"):
            self.pids.add(row["worker_pid"])
        self.bar.update(1)
        if len(self.rows) >= self.batch_rows:
            self.flush()

    def flush(self) -> None:
        insert_rows(self.con, self.rows, replace=self.summary.rediagnose)
        self.rows = []

    def close(self) -> None:
        self.flush()
        self.bar.close()
        self.summary.worker_pids = sorted(self.pids)


def _run_serial(con, todo, settings, summary, batch_rows, progress, mtime_of) -> None:
    w = _Writer(con, summary, batch_rows, _progress(len(todo), progress), mtime_of)
    t = time.perf_counter()
    try:
        for path, h, size in todo:
            w.add(process_log(path, h, size, settings))
    finally:
        w.close()
    summary.process_s = time.perf_counter() - t


def ray_batches(todo: list[tuple[str, str, int]], logs_per_call: int) -> list[list[tuple[str, str, int]]]:
    """The logs in calls of ``logs_per_call``, largest files first (a long log started last would end the run alone)."""
    ordered = sorted(todo, key=lambda job: (-job[2], job[0]))
    size = max(1, logs_per_call)
    return [ordered[i : i + size] for i in range(0, len(ordered), size)]


def _failed_row(job: tuple[str, str, int], reason: str) -> dict:
    path, h, size = job
    row = empty_row(Path(path), h, size)
    row.update(status="error", error=f"{path}: {reason}", ingested_at=utc_naive(time.time() * 1e6))
    return row


def _run_ray(con, todo, settings, summary, batch_rows, progress, mtime_of, address, workers, logs_per_call) -> None:
    """One ``LogWorker`` actor per worker CPU, fed calls of a few logs each (two in flight per actor).

    An actor whose process dies is restarted (``max_restarts=-1``) and its unfinished calls are run again
    (``max_task_retries``); a call that still fails is split into single logs, so only a log that kills
    its worker every time becomes an error row.
    """
    t = time.perf_counter()
    with ray_session(address, workers) as ray:
        summary.ray_start_s = time.perf_counter() - t
        summary.mode = "ray"
        cpus = cluster_cpus(ray)
        n = min(workers, cpus) if workers else cpus
        summary.workers = n
        actor_cls = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=TASK_MAX_RETRIES)(LogWorker)
        w = _Writer(con, summary, batch_rows, _progress(len(todo), progress), mtime_of)
        t = time.perf_counter()
        actors = [actor_cls.remote(settings) for _ in range(n)]
        calls = deque(ray_batches(todo, logs_per_call))
        pending: dict = {}  # call ref -> (actor, its logs)

        def feed(actor) -> None:
            if calls:
                jobs = calls.popleft()
                pending[actor.process_batch.remote(jobs)] = (actor, jobs)

        starting = {actor.__ray_ready__.remote(): actor for actor in actors}  # fed once it runs: on a busy
        try:  # cluster an actor that never gets a CPU holds no calls
            while pending or starting:
                done, _ = ray.wait([*pending, *starting], num_returns=1)
                for ref in done:
                    if ref in starting:
                        actor = starting.pop(ref)
                        try:
                            ray.get(ref)
                        except ray.exceptions.RayError:
                            continue  # never started: the others take its share
                        for _ in range(CALLS_IN_FLIGHT_PER_WORKER):
                            feed(actor)
                        continue
                    actor, jobs = pending.pop(ref)
                    try:
                        rows = ray.get(ref)
                    except ray.exceptions.RayError as exc:
                        if len(jobs) > 1:  # one of them may be what kills the worker: each alone, first
                            calls.extendleft([job] for job in reversed(jobs))
                            rows = []
                        else:
                            rows = [_failed_row(jobs[0], f"failed after {TASK_MAX_RETRIES} retries: {type(exc).__name__}")]
                    for row in rows:
                        w.add(row)
                    feed(actor)
            for jobs in calls:  # left only when no worker could start
                for job in jobs:
                    w.add(_failed_row(job, "no Ray worker could start"))
        finally:
            for actor in actors:  # frees their CPUs at once, also on a cluster that outlives this run
                ray.kill(actor)
            w.close()
        summary.process_s = time.perf_counter() - t
