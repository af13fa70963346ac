"""Does the 100 Hz response-gain fit tell a CG offset from a damaged rotor where the truth is known? Our simulator.

    nice python -m bench.response_gain_sim [--flights 4] [--seed 0] [--sim ours|evalsim]

Simulated CrazyPAD missions (``offline.crazypad.mission``) logged at 100 Hz on the calibrated-free nominal
Crazyflie (``models/crazyflie.yaml``): healthy; the CG moved 4 mm toward PX4 rotor 2 (Bitcraze M3) in x and y;
rotor 2 with 15 % less thrust and torque. Per flight, ``offline.response_gain.fit_response_gain`` on the roll
and pitch accelerations (differentiated gyro), lag = the motor time constant. Prints the mean fitted gains
(x 1e3, each in the rotor's expected moment direction: all four positive and alike for a healthy vehicle) and
rotor 2's gain relative to the mean of the four. About 20 s.

``--sim evalsim``: the evaluation-only RotorPy-based simulator (``offline/evalsim``; its 1.5 kg paper quad, arms
0.16 m, own PX4-like cascade at 250 Hz), logged at 125 Hz without jitter or drops, 40 s flights, with and without
1 m/s gusts; the CG moved 10 % of the arm toward rotor 2, rotor 2 with 15 % thrust loss at hover. About 5 min.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from bench import REPO
from monitor.errors import ModelError  # noqa: E402
from monitor.vehicle import load_vehicle  # noqa: E402
from offline.crazypad.mission import batch_waypoints, sim_config  # noqa: E402
from offline.response_gain import angular_acceleration, fit_response_gain  # noqa: E402
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


def report(name: str, axis: str, fits: list, signs: np.ndarray) -> None:
    g = np.array([signs * f.beta * 1e3 for f in fits])
    rel = [f.relative(signs)[1] for f in fits]
    print(
        f"{name:28s} {axis:5s} gains {np.array2string(g.mean(axis=0), precision=2)}"
        f" +- {np.array2string(g.std(axis=0), precision=2)}  rotor 2 relative {np.mean(rel):+.2f}"
        f" +- {np.std(rel):.2f}  R^2 {np.mean([f.r2 for f in fits]):.2f}"
    )


def evalsim(args) -> int:
    from offline.evalsim.environment import Telemetry, Wind
    from offline.evalsim.flight import simulate_flights
    from offline.evalsim.sets import build_set

    rate_hz, lag_s = 125.0, 0.03  # 250 Hz physics / 2; the airframe's motor time constant
    base = next(s for s in build_set("paper", flights=16, seed=args.seed, duration_s=40) if s.label == 1)
    af = base.airframe
    pos = np.asarray(af.rotor_positions_frd_m)
    signs = {"roll": np.sign(-pos[:, 1]), "pitch": np.sign(pos[:, 0])}
    off = 0.1 * float(np.abs(pos[0, 0]))
    loss = list(af.damage.thrust_loss_at_hover)
    loss[1] = 0.15
    conds = {
        "healthy": af,
        "CG 10 % of arm toward rotor 2": replace(af, cg_offset_frd_m=(-off, -off, 0.0)),
        "rotor 2 -15 % thrust": replace(af, damage=replace(af.damage, thrust_loss_at_hover=tuple(loss))),
    }
    tel = Telemetry(rate_hz=rate_hz, jitter_std_s=0.0, drop_probability=0.0)
    print(f"evalsim, {args.flights} flights per condition, {rate_hz:g} Hz, lag {lag_s * 1e3:.0f} ms, gains x 1e3")
    for gust in (0.0, 1.0):
        for name, a in conds.items():
            specs = [
                replace(
                    base,
                    name=f"{name}-{i}",
                    airframe=a,
                    seed=100 + i,
                    telemetry=tel,
                    wind=Wind(gust_std_m_s=(gust, gust, gust / 2)),
                )
                for i in range(args.flights)
            ]
            logs = simulate_flights(specs)
            for k, axis in enumerate(("roll", "pitch")):
                fits = []
                for lg in logs:
                    acc = angular_acceleration(lg.rates_frd_rad_s[0, :, k], None, rate_hz)
                    keep = np.arange(len(acc)) > 2 * rate_hz
                    fits.append(fit_response_gain(lg.pwm_us[0], acc, rate_hz, keep, lag_s))
                report(f"gust {gust:g} m/s, {name}", axis, fits, signs[axis])
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=4)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sim", choices=("ours", "evalsim"), default="ours")
    args = ap.parse_args(argv)
    if args.sim == "evalsim":
        return evalsim(args)
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
            fits = []
            for f in range(n):
                acc = angular_acceleration(log.rates_frd_rad_s[f, :, k], None, RATE_HZ)
                try:
                    fits.append(fit_response_gain(log.pwm_us[f], acc, RATE_HZ, keep, vehicle.motor_time_constant_s))
                except ModelError as exc:
                    print(f"  {name} {axis} flight {f}: {exc}")
            report(name, axis, fits, signs[axis])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
