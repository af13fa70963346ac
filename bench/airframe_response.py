"""Can a flight's response to differential thrust tell the trained airframe from another? Our simulator says no.

    python -m bench.airframe_response --seed 100 --flights 48

Healthy and single-propeller flights of our simulator with register physics (``bench.first_flight.flights``: inertia
+-10 %, arm errors, CG, motor lag, telemetry delay, jitter and drops applied to the logged signals), each read by
``response_ratio`` below. Prints the quantiles. On the defaults the model's own airframe spans x0.04-0.60 of its
file's response (1st-99th percentile): a 20-Hz log in closed loop does not identify the response well enough to
tell an airframe with other arms or inertia (x0.5-2) from it, so ``diagnose`` does not use it.
Never run on the evaluation-only simulator.

What is fitted: the pitch and roll angular acceleration per unit of differential thrust share. On a quad-X whose
  rotors give equal thrust ``m g / 4`` at hover, shifting a share ``u`` along the pitch direction
  ``(-1, 1, -1, 1) / 2`` (PX4 order) gives a pitch moment ``-m g a_x u / 2`` (``a_x`` the rotors' distance
  ahead of the CG), so the pitch acceleration is ``-G u`` with ``G = m g a_x / (2 I_yy)`` (roll alike with ``a_y``
  and ``I_xx``, sign +). ``response_ratio`` is the fitted ``G`` over the model's airframe's (its vehicle file): an
  airframe with other arms or another mass-to-inertia ratio answers differently even where it hovers at the same
  RPM. The fit is a least-squares line of the differentiated gyro on the shares one grid step earlier (motor lag
  and the logging delay), over airborne steps.
"""

from __future__ import annotations

import argparse

import numpy as np

from bench.first_flight import flights
from monitor.flight import FlightTable
from monitor.memory.summary import rotor_values
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

GRAVITY_M_S2 = 9.80665
_PITCH = np.array([-0.5, 0.5, -0.5, 0.5])
_ROLL = np.array([-0.5, 0.5, 0.5, -0.5])
MIN_RESPONSE_STEPS = 200  # airborne steps with every value measured before the fit is trusted (10 s at 20 Hz)


def expected_gain(vehicle) -> tuple[float, float]:
    """(G_roll, G_pitch) in rad/s^2 per unit share for the vehicle file's airframe."""
    pos = np.asarray(vehicle.rotor_positions_frd_m, dtype=np.float64)
    a_x, a_y = float(np.mean(np.abs(pos[:, 0]))), float(np.mean(np.abs(pos[:, 1])))
    ixx, iyy, _ = vehicle.inertia_diag_kg_m2
    w = vehicle.mass_kg * GRAVITY_M_S2
    return w * a_y / (2.0 * ixx), w * a_x / (2.0 * iyy)


def fitted_gain(table: FlightTable) -> tuple[float, float] | None:
    """(G_roll, G_pitch) fitted on this flight, None where the log lacks body rates or outputs for it."""
    x, _ = rotor_values(table)
    x = np.asarray(x, dtype=np.float64)
    rates = np.stack([table.roll_rate_rad_s, table.pitch_rate_rad_s], axis=1).astype(np.float64)
    air = np.asarray(table.airborne, dtype=bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = x / x.mean(axis=1, keepdims=True)
    u = np.stack([s @ _ROLL, s @ _PITCH], axis=1)
    acc = np.gradient(rates, axis=0) * table.rate_hz
    u_prev = np.vstack([np.full((1, 2), np.nan), u[:-1]])
    ok = air & np.concatenate([[False], air[:-1]]) & np.isfinite(u_prev).all(axis=1) & np.isfinite(acc).all(axis=1)
    if ok.sum() < MIN_RESPONSE_STEPS:
        return None
    out = []
    for axis, sign in ((0, 1.0), (1, -1.0)):
        a, b = u_prev[ok, axis], acc[ok, axis]
        a = a - a.mean()
        den = float(a @ a)
        if not den > 0:
            return None
        out.append(sign * float(a @ (b - b.mean())) / den)
    return out[0], out[1]


def response_ratio(table: FlightTable, vehicle) -> float | None:
    """The fitted response over the vehicle file's, the geometric mean of roll and pitch; None where unknown."""
    fit = fitted_gain(table)
    if fit is None or min(fit) <= 0:
        return None if fit is None else 0.0
    g = expected_gain(vehicle)
    return float(np.sqrt((fit[0] / g[0]) * (fit[1] / g[1])))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seed", type=int, default=100)
    p.add_argument("--flights", type=int, default=48)
    p.add_argument("--duration-s", type=float, default=60.0)
    args = p.parse_args(argv)
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    r = []
    for kind in ("healthy", "single"):
        for t, *_ in flights(kind, args.seed, args.flights, args.duration_s):
            x = response_ratio(t, vehicle)
            if x is not None:
                r.append(x)
    q = np.percentile(r, [1, 5, 50, 95, 99])
    print(f"response ratio on {len(r)} flights of the model's airframe (seed {args.seed}):")
    print("  1 % {:.3f}, 5 % {:.3f}, 50 % {:.3f}, 95 % {:.3f}, 99 % {:.3f}".format(*q))
    print(f"  band (1st-99th percentile widened by a tenth): {q[0] / 1.1:.3f}-{q[4] * 1.1:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
