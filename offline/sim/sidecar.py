"""Ground truth beside simulated flights: a manifest (config, seed, git revision) plus, per
flight, the propeller conditions, label, payload and waypoints, and every model term."""

from __future__ import annotations

import datetime as _dt
from typing import Any

import numpy as np

from monitor.config import to_mapping
from monitor.labels import label_from_mask
from monitor.resample import US_PER_S
from monitor.vehicle import VehicleConfig
from offline.manifest import make_manifest

# Codes 0, 1, 2 are the propeller's, as offline.propellers; 3 is a motor whose output is held at its minimum.
CONDITION_NAMES = ("normal", "bent", "cracked", "stopped")


def make_sidecar(
    vehicle: VehicleConfig,
    sim,
    waypoints_ned_m: np.ndarray,
    conditions: np.ndarray,
    payload_kg: np.ndarray,
    seed: int,
    propellers: str,
    *,
    waypoints_seed: int | None = None,
    vehicle_path: str = "",
    vehicle_sources: dict[str, str] | None = None,
    files: list[str] | None = None,
    onset_s: float | None = None,
    start_utc_us: list[int] | None = None,
    **extra: Any,
) -> dict[str, Any]:
    """``onset_s``: when the damage started (s into each flight; None: at take-off); ``start_utc_us``: each
    flight's boot time on the log's UTC clock (None: the logs carry no date)."""
    conditions = np.asarray(conditions, dtype=np.int64)
    payload = np.broadcast_to(np.asarray(payload_kg, dtype=np.float64), (len(conditions),))
    flights = []
    for i, cond in enumerate(conditions):
        flights.append(
            {
                "index": i,
                "file": files[i] if files else None,
                "propeller_conditions": [CONDITION_NAMES[c] for c in cond],
                "faulty_propellers": [p + 1 for p in range(4) if cond[p] != 0],
                "label": label_from_mask(cond != 0),
                "onset_s": onset_s if np.any(cond != 0) else None,
                "payload_kg": float(payload[i]),
                "total_mass_kg": float(vehicle.mass_kg + payload[i]),
                "waypoints_ned_m": np.asarray(waypoints_ned_m[i]).tolist(),
            }
        )
        if start_utc_us is not None:
            flights[-1]["start_utc"] = _dt.datetime.fromtimestamp(start_utc_us[i] / US_PER_S, _dt.timezone.utc).isoformat()
    config = {
        "vehicle": to_mapping(vehicle),
        "vehicle_path": vehicle_path,
        "vehicle_sources": vehicle_sources or {},
        "sim": to_mapping(sim),
        "propellers": propellers,
        "waypoints_seed": waypoints_seed,
    }
    return make_manifest("propwatch-sim-flights", config, seed, flights=flights, **extra)
