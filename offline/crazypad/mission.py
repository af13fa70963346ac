"""The CrazyPAD flight script as a simulator mission.

Upstream script (github.com/AerialRoboticsUUST/CrazyPAD, src/log_to_flash/collect_data.py),
with cflib's PositionHlCommander (default_height 0.5 m, PID controller):
take off to 0.5 m, go to (2, 0) at 0.3 m/s, land, wait 5 s, take off, go back
to (0, 0), land. In the logs (``propwatch crazypad analyse``) each leg is airborne
(z > 0.25 m) for about 7.5 s and the vehicle reaches about 0.65 m/s: the high-level
commander's planner does not hold the requested 0.3 m/s.

The simulator starts every flight hovering and has no ground, so the mission
is the part the logs call airborne (z > 0.25 m): it starts hovering at 0.25 m
(the top of the take-off band), climbs to 0.5 m, flies 2 m along +x (north:
the Crazyflie's x points forward and the script never yaws), descends to
0.25 m (where a real landing leaves the airborne band), climbs again and flies
back, descends again. ``propwatch diagnose`` classifies every airborne window
of a real flight, climb and descent included, so the training flights have them too.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from offline.sim.controller import ControllerConfig
from offline.sim.simulator import SimConfig


@dataclass(frozen=True)
class CrazypadMission:
    height_m: float = 0.5  # PositionHlCommander default_height in collect_data.py
    band_m: float = 0.25  # the data set's airborne threshold: take-off and landing cross it
    travel_x_m: float = 2.0  # go_to(x=2.0, y=0.0)
    cruise_m_s: float = 0.5  # the script asks 0.3 m/s; real peaks are ~0.65 m/s, mean over a leg ~0.4 m/s
    duration_s: float = 18.0  # two legs of ~7.5 s airborne each, back to back, plus the slower approaches

    def waypoints_ned_m(self) -> np.ndarray:
        """(6, 3): climb, out to x = 2 m, descend; climb, back, descend (the simulator repeats the route)."""
        z, b, x = -self.height_m, -self.band_m, self.travel_x_m
        return np.array([[0.0, 0.0, z], [x, 0.0, z], [x, 0.0, b], [x, 0.0, z], [0.0, 0.0, z], [0.0, 0.0, b]])

    def start_ned_m(self) -> tuple[float, float, float]:
        return (0.0, 0.0, -self.band_m)


CRAZYPAD = CrazypadMission()


def crazyflie_controller(cruise_m_s: float = CRAZYPAD.cruise_m_s) -> ControllerConfig:
    """PX4-like gains for a 31 g quad flying slow indoor legs.

    The cascade is PX4's (normalised-torque rate loop, so the gains carry over
    across sizes); only the mission limits change: the Crazyflie script flies
    at walking pace, so cruise speed and horizontal acceleration are the
    high-level commander's, and waypoints count as reached within 10 cm.
    """
    return replace(
        ControllerConfig(),
        mpc_xy_cruise_m_s=cruise_m_s,
        mpc_acc_hor_m_s2=1.0,
        mpc_z_vel_max_up_m_s=0.3,
        mpc_z_vel_max_dn_m_s=0.3,
        nav_acc_rad_m=0.05,
        mpc_yaw_mode_heading_min_m=1e3,
    )


def sim_config(mission: CrazypadMission = CRAZYPAD, **overrides) -> SimConfig:
    """Rates for a Crazyflie: its rate loop runs at 500 Hz (firmware stabilizer), physics at 1 kHz."""
    cfg = SimConfig(
        physics_rate_hz=1000,
        control_rate_hz=500,
        position_rate_hz=100,
        log_rate_hz=20,
        duration_s=mission.duration_s,
        start_ned_m=mission.start_ned_m(),
        controller=crazyflie_controller(mission.cruise_m_s),
    )
    return replace(cfg, **overrides) if overrides else cfg


def batch_waypoints(n: int, mission: CrazypadMission = CRAZYPAD) -> np.ndarray:
    """(n, 6, 3) the same route for n flights."""
    w = mission.waypoints_ned_m()
    return np.broadcast_to(w, (n,) + w.shape).copy()
