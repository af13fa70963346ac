"""propwatch dataset: generate the paper's fault data sets (A, B, C) or custom ones, one npz + manifest each.

Examples:
  propwatch dataset --sets A,B,C --fault bent --out out/data            # A-bent.npz, B-bent.npz, C-bent.npz
  propwatch dataset --name R --waypoints random --payload 0,0.6 --wind 3 --fault mixed --out out/data
  propwatch dataset --name RR --waypoints random --payload 0,0.6 --fault varied --physics randomised \
      --propellers quadratic --out out/data  # every flight's physics drawn from the simulator's assumption register
"""

from __future__ import annotations

import argparse
import contextlib
import fnmatch
import math
import sys
from pathlib import Path

from monitor.errors import ConfigError
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.dataset.generate import FAULTS, PRESETS, DatasetSpec, generate
from offline.dataset.records import save_dataset
from offline.manifest import write_manifest


def _range(text: str) -> tuple[float, float]:
    parts = [float(v) for v in text.split(",")]
    if len(parts) == 1:
        return parts[0], parts[0]
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH or one value, got {text!r}")
    return parts[0], parts[1]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="propwatch dataset", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--out", type=Path, default=Path("out/data"), help="folder for <name>-<fault>.npz and .manifest.json")
    p.add_argument(
        "--sets", default="", help="comma-separated paper presets: A (1.5 kg, route A), B (1.5 kg, route B), C (1.95 kg, route A)"
    )
    p.add_argument("--name", default="", help="a custom data set (use with --waypoints/--payload/...)")
    p.add_argument("--fault", default="bent", help=f"comma-separated, each one of {', '.join(FAULTS)}")
    p.add_argument("--waypoints", default="A", help="custom set: comma-separated routes A, B, random (cycled over flights)")
    p.add_argument("--payload", type=_range, default=(0.0, 0.0), help="custom set: extra kg, LOW,HIGH uniform per flight")
    p.add_argument("--flights-per-label", type=int, default=2, help="simulated flights for each of the 16 labels (default 2)")
    p.add_argument("--duration", type=float, default=80.0, help="seconds per flight (paper: 80)")
    p.add_argument(
        "--propellers", choices=("lstm", "quadratic"), default="lstm", help="propeller model: learnt (lstm, default) or quadratic"
    )
    p.add_argument("--wind", type=float, default=0.0, help="max steady wind, m/s (random per vehicle variant)")
    p.add_argument("--motor-efficiency-spread", type=float, default=0.0, help="+- fraction per rotor per variant")
    p.add_argument("--cg-offset", type=float, default=0.0, help="max horizontal CG offset, m, per variant")
    p.add_argument("--variants", type=int, default=1, help="vehicle variants carrying the randomised terms")
    p.add_argument(
        "--physics",
        choices=("fixed", "randomised"),
        default="fixed",
        help="randomised: draw every flight's physics and fault signatures from the assumption register "
        "(needs --propellers quadratic; replaces --wind/--motor-efficiency-spread/--cg-offset/--variants)",
    )
    p.add_argument(
        "--airframe",
        choices=("drawn", "nominal"),
        default="drawn",
        help="with --physics randomised: drawn (default) also draws the airframe's CG, motor spread, arm and ESC errors; "
        "nominal keeps them as the vehicle file says (a calibrated airframe, see propwatch adapt)",
    )
    p.add_argument("--sensor-noise", type=float, default=1.0, help="scale of the simulator's gyro/attitude noise (0 = off)")
    p.add_argument("--vehicle", type=Path, default=DEFAULT_VEHICLE, help="vehicle YAML (default models/vehicle.yaml)")
    p.add_argument("--seed", type=int, default=0, help="seed of routes, variants, noise and faults (default 0)")
    p.add_argument(
        "--chunk-flights", type=int, default=64, help="flights per simulator call and per Ray task (part of the data set)"
    )
    p.add_argument(
        "--ray",
        nargs="?",
        const="auto",
        default=None,
        metavar="ADDRESS",
        help="simulate chunks as Ray tasks: local Ray without ADDRESS, else join the cluster at HOST:PORT (same arrays as without)",
    )
    p.add_argument("--workers", type=int, default=None, help="with --ray: worker processes (local) or tasks in flight")
    p.add_argument(
        "--assumption",
        action="append",
        default=[],
        metavar="NAME=LOW,HIGH",
        help="with --physics randomised: narrow or move one register range (NAME may be a glob, e.g. "
        "'*_torque_per_thrust_change_*=-0.10,0'; the names it moves are printed, a glob can catch more than meant); "
        "a stress set for selection on our own simulator. Repeatable; the manifest records the ranges used",
    )
    return p


