"""Simulate a few PX4-like flight logs (.tlog) to try propwatch on: a small fleet, one vehicle with a bent propeller.

    python examples/simulate_flights.py OUT_DIR

Needs the ``offline`` extra (``pip install -e '.[offline]'``). Each vehicle's logs carry its own board id and one
flight a day, as a ground station records them; writes ``OUT_DIR/vehicle_V/flight_K.tlog``.
"""

from __future__ import annotations

import sys
from pathlib import Path

from offline.fleet_sim import FleetSpec, write_fleet


def run(out: str | Path, vehicles: int = 2, flights: int = 3, duration_s: float = 25.0, seed: int = 1) -> list[Path]:
    """Write the fleet; the last vehicle's propeller 3 is bent from its second flight on. Returns the log paths."""
    spec = FleetSpec(
        vehicles=vehicles,
        flights=flights,
        duration_s=duration_s,
        faulty_vehicle=vehicles - 1,
        fault_from_flight=1,
        faulty_propeller=3,
        propellers="quadratic",  # analytic propellers: no trained weights needed
        seed=seed,
    )
    paths = write_fleet(out, spec)
    for p in paths:
        print(p)
    return paths


if __name__ == "__main__":
    run(sys.argv[1] if len(sys.argv) > 1 else "out/example-flights")
