"""``propwatch simulate``: simulated flights with ground truth, as npz or PX4-like .tlog.

    propwatch simulate --out DIR [--flights K] [--label N] [--fault bent|cracked|stopped] [--onset S]
                       [--vehicle-id K] [--first-flight K] [--payload-kg X] [--waypoints-seed S] [--seed S]
                       [--duration-s 80] [--format tlog|npz]
                       [--vehicle PATH] [--propellers lstm|quadratic] [--waypoint-set A|B]

Writes ``flight_000.tlog``... (what ``propwatch diagnose`` reads; the default) or ``flights.npz`` (all flights,
for training) plus ``sidecar.json`` (ground truth and provenance) into DIR. The flights are one vehicle's: flight
k starts k days after the first (2024-06-01), and each .tlog ends as PX4 ends a mission, landed then disarmed, so
the monitor's vehicle memory and the fleet see a flight that ended. ``--vehicle-id K`` writes the board's id
(AUTOPILOT_VERSION ``uid``) into every .tlog, as a ground station records it on connect; ``--first-flight K`` goes
on with the vehicle's flights in a later run (``flight_00K.tlog`` on, K days after the first, ground truth in
``sidecar_00K.json``). Files are written under
temporary names and renamed, and the sidecar last, so a failed run leaves no sidecar describing missing flights.

``write_flights(out, SimulateSpec(...))`` does the same from Python.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.errors import ConfigError
from monitor.labels import N_LABELS, faulty_for
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle_with_sources
from offline.fleet_sim import DAY_US, append_autopilot_version, vehicle_uid
from offline.manifest import write_manifest
from offline.sim.io_npz import write_npz
from offline.sim.io_tlog import DEFAULT_WALL_BOOT_US, write_tlog
from offline.sim.mission import random_waypoints, waypoint_set
from offline.sim.sidecar import CONDITION_NAMES, make_sidecar
from offline.sim.simulator import SimConfig, simulate

TLOG_RATE_HZ = 50  # PX4 streams ATTITUDE & co. at 50 Hz to a companion computer
FAULTS = CONDITION_NAMES[1:]  # damaged propellers (offline.propellers), or a motor held at its minimum


@dataclass(frozen=True)
class SimulateSpec:
    """What ``propwatch simulate`` flies; the defaults are the command's."""

    flights: int = 1
    label: int = 1  # monitor.labels: 1 all healthy, 2..16 the damaged propellers
    fault: str = "bent"  # bent | cracked (the propeller) | stopped (the motor's output held at its minimum)
    onset_s: float | None = None  # seconds after the start of the flight; None: damaged from take-off
    vehicle_id: int | None = None  # board id K in every .tlog: offline.fleet_sim's vehicle_K, read back as 505700000000000K
    first_flight: int = 0  # the flights are this vehicle's K, K+1, ...: named, dated and routed from K on
    payload_kg: float = 0.0
    waypoints_seed: int | None = None  # default: seed
    waypoint_set: str | None = None  # "A" | "B": the paper's named route
    seed: int = 0
    duration_s: float = 80.0
    format: str = "tlog"  # tlog | npz
    vehicle: Path = DEFAULT_VEHICLE
    propellers: str = "lstm"  # lstm | quadratic

    def check(self) -> None:
        if self.flights < 1:
            raise ConfigError(f"--flights: must be at least 1, got {self.flights}")
        if not 1 <= self.label <= N_LABELS:
            raise ConfigError(f"--label: must be 1..{N_LABELS}, got {self.label} (propwatch simulate --help lists them)")
        if self.fault not in FAULTS:
            raise ConfigError(f"--fault: one of {', '.join(FAULTS)}, got {self.fault!r}")
        if self.payload_kg < 0:
            raise ConfigError(f"--payload-kg: must be >= 0, got {self.payload_kg}")
        if self.format not in ("tlog", "npz"):
            raise ConfigError(f"--format: tlog or npz, got {self.format!r}")
        if self.onset_s is not None:
            if self.label == 1:
                raise ConfigError("--onset: label 1 damages nothing; give --label 2..16 to say which propellers")
            if not 0 < self.onset_s < self.duration_s:
                raise ConfigError(f"--onset: must be inside the flight (0 to {self.duration_s:g} s), got {self.onset_s:g}")
        if self.fault == "stopped" and self.label != 1 and self.onset_s is None:
            raise ConfigError("--fault stopped: a vehicle with a stopped motor never takes off; give --onset S (in the air)")
        if self.first_flight < 0:
            raise ConfigError(f"--first-flight: must be >= 0, got {self.first_flight}")
        if self.vehicle_id is not None and not 1 <= self.vehicle_id < 2**32:
            raise ConfigError(f"--vehicle-id: must be 1..{2**32 - 1}, got {self.vehicle_id}")


