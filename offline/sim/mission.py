"""Missions as in the paper (Tong et al. Sec. V-B): N random waypoints in a box, flown in order
for the whole flight (80 s), repeating the route when it finishes early.

Flights start hovering at ``START_NED_M`` (10 m above the origin). The
paper's waypoint sets A (training, and test set C with payload) and B (test
set with other waypoints) are not published; ``waypoint_set`` makes two
fixed, different sets from fixed seeds so every data set names the same
route.
"""

from __future__ import annotations

import numpy as np

from monitor.errors import ConfigError

START_NED_M = np.array([0.0, 0.0, -10.0])
# Box for random waypoints (NED, m): +-15 m around the start, 4..16 m altitude.
DEFAULT_BOX_NED_M = ((-15.0, 15.0), (-15.0, 15.0), (-16.0, -4.0))
_NAMED_SEEDS = {"A": 20240601, "B": 20240602}


def random_waypoints(n_flights: int, n_waypoints: int = 5, seed: int = 0, box_ned_m=DEFAULT_BOX_NED_M) -> np.ndarray:
    """(n_flights, n_waypoints, 3) uniform in ``box_ned_m`` ((lo, hi) per NED axis).

    Flight i's waypoints depend only on (seed, i), so asking for more flights
    extends the set without changing the first ones.
    """
    box = np.asarray(box_ned_m, dtype=np.float64)
    if box.shape != (3, 2) or np.any(box[:, 1] < box[:, 0]):
        raise ConfigError(f"box_ned_m: must be three (lo, hi) pairs, got {box_ned_m!r}")
    out = np.empty((n_flights, n_waypoints, 3))
    for i in range(n_flights):
        rng = np.random.default_rng([seed, i])
        out[i] = box[:, 0] + rng.random((n_waypoints, 3)) * (box[:, 1] - box[:, 0])
    return out


def waypoint_set(name: str, n_waypoints: int = 5) -> np.ndarray:
    """The fixed route named ``name`` ("A" or "B"), shape (n_waypoints, 3)."""
    if name not in _NAMED_SEEDS:
        raise ConfigError(f"waypoint set: unknown {name!r}; known: {sorted(_NAMED_SEEDS)}")
    return random_waypoints(1, n_waypoints, seed=_NAMED_SEEDS[name])[0]
