"""Which same-spin pairs can physics see? The evaluation's pair onsets against their yaw-balance shift.

    python -m bench.bench_pair_physics --cache out/alerts-cache     # the evaluation's pair set (seed 202), ~1 min

A same-spin diagonal pair (1+2 CCW, 3+4 CW) that loses thrust keeps roll and pitch balanced, so the yaw-free
omega^2 shares do not move; what moves is the yaw balance, by g = 1 - (1 - f)(1 + c) per rotor: f the thrust
loss, c the damaged blade's change of torque per unit thrust, an unmeasured assumption our register draws from
-30 % to +30 % (offline/sim/assumptions.py). When c is close to f the pair's torque per omega^2 is unchanged:
the controller speeds all four rotors alike, exactly as for a heavier payload, and no omega^2 evidence tells the
two apart. This prints each same-spin pair of the set with its losses, its g (torque-per-omega^2 drop at the
rotor's own hover speed, averaged over the pair: the yaw balance's shift), the decision's first fault whose
alert or hypothesis set holds the pair, and the detection by |g|. Adjacent and other pairs are counted too.

The physics is our simulator's draw (the register): evalsim's pairs are not listed (its torque model is its
own, -12..-2 % per thrust, so every pair of it moves the yaw balance by more than its loss).
"""

from __future__ import annotations

import argparse

import numpy as np

from monitor.decision.config import DecisionConfig  # noqa: E402
from monitor.decision.thresholds import file_sha256
from monitor.model import Classifier  # noqa: E402
from monitor.vehicle import load_vehicle  # noqa: E402
from offline.alerts.evaluate import REPO_ROOT, cached, set_key  # noqa: E402
from offline.alerts.flights import RPM_PER_RAD_S, FlightSet, onset_draws, simulate_set  # noqa: E402
from offline.alerts.rules import decision_rule  # noqa: E402

BINS = (0.0, 0.03, 0.06, 0.1, 1.0)  # |g|: below YAW_SIGMA-scale shifts, up to the reference, beyond


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cache", default="", help="the evaluation's flight cache (offline.alerts.evaluate --cache)")
    p.add_argument("--seed", type=int, default=202, help="the pair set's seed (the evaluation's: its --seed + 2)")
    p.add_argument("--flights", type=int, default=50)
    p.add_argument("--duration-s", type=float, default=80.0, help="flight length (the evaluation's: 80 s)")
    args = p.parse_args(argv)
    model = REPO_ROOT / "models" / "classifier.onnx"
    vehicle = load_vehicle(REPO_ROOT / "models" / "vehicle.yaml")
    clf = Classifier(str(model))
    fs = FlightSet("pair", n_flights=args.flights, seed=args.seed, physics="randomised", duration_s=args.duration_s)
    flights = cached(args.cache, set_key(fs, file_sha256(model)), lambda: simulate_set(vehicle, fs, clf, log=print))
    draws = onset_draws(fs)
    run = decision_rule(DecisionConfig())
    rows = []
    for f, (truth, sigs) in zip(flights, draws):
        assert tuple(truth) == tuple(f.truth), (f.name, truth, f.truth)
        n0 = max(int(f.onset_s * f.rate_hz), 1)
        s_hover = np.median(f.motor_rpm[:n0], axis=0) / (vehicle.omega_max_rad_s * RPM_PER_RAD_S)
        g = [1.0 - float(sig.torque_factor(s_hover[p - 1])) for p, sig in zip(truth, sigs)]
        hit = None
        for t, lvl, props, sets in run(f):
            if lvl == "fault" and t >= f.onset_s and any(set(truth) <= set(s) for s in (props, *sets)):
                hit = t - f.onset_s
                break
        same_spin = set(truth) in ({1, 2}, {3, 4})
        rows.append((f.name, truth, f.thrust_loss, float(np.mean(g)), same_spin, hit, args.duration_s - f.onset_s))
    print("flight | pair | thrust loss | g (yaw shift) | fault containing the pair, s after onset | flight left, s")
    for name, truth, loss, g, ss, hit, left in rows:
        if ss:
            print(
                f"{name} | {'+'.join(map(str, truth))} | {loss} | {g:+.3f} | {'-' if hit is None else f'{hit:.1f}'} | {left:.0f}"
            )
    print("\nsame-spin pairs by |g| (the pair's torque-per-omega^2 drop): detected / flights")
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        sel = [r for r in rows if r[4] and lo <= abs(r[3]) < hi]
        print(f"  {lo:.2f} <= |g| < {hi:.2f}: {sum(r[5] is not None for r in sel)} / {len(sel)}")
    other = [r for r in rows if not r[4]]
    print(f"adjacent pairs (1+3, 1+4, 2+3, 2+4): {sum(r[5] is not None for r in other)} / {len(other)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
