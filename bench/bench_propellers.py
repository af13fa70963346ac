"""Simulator real-time factor with LSTM propellers against analytic ones, in the same run.

    .venv/bin/python -m bench.bench_propellers [--batch 256] [--duration-s 10] [--threads 1]

Prints, per propeller kind: wall and CPU time, aggregate real-time factor
(flights x simulated seconds / seconds) on each, and the propeller model's own
CPU cost per physics step. On a shared machine the CPU-time figure is the
one-core figure; the wall figure includes waiting for the core. Conditions are a fixed random mix (seed 0) of normal,
bent and cracked rotors. The target: >= 500x aggregate at batch 256 on
one core with LSTM propellers.
"""

from __future__ import annotations

import argparse
import os
import sys
import time


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--duration-s", type=float, default=10.0)
    ap.add_argument("--threads", type=int, default=1, help="BLAS threads (set before numpy loads)")
    args = ap.parse_args(argv)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(args.threads)

    import numpy as np

    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
    from offline.propellers import build_propellers
    from offline.sim.mission import random_waypoints
    from offline.sim.propeller import QuadraticPropeller
    from offline.sim.simulator import SimConfig, simulate

    vehicle = load_vehicle(DEFAULT_VEHICLE)
    cfg = SimConfig(duration_s=args.duration_s)
    cond = np.random.default_rng(0).integers(0, 3, (args.batch, 4))
    wps = random_waypoints(args.batch, 5, seed=0)
    kinds = {
        "sim QuadraticPropeller": lambda: QuadraticPropeller.for_vehicle(vehicle),
        "quadratic (fault signatures)": lambda: build_propellers(vehicle, cond, kind="quadratic", rng_seed=0),
        "lstm": lambda: build_propellers(vehicle, cond, kind="lstm", rng_seed=0),
    }
    print(f"batch {args.batch}, {args.duration_s} s simulated, physics {cfg.physics_rate_hz} Hz, threads {args.threads}")
    omega = np.full((args.batch, 4), vehicle.hover_omega_rad_s)
    dt = 1.0 / cfg.physics_rate_hz
    for name, make in kinds.items():
        prop = make()
        prop.reset(omega)
        n_calls = 2000
        c0 = time.process_time()
        for _ in range(n_calls):
            prop(omega, dt)
        per_call_us = (time.process_time() - c0) / n_calls * 1e6
        t0, c0 = time.perf_counter(), time.process_time()
        simulate(vehicle, wps, make(), cfg, seed=0)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        flight_s = args.batch * args.duration_s
        print(
            f"{name:30s} wall {wall:6.2f} s ({flight_s / wall:6.0f}x)   cpu {cpu:6.2f} s ({flight_s / cpu:6.0f}x real time)   "
            f"propeller step {per_call_us:6.1f} us cpu/call",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