def register_from_args(a: argparse.Namespace):
    """The assumption register with every ``--assumption`` override applied (None: the default register)."""
    if not a.assumption:
        return None
    if a.physics != "randomised":
        raise ConfigError("--assumption: only with --physics randomised")
    from offline.sim.assumptions import REGISTER

    register = REGISTER
    for item in a.assumption:
        name, sep, rng = item.partition("=")
        if not sep:
            raise ConfigError(f"--assumption: expected NAME=LOW,HIGH, got {item!r}")
        try:
            low, high = _range(rng)
        except (argparse.ArgumentTypeError, ValueError) as exc:
            raise ConfigError(f"--assumption {item!r}: {exc}") from None
        if not (math.isfinite(low) and math.isfinite(high)) or low > high:
            raise ConfigError(f"--assumption {item!r}: need finite LOW <= HIGH")
        names = fnmatch.filter(register.names, name.strip())
        if not names:
            raise ConfigError(f"--assumption {item!r}: no register entry matches {name.strip()!r}")
        print(f"--assumption {item!r} moves {', '.join(names)}", file=sys.stderr)  # a glob can catch more than meant
        for n in names:
            register = register.with_range(n, low, high)
    return register


def specs_from_args(a: argparse.Namespace) -> list[DatasetSpec]:
    faults = [f.strip() for f in a.fault.split(",") if f.strip()]
    common = dict(
        flights_per_label=a.flights_per_label,
        duration_s=a.duration,
        propellers=a.propellers,
        wind_max_m_s=a.wind,
        motor_efficiency_spread=a.motor_efficiency_spread,
        cg_offset_max_m=a.cg_offset,
        vehicle_variants=a.variants,
        sensor_noise_scale=a.sensor_noise,
        chunk_flights=a.chunk_flights,
        physics=a.physics,
        airframe=a.airframe,
    )
    specs = []
    sets = [s.strip() for s in a.sets.split(",") if s.strip()]
    unknown = [s for s in sets if s not in PRESETS]
    if unknown:
        raise ConfigError(f"--sets: unknown preset(s) {unknown}; known: {sorted(PRESETS)}")
    if not sets and not a.name:
        raise ConfigError("give --sets (paper presets) or --name (a custom data set)")
    for i, fault in enumerate(faults):
        # Each data set has its own seed so B is not A's noise on another route.
        for j, s in enumerate(sets):
            specs.append(DatasetSpec(name=f"{s}-{fault}", fault=fault, seed=a.seed + 100 * i + j, **PRESETS[s], **common))
        if a.name:
            specs.append(
                DatasetSpec(
                    name=f"{a.name}-{fault}",
                    fault=fault,
                    seed=a.seed + 100 * i + 50,
                    waypoints=tuple(w.strip() for w in a.waypoints.split(",")),
                    payload_kg=a.payload,
                    **common,
                )
            )
    return specs


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    vehicle = load_vehicle(a.vehicle)
    if a.chunk_flights < 1:
        raise ConfigError(f"--chunk-flights: must be >= 1, got {a.chunk_flights}")
    specs = specs_from_args(a)
    register = register_from_args(a)
    run_chunks, session = None, contextlib.nullcontext()
    if a.ray:
        from fleet.raycluster import ray_session
        from offline.dataset.ray_shard import ray_chunks

        run_chunks, session = ray_chunks(a.ray, a.workers), ray_session(a.ray, a.workers)  # one Ray for every set
    with session:
        for spec in specs:
            ds = generate(spec, vehicle, run_chunks=run_chunks, register=register)
            path = save_dataset(a.out / f"{spec.name}.npz", ds)
            write_manifest(a.out / f"{spec.name}.manifest.json", ds.manifest)
            print(f"wrote {path}: {ds.n_flights} flights x {ds.n_steps} steps ({ds.n_steps / ds.sample_rate_hz:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
