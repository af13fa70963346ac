"""The baseline's k on simulated CrazyPAD flights only: healthy false alarms and single-rotor cuts named, per rotor.

    nice python -m bench.crazypad_fusion_sim [--baselines 20] [--seed 0]

Our simulator (``offline.crazypad.simdata``, the training recipe: healthy rotors +-3 % thrust from flight to flight,
cuts of 8-40 % thrust on ANY one rotor, command noise as measured on healthy flights). Each trial draws an
airframe's baseline from 4 healthy simulated flights (as CrazyPAD's E8 has 4 calibration logs; spread floored as in
``offline.adapt.share_rule``), then scores fresh healthy flights and one-rotor cuts on each of the four rotors with the
baseline-only rule of ``offline.adapt.share_rule.fuse`` (no classifier) at several k. This is where k = 3 is checked
without any real fault flight: the simulated healthy false alarms and the named cuts per rotor at each k.
About 30 s.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from bench import REPO
from monitor.vehicle import load_vehicle  # noqa: E402
from offline.adapt.share_rule import SPREAD_FLOOR  # noqa: E402
from offline.crazypad.simdata import Recipe, simulate_dataset  # noqa: E402

KS = (2.0, 2.5, 3.0, 3.5, 4.0)
N_CAL = 4


def shares(rpm: np.ndarray) -> np.ndarray:
    """(B, 4) each flight's mean omega^2 share, as ``offline.adapt.share_rule.flight_shares`` (finite rows only)."""
    w2 = (rpm / 1000.0) ** 2
    out = []
    for f in w2:
        m = np.mean(f[np.all(np.isfinite(f), axis=1)], axis=0)
        out.append(m / m.mean())
    return np.array(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baselines", type=int, default=20, help="simulated airframes (baselines) drawn")
    ap.add_argument("--per-label", type=int, default=10, help="scored flights per label and airframe")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    vehicle = load_vehicle(REPO / "models" / "crazyflie.yaml")
    recipe = Recipe(flights_per_label=args.per_label, labels=(1, 2, 3, 4, 5), seed=args.seed)
    fa = {k: 0 for k in KS}
    named = {k: np.zeros(4, int) for k in KS}
    n_healthy, n_cut = 0, np.zeros(4, int)
    for b in range(args.baselines):
        cal = simulate_dataset(vehicle, replace(recipe, flights_per_label=N_CAL, labels=(1,)), "cal", seed_offset=2 * b)
        sc = simulate_dataset(vehicle, recipe, "scored", seed_offset=2 * b + 1)
        s_cal = shares(cal.signals["motor_rpm"])
        mean, spread = s_cal.mean(axis=0), np.maximum(s_cal.std(axis=0, ddof=1), SPREAD_FLOOR)
        dev = (shares(sc.signals["motor_rpm"]) - mean) / spread
        truth = sc.conditions.astype(bool)
        for i, d in enumerate(dev):
            rotors = np.flatnonzero(truth[i])
            if len(rotors) == 0:
                n_healthy += 1
            else:
                n_cut[rotors[0]] += 1
            for k in KS:
                top = int(np.argmax(d))
                if d[top] <= k:
                    continue
                if len(rotors) == 0:
                    fa[k] += 1
                elif top == rotors[0] and np.sum(d > k) == 1:
                    named[k][top] += 1
    print(f"{args.baselines} simulated airframes, {N_CAL} healthy flights each for the baseline, floor {SPREAD_FLOOR}")
    print(f"{'k':>4s} {'healthy flagged':>18s}   one-rotor cut named exactly, PX4 rotor 1 / 2 / 3 / 4")
    for k in KS:
        per = " / ".join(f"{named[k][r]}/{n_cut[r]}" for r in range(4))
        print(f"{k:4.1f} {fa[k]:>8d}/{n_healthy:<4d} ({100 * fa[k] / n_healthy:4.1f} %)   {per}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
