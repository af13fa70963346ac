"""evalsim speed: real-time factor of the evaluation-only simulator at batch 1 and 32 (paper-set
flights), against one derivative of RotorPy's own ``Multirotor``.

    python -m bench.bench_evalsim [--duration-s 80] [--batch 32] [--json]

Prints; asserts nothing (speed depends on the machine and its load). Process CPU time is
given beside wall clock: on a shared machine CPU time is the fairer figure.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one core, before numpy loads
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from offline.evalsim.flight import WARMUP_S, multirotor_for, simulate_flights  # noqa: E402
from offline.evalsim.sets import build_set  # noqa: E402


def _timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--duration-s", type=float, default=80.0)
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    specs = build_set("paper", a.batch, seed=0, duration_s=a.duration_s)
    results = {"duration_s": a.duration_s, "warmup_s": WARMUP_S}
    for b in sorted({1, a.batch}):
        _, wall, cpu = _timed(lambda b=b: simulate_flights(specs[:b]))
        flown = b * a.duration_s
        results[f"batch_{b}"] = {
            "wall_s": wall,
            "cpu_s": cpu,
            "cpu_s_per_flight": cpu / b,
            "real_time_factor_cpu": flown / cpu,
            "real_time_factor_wall": flown / wall,
        }
    mr = multirotor_for(specs[0].airframe, lambda om: (np.full(4, 1.076e-5), np.full(4, 1.632e-7)))
    s = np.zeros(20)
    s[9], s[16:20] = 1.0, 585.0
    n = 2000
    _, wall, cpu = _timed(lambda: [mr._s_dot_fn(0.0, s, s[16:20]) for _ in range(n)])
    results["rotorpy_s_dot_us"] = 1e6 * cpu / n
    if a.json:
        print(json.dumps(results, indent=2))
        return 0
    print(f"evalsim, {a.duration_s:g} s flights (+{WARMUP_S:g} s unlogged hover), physics 250 Hz RK4:")
    for k, r in results.items():
        if k.startswith("batch_"):
            print(
                f"  {k:<9} wall {r['wall_s']:7.1f} s  cpu {r['cpu_s']:7.1f} s  "
                f"cpu per flight {r['cpu_s_per_flight']:6.2f} s  real-time factor (cpu) {r['real_time_factor_cpu']:6.1f}x"
            )
    print(f"  RotorPy Multirotor._s_dot_fn: {results['rotorpy_s_dot_us']:.0f} µs per derivative (RK4 needs 4 per step)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