LABEL_TABLE = "labels: the damaged propellers (PX4 order: 1 front-right, 2 rear-left, 3 front-left, 4 rear-right)\n" + "\n".join(
    "  "
    + "   ".join(
        f"{n:>2} {'healthy' if not faulty_for(n) else '+'.join(map(str, faulty_for(n))):<7}" for n in range(row, N_LABELS + 1, 4)
    ).rstrip()
    for row in range(1, 5)
)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="propwatch simulate",
        description="Simulated flights of one vehicle with ground truth, as PX4-like .tlog or npz.",
        epilog=LABEL_TABLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", required=True, type=Path, help="output directory (created)")
    p.add_argument("--flights", type=int, default=1, help="number of flights, one a day (default 1)")
    p.add_argument("--label", type=int, default=1, help=f"which propellers are damaged, 1..{N_LABELS} (table below; 1 = none)")
    p.add_argument(
        "--fault", choices=FAULTS, default="bent", help="bent or cracked propellers, or stopped motors (output at minimum)"
    )
    p.add_argument(
        "--onset",
        type=float,
        default=None,
        metavar="S",
        help="the damage starts S seconds into the flight, in the air (default: damaged from take-off)",
    )
    p.add_argument("--vehicle-id", type=int, default=None, metavar="K", help="write board id K into every .tlog")
    p.add_argument(
        "--first-flight",
        type=int,
        default=0,
        metavar="K",
        help="number, date and route the flights from the vehicle's flight K on (a later run into the same folder)",
    )
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
        "--propellers", choices=("lstm", "quadratic"), default="lstm", help="propeller model: learnt (lstm, default) or quadratic"
    )
    return p.parse_args(argv)


def spec_from_args(args: argparse.Namespace) -> SimulateSpec:
    return SimulateSpec(
        flights=args.flights,
        label=args.label,
        fault=args.fault,
        onset_s=args.onset,
        vehicle_id=args.vehicle_id,
        first_flight=args.first_flight,
        payload_kg=args.payload_kg,
        waypoints_seed=args.waypoints_seed,
        waypoint_set=args.waypoint_set,
        seed=args.seed,
        duration_s=args.duration_s,
        format=args.format,
        vehicle=args.vehicle,
        propellers=args.propellers,
    )


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


def _propeller_model(vehicle, spec: SimulateSpec, conditions: np.ndarray, n: int, seed: int):
    """The propellers' model: damaged from take-off, or switched at the onset (``offline.dataset.onset``)."""
    if spec.onset_s is None or not conditions.any():
        return build_propellers(vehicle, conditions, spec.propellers, seed)
    from offline.dataset.onset import SwitchedPropellers

    before = build_propellers(vehicle, np.zeros_like(conditions), spec.propellers, seed)
    after = build_propellers(vehicle, conditions, spec.propellers, seed + 1)
    return SwitchedPropellers(before, after, np.full(n, spec.onset_s))


