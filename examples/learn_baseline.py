"""Learn one vehicle's healthy normal from its own flights, then judge a new flight against it.

    python examples/learn_baseline.py OUT.json HEALTHY_LOG... [--judge LOG]

What ``propwatch baseline learn`` writes and ``propwatch diagnose --baseline`` reads: each rotor's share of the
thrust on healthy flights (at least three), the vehicle's id taken from the logs themselves.
"""

from __future__ import annotations

import sys
from pathlib import Path

from monitor.memory.baseline import VehicleBaseline
from monitor.memory.judge import judge as judge_flight
from monitor.memory.learn import learn_from_logs, read_flight
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle


def run(out: str | Path, healthy_logs: list[str], vehicle_yaml: str | None = None) -> VehicleBaseline:
    """Read the healthy logs, learn their baseline (refusing one that looks unlike the rest), save it to ``out``."""
    esc = load_vehicle(vehicle_yaml or DEFAULT_VEHICLE).esc  # motor commands to RPM
    flights = [read_flight(log, None, esc) for log in healthy_logs]
    baseline = learn_from_logs(flights)
    baseline.save(out)
    print(f"{out}: vehicle {baseline.vehicle_id}, {len(flights)} healthy flights")
    return baseline


def judge(baseline_json: str | Path, log: str, vehicle_yaml: str | None = None) -> dict:
    """One more flight of the same vehicle against the saved baseline: each rotor's share against its normal."""
    baseline = VehicleBaseline.load(baseline_json)
    flight = read_flight(log, None, load_vehicle(vehicle_yaml or DEFAULT_VEHICLE).esc)
    baseline.check_vehicle(flight.vehicle_id, flight.table.motor_names, flight.summary.basis, log)  # same vehicle?
    verdict = judge_flight(baseline.normal(), flight.summary)
    spread = ", ".join(f"{i + 1}: {x:+.1f}" for i, x in enumerate(verdict["deviation_sigma"]))
    print(f"{log}: each rotor's share against its normal (spreads) {spread}; faulty: {verdict['faulty_propellers']}")
    return verdict


if __name__ == "__main__":
    args = sys.argv[1:]
    extra = args[args.index("--judge") + 1] if "--judge" in args else None
    logs = [a for a in args[1:] if a not in ("--judge", extra)]
    run(args[0], logs)
    if extra:
        judge(args[0], extra)
