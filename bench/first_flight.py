"""What a first flight's shares show on our simulator: the healthy spread and damage from take-off.

    python -m bench.first_flight --kind healthy --seed 100 --flights 96
    python -m bench.first_flight --kind single --seed 101 --flights 96

Flights of our simulator (``offline.alerts.flights.randomised_chunks``: every flight's physics drawn from the
assumption register, airframe terms included: CG offset, motor efficiency spread, arm errors, ESC offsets, inertia,
motor lag, gusty wind; payload 0-0.6 kg; the logged signals degraded by the register's telemetry delay, jitter and
drops), each read by ``monitor.diagnose.shares.share_evidence`` exactly as ``diagnose`` reads a log. ``single``:
one propeller bent or cracked from take-off (the register's damage signatures).

Prints the quantiles of ``standout`` (the highest level share minus the next) and, at the shipped
``STANDOUT_SHARE``, how many flights name a rotor: healthy flights name one falsely; damaged ones name the damaged
rotor, another one, or none (by thrust loss). ``STANDOUT_SHARE`` is the healthy 99th percentile of this command's
``--kind healthy --seed 100 --flights 96``. Never run on the evaluation-only simulator.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from monitor.diagnose.shares import STANDOUT_SHARE, share_evidence
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle


def flights(kind: str, seed: int, n: int, duration_s: float):
    """(table, truth rotors, thrust loss per truth rotor) for each flight of the set."""
    from offline.alerts.flights import FlightSet, randomised_chunks
    from offline.dataset.generate import degraded_signals

    vehicle = load_vehicle(DEFAULT_VEHICLE)
    fs = FlightSet(kind=kind, n_flights=n, duration_s=duration_s, seed=seed, physics="randomised", onset_s=(0.0, 0.0))
    for ch in randomised_chunks(vehicle, fs):
        sig = degraded_signals(ch.flog, ch.phys)
        for b in range(len(ch.names)):
            t = ch.flog.to_flight_table(b, source=ch.names[b])
            t = replace(
                t,
                motor_rpm=sig["motor_rpm"][b],
                roll_rad=sig["roll_rad"][b],
                pitch_rad=sig["pitch_rad"][b],
                yaw_rad=sig["yaw_rad"][b],
            )
            truth = tuple(int(i) + 1 for i in np.flatnonzero(ch.cond[b]))
            factor = ch.hover_thrust_factors(b, t.motor_rpm, vehicle, duration_s)
            yield t, truth, tuple(float(1.0 - factor[p - 1]) for p in truth), ch.phys[b]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--kind", choices=("healthy", "single"), default="healthy")
    p.add_argument("--seed", type=int, default=100)
    p.add_argument("--flights", type=int, default=96)
    p.add_argument("--duration-s", type=float, default=60.0)
    args = p.parse_args(argv)
    rows = []
    for t, truth, loss, phys in flights(args.kind, args.seed, args.flights, args.duration_s):
        ev = share_evidence(t)
        cg = np.asarray(phys.values.get("cg_offset_frd_m", (0.0, 0.0, 0.0)), dtype=float)
        rows.append((ev.standout, ev.named_rotor, ev.top_rotor, truth, loss, float(np.hypot(cg[0], cg[1]))))
    st = np.array([r[0] for r in rows])
    q = np.percentile(st, [50, 90, 95, 99, 100])
    print(f"{args.kind} seed {args.seed}: {len(rows)} flights of {args.duration_s:g} s")
    print("standout quantiles (share): 50 % {:.4f}, 90 % {:.4f}, 95 % {:.4f}, 99 % {:.4f}, max {:.4f}".format(*q))
    print(f"at STANDOUT_SHARE = {STANDOUT_SHARE}:")
    if args.kind == "healthy":
        named = sum(r[1] is not None for r in rows)
        print(f"  healthy flights naming a rotor: {named} of {len(rows)} ({100 * named / len(rows):.1f} %)")
        return 0
    for lo, hi in ((0.0, 0.06), (0.06, 0.10), (0.10, 0.15), (0.15, 1.0)):
        sel = [r for r in rows if r[3] and lo <= r[4][0] < hi]
        if not sel:
            continue
        right = sum(r[1] == r[3][0] for r in sel)
        wrong = sum(r[1] is not None and r[1] != r[3][0] for r in sel)
        top = sum(r[2] == r[3][0] for r in sel)
        print(
            f"  loss {100 * lo:.0f}-{100 * hi:.0f} %: {len(sel)} flights, damaged rotor named {right}, another named "
            f"{wrong}, none named {len(sel) - right - wrong}; highest share on the damaged rotor {top}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
