"""``propwatch dataset --ray``: the data set's chunks of flights as Ray tasks.

``generate`` cuts a data set into chunks (``DatasetSpec.chunk_flights`` flights of
one vehicle variant) and seeds each chunk from (seed, variant, chunk start), so a
chunk's flights do not depend on which process simulates it or when. Here each
chunk is one Ray task; results come back in chunk order, so the arrays equal the
serial run's bit for bit whatever the number of workers (a test proves it).
The chunk size is part of the data set's definition (it is in the manifest):
use smaller chunks to give more workers something to do.

A task returns only the float32 signals the data set keeps (``from_log`` casts
to float32 anyway), not the whole flight log, to keep the object store small.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

TASK_MAX_RETRIES = 3
IN_FLIGHT_PER_WORKER = 2


@dataclass(frozen=True)
class ChunkSignals:
    """What ``generate.from_log`` reads from a flight log: ``signals()`` and ``log_rate_hz``."""

    arrays: dict
    log_rate_hz: float

    def signals(self) -> dict[str, np.ndarray]:
        return self.arrays


def simulate_chunk(job: tuple):
    """Run one chunk job ``(function, keyword arguments)``; a flight log comes back as its float32 signals."""
    fn, kw = job
    out = fn(**kw)
    if hasattr(out, "signals"):
        return ChunkSignals({k: np.asarray(v, dtype=np.float32) for k, v in out.signals().items()}, float(out.log_rate_hz))
    return out  # already the signals (randomised physics)


def _flights(job: tuple) -> int:
    kw = job[1]
    return len(kw["conditions"] if "conditions" in kw else kw["cond"])


def ray_chunks(address: str = "auto", workers: int | None = None, progress: bool = True):
    """A ``run_chunks`` for ``generate``: chunks as Ray tasks, yielded in order, with a progress bar."""
    from fleet.raycluster import cluster_cpus, ray_session

    def run(jobs: list[tuple]):
        with ray_session(address, workers) as ray:
            task = ray.remote(num_cpus=1, max_retries=TASK_MAX_RETRIES)(simulate_chunk)
            window = (workers or cluster_cpus(ray)) * IN_FLIGHT_PER_WORKER
            bar = _bar(sum(_flights(j) for j in jobs), progress)
            refs: list = []
            finished: set = set()
            try:
                for i in range(len(jobs)):
                    while len(refs) < len(jobs) and len(refs) - i < window:
                        refs.append(task.remote(jobs[len(refs)]))
                    while refs[i] not in finished:
                        running = [r for r in refs[i:] if r not in finished]
                        ready, _ = ray.wait(running, num_returns=1)
                        for r in ready:
                            finished.add(r)
                            bar.update(_flights(jobs[refs.index(r)]))
                    out = ray.get(refs[i])
                    refs[i] = None  # let the object store drop it
                    yield out
            finally:
                bar.close()

    return run


def _bar(total: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, unit="flight", desc="dataset (ray)", file=sys.stderr, disable=not enabled)
