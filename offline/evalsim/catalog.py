"""Every evaluation set by name: the paper quad's (``offline.evalsim.sets``) and other airframes' (``strangers``).

NEVER used for training or model selection (see the package docstring).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path

from monitor.vehicle import DEFAULT_VEHICLE
from offline.evalsim import sets, strangers
from offline.evalsim.flight import FlightSpec
from offline.evalsim.names import DEFAULT_DURATION_S, STRANGER_SETS


def build_set(
    name: str, flights: int | None = None, seed: int = 0, duration_s: float = DEFAULT_DURATION_S, vehicle_path=DEFAULT_VEHICLE
) -> list[FlightSpec]:
    """The flight specs of set ``name``, whichever module draws it."""
    if name in STRANGER_SETS:
        return sets.build_specs(strangers.BUILDERS[name], flights, seed, duration_s, vehicle_path)
    return sets.build_set(name, flights, seed, duration_s, vehicle_path)


def write_set(
    name: str,
    out_dir: str | Path,
    flights: int | None = None,
    seed: int = 0,
    duration_s: float = DEFAULT_DURATION_S,
    progress: Callable[[int], None] | None = None,
) -> Path:
    """Simulate set ``name`` into ``out_dir`` (``sets.write_set``); a ``strangers_*`` flight ends in landing and
    disarm, with a date, its airframe's uid and its size in the truth (``strangers.write_flight``)."""
    if name in STRANGER_SETS:
        specs = build_set(name, flights, seed, duration_s)
        writer = partial(strangers.write_flight, name, seed)
        return sets.write_set(name, out_dir, flights, seed, duration_s, progress, specs=specs, writer=writer)
    return sets.write_set(name, out_dir, flights, seed, duration_s, progress)
