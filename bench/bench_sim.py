"""Simulator speed and memory: real-time factors at batch 1 and 256 (80 s flights, one core),
peak memory against batch size, and RotorPy (Multirotor + SE3Control, 5 ms step) side by side.

    .venv/bin/python -m bench.bench_sim [--quick] [--json]

The figures print; nothing is asserted (speed depends on the machine and its load). Both
wall-clock and process CPU time are given: on a shared machine the CPU-time figure is the
fairer one.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one core, before numpy loads
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402

import numpy as np  # noqa: E402

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle  # noqa: E402
from offline.sim.mission import random_waypoints  # noqa: E402
from offline.sim.propeller import QuadraticPropeller  # noqa: E402
from offline.sim.simulator import SimConfig, simulate  # noqa: E402


def time_sim(vehicle, n: int, duration_s: float, randomised: bool = False) -> dict:
    """``randomised``: every flight with its own physics drawn from the assumption register (per-flight path)."""
    sim = dataclasses.replace(SimConfig(), duration_s=duration_s)
    wps = random_waypoints(n, 5, seed=1)
    prop = QuadraticPropeller.for_vehicle(vehicle)
    per_flight = None
    if randomised:
        from offline.sim.assumptions import REGISTER, draw_flights
        from offline.sim.perflight import PerFlightTerms

        per_flight = PerFlightTerms.from_flights(draw_flights(REGISTER, 0, range(n)), vehicle)
    w0, c0 = time.perf_counter(), time.process_time()
    simulate(vehicle, wps, prop, sim, seed=0, per_flight=per_flight)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    flown = n * duration_s
    return {
        "flights": n,
        "duration_s": duration_s,
        "wall_s": round(wall, 3),
        "cpu_s": round(cpu, 3),
        "rtf_wall": round(flown / wall, 1),
        "rtf_cpu": round(flown / cpu, 1),
    }


def peak_memory(vehicle, n: int, duration_s: float) -> int:
    sim = dataclasses.replace(SimConfig(), duration_s=duration_s)
    wps = random_waypoints(n, 5, seed=1)
    tracemalloc.start()
    tracemalloc.reset_peak()
    simulate(vehicle, wps, QuadraticPropeller.for_vehicle(vehicle), sim, seed=0)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def time_rotorpy(duration_s: float, t_step_s: float = 0.005) -> dict:
    try:
        from rotorpy.controllers.quadrotor_control import SE3Control
        from rotorpy.trajectories.hover_traj import HoverTraj
        from rotorpy.vehicles.crazyflie_params import quad_params
        from rotorpy.vehicles.multirotor import Multirotor
    except ImportError as exc:
        return {"error": f"rotorpy not installed ({exc}); pip install rotorpy"}
    state = {
        "x": np.array([1.0, -1.0, 0.5]),
        "v": np.zeros(3),
        "q": np.array([0, 0, 0, 1.0]),
        "w": np.zeros(3),
        "wind": np.zeros(3),
        "rotor_speeds": np.full(4, 1788.53),
    }
    vehicle = Multirotor(quad_params, initial_state=state)
    controller = SE3Control(quad_params)
    traj = HoverTraj()
    steps = int(round(duration_s / t_step_s))
    w0, c0 = time.perf_counter(), time.process_time()
    for k in range(steps):
        t = k * t_step_s
        control = controller.update(t, state, traj.update(t))
        state = vehicle.step(state, control, t_step_s)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return {
        "flights": 1,
        "duration_s": duration_s,
        "t_step_s": t_step_s,
        "wall_s": round(wall, 3),
        "cpu_s": round(cpu, 3),
        "rtf_wall": round(duration_s / wall, 1),
        "rtf_cpu": round(duration_s / cpu, 1),
        "final_error_m": float(np.linalg.norm(state["x"])),
    }


def numpy_call_us() -> float:
    """Cost of one small numpy call here and now: the unit a simulator step is made of."""
    a, b = np.ones((1, 4)), np.ones((1, 4))
    n = 20000
    t0 = time.process_time()
    for _ in range(n):
        np.multiply(a, b, out=a)
    return (time.process_time() - t0) / n * 1e6


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="short flights (smoke test of the script)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    args = p.parse_args(argv)
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    dur = 4.0 if args.quick else 80.0
    big = 16 if args.quick else 256
    sim = SimConfig()
    out = {
        "rates_hz": {
            "physics": sim.physics_rate_hz,
            "control": sim.control_rate_hz,
            "position": sim.position_rate_hz,
            "log": sim.log_rate_hz,
        },
        "batch_1": time_sim(vehicle, 1, dur),
        f"batch_{big}": time_sim(vehicle, big, dur),
        f"batch_{big}_randomised": time_sim(vehicle, big, dur, randomised=True),
    }
    mem_dur = 2.0 if args.quick else 10.0
    sizes = (8, 32) if args.quick else (32, 128, 512)
    out["peak_memory"] = {f"batch_{n}": peak_memory(vehicle, n, mem_dur) for n in sizes}
    per = [out["peak_memory"][f"batch_{n}"] / n for n in sizes]
    out["peak_memory_bytes_per_flight"] = [round(x) for x in per]
    out["peak_memory_duration_s"] = mem_dur
    out["rotorpy"] = time_rotorpy(2.0 if args.quick else 10.0)
    out["numpy_call_us"] = round(numpy_call_us(), 3)
    if "error" not in out["rotorpy"]:
        # Same machine, same moment: the ratio survives a loaded machine better than either figure.
        for key in ("batch_1", f"batch_{big}", f"batch_{big}_randomised"):
            out[key]["x_rotorpy_cpu"] = round(out[key]["rtf_cpu"] / out["rotorpy"]["rtf_cpu"], 1)
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(
        f"numpy reference: one small ufunc call = {out['numpy_call_us']:.2f} us of CPU (scales every figure below; compare runs by it)"
    )
    print(
        f"propwatch simulator, physics {sim.physics_rate_hz} Hz / control {sim.control_rate_hz} Hz / "
        f"position {sim.position_rate_hz} Hz / log {sim.log_rate_hz} Hz, one thread"
    )
    for key in ("batch_1", f"batch_{big}", f"batch_{big}_randomised"):
        r = out[key]
        print(
            f"  {r['flights']:4d} x {r['duration_s']:.0f} s flights: wall {r['wall_s']:7.2f} s  cpu {r['cpu_s']:7.2f} s  "
            f"real-time factor {r['rtf_wall']:8.1f} (wall)  {r['rtf_cpu']:8.1f} (cpu)"
            + (f"  = {r['x_rotorpy_cpu']:.0f} x RotorPy" if "x_rotorpy_cpu" in r else "")
            + ("  (per-flight drawn physics)" if key.endswith("randomised") else "")
        )
    print(f"  peak traced memory over {mem_dur:.0f} s flights:")
    for n, b in zip(sizes, per):
        print(f"    batch {n:4d}: {out['peak_memory'][f'batch_{n}'] / 2**20:8.2f} MiB  ({b / 2**10:7.1f} KiB per flight)")
    r = out["rotorpy"]
    if "error" in r:
        print(f"  RotorPy: {r['error']}")
    else:
        print(
            f"  RotorPy Multirotor + SE3Control, {r['t_step_s'] * 1000:.0f} ms step, 1 x {r['duration_s']:.0f} s: "
            f"wall {r['wall_s']:.2f} s  cpu {r['cpu_s']:.2f} s  real-time factor {r['rtf_wall']:.1f} (wall)  "
            f"{r['rtf_cpu']:.1f} (cpu)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
