"""Real CrazyPAD flights through the project's reader, cut to the phases the simulation flies.

The reader (``monitor.logs.read_log``, formats ``crazypad`` and
``crazypad-controller``) gives the 20 Hz ``FlightTable`` with rotors in PX4
order and the airborne mask (z > 0.25 m, motors on). Take-off and landing are
not simulated (the simulator starts in hover and has no ground), so each
airborne stretch loses its first ``TRIM_START_S`` (still climbing to 0.5 m) and
its last ``TRIM_END_S`` (already descending): what remains is hover and the
2 m translation, as in ``offline.crazypad.mission``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.flight import FlightTable
from monitor.logs import read_log
from monitor.vehicle import VehicleConfig
from offline.crazypad.data import DEFAULT_ROOT, CrazypadFlight, load_manifest, select
from offline.crazypad.vehicle import bitcraze_order

TRIM_START_S = 1.5
TRIM_END_S = 1.0


def log_format(flight: CrazypadFlight) -> str:
    return "crazypad" if flight.has_motor_commands else "crazypad-controller"


def read_flight(flight: CrazypadFlight, vehicle: VehicleConfig, root: str | Path = DEFAULT_ROOT) -> FlightTable:
    return read_log(Path(root) / flight.file, fmt=log_format(flight), esc=vehicle.esc, rate_hz=20.0)


def read_motor_flights(
    vehicle: VehicleConfig, root: str | Path = DEFAULT_ROOT
) -> tuple[list[CrazypadFlight], dict[str, FlightTable]]:
    """Every motor log of the manifest (``select``) and its flight table, by file: what the CrazyPAD benches read."""
    flights = select(load_manifest(root))
    return flights, {f.file: read_flight(f, vehicle, root) for f in flights}


def core_mask(table: FlightTable, trim_start_s: float = TRIM_START_S, trim_end_s: float = TRIM_END_S) -> np.ndarray:
    """(T,) airborne minus the take-off climb and the landing descent of every stretch."""
    a0, a1 = int(round(trim_start_s * table.rate_hz)), int(round(trim_end_s * table.rate_hz))
    mask = np.zeros(len(table), dtype=bool)
    for a, b in table.airborne_segments():
        if b - a1 > a + a0:
            mask[a + a0 : b - a1] = True
    return mask


def command_shares(motor_cmd: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """(..., 4) each motor's mean command over the mean of all four (project order), over ``mask``."""
    cmd = np.asarray(motor_cmd, dtype=np.float64)
    if mask is not None:
        cmd = cmd[..., mask, :]
    m = np.nanmean(cmd, axis=-2)
    return m / np.mean(m, axis=-1, keepdims=True)


@dataclass(frozen=True)
class FlightSummary:
    flight: CrazypadFlight
    n_core: int  # 20 Hz samples in the core phases
    motor_cmd_mean: tuple[float, float, float, float]  # per motor over the core, PX4 rotor order
    roll_mean_rad: float

    @property
    def mean_cmd(self) -> float:
        return float(np.mean(self.motor_cmd_mean))

    @property
    def shares_bitcraze(self) -> tuple[float, ...]:
        """M1..M4 mean command over the mean of all four."""
        m = np.asarray(self.motor_cmd_mean)
        return tuple(map(float, bitcraze_order(m / m.mean())))

    def to_dict(self) -> dict:
        f = self.flight
        return {
            "file": f.file,
            "airframe": f.airframe,
            "group": f.group,
            "role": f.role,
            "n_core": self.n_core,
            "mean_cmd": round(self.mean_cmd, 1),
            "shares_M1_M4": [round(s, 4) for s in self.shares_bitcraze],
            "roll_mean_deg": round(float(np.degrees(self.roll_mean_rad)), 3),
        }


def summarise(flight: CrazypadFlight, vehicle: VehicleConfig, root: str | Path = DEFAULT_ROOT) -> FlightSummary:
    tab = read_flight(flight, vehicle, root)
    m = core_mask(tab)
    return FlightSummary(
        flight, int(m.sum()), tuple(map(float, np.nanmean(tab.motor_cmd[m], axis=0))), float(np.nanmean(tab.roll_rad[m]))
    )