def write_flights(out: str | Path, spec: SimulateSpec = SimulateSpec()) -> list[Path]:
    """Simulate ``spec`` into ``out``: the flights' files, then ``sidecar.json`` (the last path returned)."""
    spec.check()
    out = Path(out)
    loaded = load_vehicle_with_sources(spec.vehicle)
    vehicle = loaded.config
    rate = TLOG_RATE_HZ if spec.format == "tlog" else SimConfig().log_rate_hz
    sim = dataclasses.replace(SimConfig(), duration_s=spec.duration_s, log_rate_hz=rate)

    n, k0 = spec.flights, spec.first_flight
    seed = spec.seed + k0  # another run's flights: their own noise
    faulty = [p - 1 for p in faulty_for(spec.label)]
    conditions = np.zeros((n, 4), dtype=np.int64)  # the propellers' (offline.propellers codes)
    truth = np.zeros((n, 4), dtype=np.int64)  # the sidecar's (offline.sim.sidecar.CONDITION_NAMES)
    truth[:, faulty] = CONDITION_NAMES.index(spec.fault)
    stop_s = None
    if spec.fault == "stopped":
        stop_s = np.full((n, 4), math.inf)
        stop_s[:, faulty] = spec.onset_s
    else:
        conditions[:, faulty] = CONDITION_NAMES.index(spec.fault)
    wseed = spec.seed if spec.waypoints_seed is None else spec.waypoints_seed
    if spec.waypoint_set:
        waypoints = np.broadcast_to(waypoint_set(spec.waypoint_set), (n, 5, 3)).copy()
    else:
        waypoints = random_waypoints(k0 + n, 5, seed=wseed)[k0:]  # flight k's route whichever run flies it
    payload = np.full(n, spec.payload_kg)
    propellers = _propeller_model(vehicle, spec, conditions, n, seed)
    log = simulate(
        vehicle,
        waypoints,
        propellers,
        sim,
        payload_kg=payload,
        seed=seed,
        progress=n * sim.duration_s > 60,
        motor_stop_s=stop_s,
    )

    out.mkdir(parents=True, exist_ok=True)
    if spec.format == "npz":
        files = [out / "flights.npz"]
    else:
        files = [out / f"flight_{k0 + i:03d}.tlog" for i in range(n)]
    sidecar_path = out / ("sidecar.json" if k0 == 0 else f"sidecar_{k0:03d}.json")
    sidecar = make_sidecar(
        vehicle,
        sim,
        waypoints,
        truth,
        payload,
        seed,
        spec.propellers,
        waypoints_seed=None if spec.waypoint_set else wseed,
        vehicle_path=str(spec.vehicle),
        vehicle_sources=loaded.sources,
        files=[f.name for f in files] if spec.format == "tlog" else [f"flights.npz[{i}]" for i in range(n)],
        onset_s=spec.onset_s if faulty else None,
        start_utc_us=[DEFAULT_WALL_BOOT_US + (k0 + i) * DAY_US for i in range(n)] if spec.format == "tlog" else None,
        vehicle_uid=None if spec.vehicle_id is None else f"{vehicle_uid(spec.vehicle_id - 1):016x}",
        waypoint_set=spec.waypoint_set,
        format=spec.format,
    )
    if spec.format == "npz":
        write_npz(files[0], log, sidecar)
    else:
        for i, f in enumerate(files):
            write_tlog(
                f,
                log,
                i,
                wall_boot_us=DEFAULT_WALL_BOOT_US + (k0 + i) * DAY_US,
                battery_full_v=vehicle.battery_full_v,
                battery_capacity_mah=vehicle.battery_capacity_mah,
                landing=True,
            )
            if spec.vehicle_id is not None:
                append_autopilot_version(f, vehicle_uid(spec.vehicle_id - 1))
    write_manifest(sidecar_path, sidecar)
    return files + [sidecar_path]


def run(args: argparse.Namespace) -> list[Path]:
    return write_flights(args.out, spec_from_args(args))


def flight_summary(name: str, flight: dict, duration_s: float) -> str:
    """One line per simulated flight: file, date, length, which propellers are damaged, how and from when, payload."""
    bad = flight["faulty_propellers"]
    what = "healthy"
    if bad:
        kind = flight["propeller_conditions"][bad[0] - 1]
        noun = "motor" if kind == "stopped" else "propeller"
        what = f"{noun}{'s' if len(bad) > 1 else ''} {'+'.join(map(str, bad))} {kind}"
        what += f" from {flight['onset_s']:g} s" if flight.get("onset_s") is not None else " from take-off"
    date = f"{flight['start_utc'][:10]}, " if flight.get("start_utc") else ""
    return f"{name}: {date}{duration_s:g} s, {what}, payload {flight['payload_kg']:g} kg"


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    files = run(args)
    sidecar = json.loads(files[-1].read_text())
    for flight in sidecar["flights"]:
        print(flight_summary(str(args.out / flight["file"]), flight, args.duration_s))
    if sidecar.get("vehicle_uid"):
        print(f"vehicle id: {sidecar['vehicle_uid']} (AUTOPILOT_VERSION uid in every .tlog)")
    print(f"ground truth: {files[-1]}")
    return 0
