"""A small simulated fleet of PX4-like .tlogs, for the fleet tools' tests, benchmark and demo.

Each vehicle carries its own AUTOPILOT_VERSION ``uid`` (as a ground station
records it on connect) and its flights are a day apart on the tlog's clock, so
``propwatch fleet ingest`` finds the vehicle and the date in the logs
themselves. One vehicle can bend a propeller from a given flight on.
"""

from __future__ import annotations

import dataclasses
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.sim.io_tlog import DEFAULT_WALL_BOOT_US, write_tlog
from offline.sim.mission import random_waypoints
from offline.sim.simulator import SimConfig, simulate

DAY_US = 86_400 * 1_000_000
UID_BASE = 0x5057_0000_0000_0000  # "PW": simulated boards
TLOG_RATE_HZ = 50


@dataclass(frozen=True)
class FleetSpec:
    vehicles: int = 3
    flights: int = 4  # per vehicle, one a day
    duration_s: float = 20.0
    faulty_vehicle: int | None = None  # 0-based; None: all healthy
    fault_from_flight: int = 2  # 0-based flight index from which its propeller is damaged
    faulty_propeller: int = 3  # PX4 rotor number 1..4
    fault: str = "bent"
    propellers: str = "lstm"
    seed: int = 0
    first_vehicle: int = 0  # numbering (folder and uid) starts here, to write several batches into one fleet


def vehicle_uid(v: int) -> int:
    return UID_BASE + v + 1


def append_autopilot_version(path: Path, uid: int) -> None:
    """Append an AUTOPILOT_VERSION record (system 1, autopilot component) carrying ``uid`` to a .tlog."""
    with open(path, "rb") as fh:
        first_ts = int.from_bytes(fh.read(8), "big")  # the record's receive time: the recording's start
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=mavlink2.MAV_COMP_ID_AUTOPILOT1)
    msg = mav.autopilot_version_encode(0, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, uid)
    with open(path, "ab") as fh:
        fh.write(struct.pack(">Q", first_ts))
        fh.write(msg.pack(mav))


def write_fleet(out: str | Path, spec: FleetSpec | None = None) -> list[Path]:
    """Simulate ``spec`` and write ``out/vehicle_V/flight_K.tlog``; returns the paths, vehicle-major."""
    from offline.propellers import build_propellers

    spec = spec or FleetSpec()
    out = Path(out)
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    n = spec.vehicles * spec.flights
    conditions = np.zeros((n, 4), dtype=np.int64)
    if spec.faulty_vehicle is not None:
        code = 1 if spec.fault == "bent" else 2
        for k in range(spec.fault_from_flight, spec.flights):
            conditions[spec.faulty_vehicle * spec.flights + k, spec.faulty_propeller - 1] = code
    sim = dataclasses.replace(SimConfig(), duration_s=spec.duration_s, log_rate_hz=TLOG_RATE_HZ)
    props = build_propellers(vehicle, conditions, kind=spec.propellers, rng_seed=spec.seed)
    log = simulate(vehicle, random_waypoints(n, 5, seed=spec.seed), props, sim, seed=spec.seed)
    paths = []
    for v in range(spec.vehicles):
        folder = out / f"vehicle_{spec.first_vehicle + v + 1}"
        folder.mkdir(parents=True, exist_ok=True)
        for k in range(spec.flights):
            i = v * spec.flights + k
            path = folder / f"flight_{k + 1:02d}.tlog"
            wall = DEFAULT_WALL_BOOT_US + k * DAY_US + v * 3_600_000_000
            write_tlog(path, log, i, wall_boot_us=wall, battery_full_v=vehicle.battery_full_v)
            append_autopilot_version(path, vehicle_uid(spec.first_vehicle + v))
            paths.append(path)
    return paths
