"""``propwatch simulate``: simulated flights with ground truth, as npz or PX4-like .tlog.

    propwatch simulate --out DIR [--flights K] [--label N] [--fault bent|cracked]
                       [--payload-kg X] [--waypoints-seed S] [--seed S]
                       [--duration-s 80] [--format tlog|npz]
                       [--vehicle PATH] [--propellers lstm|quadratic] [--waypoint-set A|B]

Writes ``flight_000.tlog``... (what ``propwatch diagnose`` reads; the default) or ``flights.npz`` (all flights,
for training) plus ``sidecar.json`` (ground truth and provenance) into DIR. Files are written
under temporary names and renamed, and the sidecar last, so a failed run
leaves no sidecar describing missing flights.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np

from monitor.errors import ConfigError
from monitor.labels import N_LABELS, faulty_for
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle_with_sources
from offline.manifest import write_manifest
from offline.sim.io_npz import write_npz
from offline.sim.io_tlog import write_tlog
from offline.sim.mission import random_waypoints, waypoint_set
from offline.sim.sidecar import CONDITION_NAMES, make_sidecar
from offline.sim.simulator import SimConfig, simulate

TLOG_RATE_HZ = 50  # PX4 streams ATTITUDE & co. at 50 Hz to a companion computer


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="propwatch simulate", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, type=Path, help="output directory (created)")
    p.add_argument("--flights", type=int, default=1, help="number of flights (default 1)")
    p.add_argument("--label", type=int, default=1, help=f"fault label 1..{N_LABELS} (monitor.labels; 1 = all normal)")
    p.add_argument("--fault", choices=CONDITION_NAMES[1:], default="bent", help="condition of the faulty propellers")
    p.add_argument("--payload-kg", type=float, default=0.0, help="payload added to the vehicle's mass")
    p.add_argument("--waypoints-seed", type=int, default=None, help="seed of the random waypoints (default: --seed)")
    p.add_argument("--waypoint-set", choices=("A", "B"), default=None, help="fly the paper's named route instead")
    p.add_argument("--seed", type=int, default=0, help="seed of sensor noise and propeller vibration")
    p.add_argument("--duration-s", type=float, default=80.0, help="flight duration (default 80 s, as the paper)")
    p.add_argument(
        "--format",
        choices=("npz", "tlog"),
        default="tlog",
        help="tlog: a PX4-like MAVLink log that diagnose reads (default); npz: arrays with ground truth for training",
    )
    p.add_argument("--vehicle", type=Path, default=DEFAULT_VEHICLE, help="vehicle YAML (default models/vehicle.yaml)")
    p.add_argument(
        "--propellers", choices=("lstm", "quadratic"), default="lstm", help="propeller model (offline.propellers; default lstm)"
    )
    return p.parse_args(argv)


def build_propellers(vehicle, conditions: np.ndarray, kind: str, seed: int):
    """The propeller model for ``conditions``; only offline.propellers knows faulty propellers."""
    try:
        from offline.propellers import build_propellers as build
    except ImportError as exc:
        if np.any(conditions != 0) or kind == "lstm":
            raise ConfigError(f"--propellers {kind} / faulty labels need offline.propellers: {exc}") from exc
        from offline.sim.propeller import QuadraticPropeller

        return QuadraticPropeller.for_vehicle(vehicle)
    return build(vehicle, conditions, kind=kind, rng_seed=seed)


def run(args: argparse.Namespace) -> list[Path]:
    if args.flights < 1:
        raise ConfigError(f"--flights: must be at least 1, got {args.flights}")
    if not 1 <= args.label <= N_LABELS:
        raise ConfigError(f"--label: must be 1..{N_LABELS}, got {args.label}")
    if args.payload_kg < 0:
        raise ConfigError(f"--payload-kg: must be >= 0, got {args.payload_kg}")
    loaded = load_vehicle_with_sources(args.vehicle)
    vehicle = loaded.config
    rate = TLOG_RATE_HZ if args.format == "tlog" else SimConfig().log_rate_hz
    sim = dataclasses.replace(SimConfig(), duration_s=args.duration_s, log_rate_hz=rate)

    n = args.flights
    conditions = np.zeros((n, 4), dtype=np.int64)
    code = CONDITION_NAMES.index(args.fault)
    for p in faulty_for(args.label):
        conditions[:, p - 1] = code
    wseed = args.seed if args.waypoints_seed is None else args.waypoints_seed
    if args.waypoint_set:
        waypoints = np.broadcast_to(waypoint_set(args.waypoint_set), (n, 5, 3)).copy()
    else:
        waypoints = random_waypoints(n, 5, seed=wseed)
    payload = np.full(n, args.payload_kg)
    propellers = build_propellers(vehicle, conditions, args.propellers, args.seed)
    log = simulate(vehicle, waypoints, propellers, sim, payload_kg=payload, seed=args.seed, progress=n * sim.duration_s > 60)

    args.out.mkdir(parents=True, exist_ok=True)
    if args.format == "npz":
        files = [args.out / "flights.npz"]
    else:
        files = [args.out / f"flight_{i:03d}.tlog" for i in range(n)]
    sidecar = make_sidecar(
        vehicle,
        sim,
        waypoints,
        conditions,
        payload,
        args.seed,
        args.propellers,
        waypoints_seed=None if args.waypoint_set else wseed,
        vehicle_path=str(args.vehicle),
        vehicle_sources=loaded.sources,
        files=[f.name for f in files] if args.format == "tlog" else [f"flights.npz[{i}]" for i in range(n)],
        waypoint_set=args.waypoint_set,
        format=args.format,
    )
    if args.format == "npz":
        write_npz(files[0], log, sidecar)
    else:
        for i, f in enumerate(files):
            write_tlog(f, log, i, battery_full_v=vehicle.battery_full_v, battery_capacity_mah=vehicle.battery_capacity_mah)
    write_manifest(args.out / "sidecar.json", sidecar)
    return files + [args.out / "sidecar.json"]


def flight_summary(name: str, flight: dict, duration_s: float) -> str:
    """One line per simulated flight: file, length, which propellers are damaged and how, payload."""
    bad = flight["faulty_propellers"]
    what = (
        "healthy"
        if not bad
        else "propeller"
        + ("s " if len(bad) > 1 else " ")
        + "+".join(map(str, bad))
        + " "
        + flight["propeller_conditions"][bad[0] - 1]
    )
    return f"{name}: {duration_s:g} s, {what}, payload {flight['payload_kg']:g} kg"


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    files = run(args)
    for flight in json.loads(files[-1].read_text())["flights"]:
        print(flight_summary(str(args.out / flight["file"]), flight, args.duration_s))
    print(f"ground truth: {files[-1]}")
    return 0
