"""Does the 100 Hz response-gain fit tell a CG offset from a damaged rotor where the truth is known? Our simulator.

    nice python bench/response_gain_sim.py [--flights 4] [--seed 0]

Simulated CrazyPAD missions (``offline.crazypad.mission``) logged at 100 Hz on the calibrated-free nominal
Crazyflie (``models/crazyflie.yaml``): healthy; the CG moved 4 mm toward PX4 rotor 2 (Bitcraze M3) in x and y;
rotor 2 with 15 % less thrust and torque. Per flight, ``monitor.response_gain.fit_response_gain`` on the roll
and pitch accelerations (differentiated gyro), lag = the motor time constant. Prints the mean fitted gains
(x 1e3, each in the rotor's expected moment direction: all four positive and alike for a healthy vehicle) and
rotor 2's gain relative to the mean of the four. About 20 s.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from monitor.errors import ModelError  # noqa: E402
from monitor.response_gain import angular_acceleration, fit_response_gain  # noqa: E402
from monitor.vehicle import load_vehicle  # noqa: E402
from offline.crazypad.mission import batch_waypoints, sim_config  # noqa: E402
from offline.sim.propeller import QuadraticPropeller  # noqa: E402
from offline.sim.simulator import simulate  # noqa: E402

RATE_HZ = 100
SETTLE_S = 1.0


def conditions(vehicle):
    return {
        "healthy": (vehicle, [1.0, 1.0, 1.0, 1.0]),
        "CG 4 mm toward rotor 2": (replace(vehicle, cg_offset_frd_m=(-0.004, -0.004, 0.0)), [1.0, 1.0, 1.0, 1.0]),
        "rotor 2 -15 % thrust": (vehicle, [1.0, 0.85, 1.0, 1.0]),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=4)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    vehicle = load_vehicle(REPO / "models" / "crazyflie.yaml")
    pos = np.asarray(vehicle.rotor_positions_array_m)
    signs = {"roll": np.sign(-pos[:, 1]), "pitch": np.sign(pos[:, 0])}
    sim = sim_config(log_rate_hz=RATE_HZ)
    n = args.flights
    print(f"{n} flights per condition, lag {vehicle.motor_time_constant_s * 1e3:.0f} ms, gains x 1e3 in each rotor's direction")
    for i, (name, (v, scale)) in enumerate(conditions(vehicle).items()):
        s = np.tile(np.asarray(scale), (n, 1))
        props = QuadraticPropeller.for_vehicle(v, thrust_scale=s, torque_scale=s)
        log = simulate(v, batch_waypoints(n), props, sim, seed=args.seed * 100 + i)
        keep = np.arange(log.n_samples) >= SETTLE_S * RATE_HZ
        for k, axis in enumerate(("roll", "pitch")):
            g, rel, r2 = [], [], []
            for f in range(n):
                acc = angular_acceleration(log.rates_frd_rad_s[f, :, k], None, RATE_HZ)
                try:
                    fit = fit_response_gain(log.pwm_us[f], acc, RATE_HZ, keep, vehicle.motor_time_constant_s)
                except ModelError as exc:
                    print(f"  {name} {axis} flight {f}: {exc}")
                    continue
                g.append(signs[axis] * fit.beta * 1e3)
                rel.append(fit.relative(signs[axis])[1])
                r2.append(fit.r2)
            g = np.array(g)
            print(
                f"{name:24s} {axis:5s} gains {np.array2string(g.mean(axis=0), precision=2)}"
                f" +- {np.array2string(g.std(axis=0), precision=2)}  rotor 2 relative {np.mean(rel):+.2f}"
                f" +- {np.std(rel):.2f}  R^2 {np.mean(r2):.2f}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
