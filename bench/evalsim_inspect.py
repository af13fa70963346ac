"""When ``propwatch calibrate`` names a motor_efficiency that singles out one rotor, how often does it ask for that
rotor's propeller to be inspected, and what does the one-rotor reading say?

    nice python -m bench.evalsim_inspect [--seeds 3] [--duration-s 40]

Evaluation-only simulator flights, as ``bench.evalsim_calibration`` makes them (2 healthy flights, 20 Hz, jitter
and drops, through a .tlog): a damaged propeller (8-15 % thrust lost at hover, torque per thrust -4..-10 %), one
weak motor (6 and 12 % thrust), a four-way motor spread (+-8 %), and a 12 % weak motor with the other three spread
+-2 % at random (what a real airframe's motors do). Per run: what was named, the ``inspect_rotor`` caveat and its
one-rotor reading (thrust, torque per thrust, the held-out BIC of that torque change). Prints one JSON line per run
and a summary per case.
"""

from __future__ import annotations

import argparse
import json
import time

from bench.evalsim_calibration import _af, _effects, _outside, _rng, eval_specs, eval_tables


def _weak_and_spread(sp, r):
    """12 % thrust lost on one rotor, the other three spread +-2 % (uniform)."""
    k = int(r.integers(4))
    e = 1.0 + r.uniform(-0.02, 0.02, 4)
    e[k] = 0.88
    return _af(sp, motor_thrust_efficiency=tuple(float(x) for x in e))


def main(argv: list[str] | None = None) -> int:
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
    from offline.calibrate.calibrate import calibrate_vehicle

    ap = argparse.ArgumentParser(prog="python -m bench.evalsim_inspect", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--duration-s", type=float, default=40.0)
    a = ap.parse_args(argv)
    nom = load_vehicle(DEFAULT_VEHICLE)
    eff = _effects()
    damaged = _outside()["damaged_propeller"][0]
    cases = {
        "damaged_propeller": lambda sp, r: damaged(sp, r),
        "weak_motor_6pct": lambda sp, r: eff["weak_motor"].evalsim(sp, 0.06, r),
        "weak_motor_12pct": lambda sp, r: eff["weak_motor"].evalsim(sp, 0.12, r),
        "motor_spread_8pct": lambda sp, r: eff["motor_spread"].evalsim(sp, 0.08, r),
        "weak_12pct_others_2pct": _weak_and_spread,
    }
    t0 = time.time()
    summary = {}
    for name, mod in cases.items():
        rows = []
        for seed in range(a.seeds):
            specs = [mod(sp, _rng("inspect", name, seed)) for sp in eval_specs(3000 + seed, a.duration_s)]
            r = calibrate_vehicle(eval_tables(specs), nom)
            ins = r.inspect_rotor
            row = {
                "case": name,
                "seed": seed,
                "named": [f["effect"] for f in r.findings],
                "efficiency": [round(x, 3) for x in r.calibrated.motor_efficiency],
                "inspect_rotor": None if ins is None else ins["rotor"],
                "reading": None if ins is None else ins["if_only_this_rotor"],
                # The four efficiencies' held-out BIC gain (first round), beside the one-rotor reading's (two
                # parameters): equal up to the parameter count where the two explanations fit the data alike.
                "motor_efficiency_heldout_bic_gain": round(
                    r.selection.steps[0].base_bic - r.selection.steps[0].trials["motor_efficiency"].bic, 1
                ),
                "wall_s": round(time.time() - t0),
            }
            print(json.dumps(row), flush=True)
            rows.append(row)
        readings = [x["reading"] for x in rows if x["reading"]]
        summary[name] = {
            "runs": len(rows),
            "inspect": sum(x["inspect_rotor"] is not None for x in rows),
            "torque_per_thrust_pct": [x["torque_per_thrust_pct"] for x in readings],
            "torque_heldout_bic_gain": [x["torque_heldout_bic_gain"] for x in readings],
            "thrust_pct": [x["thrust_pct"] for x in readings],
            "one_rotor_minus_four_efficiencies_bic": [
                round(x["reading"]["heldout_bic_gain"] - x["motor_efficiency_heldout_bic_gain"], 1) for x in rows if x["reading"]
            ],
        }
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
