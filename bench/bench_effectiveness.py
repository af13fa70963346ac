"""Rotor effectiveness from 5 s of 20 Hz data, on both simulators: a hidden 5, 10, 20 % thrust loss.

The target: the moment-balance estimator (monitor.decision.effectiveness) recovers a hidden per-rotor thrust
loss of 5, 10 and 20 % within +-2 points from 5 s of 20 Hz data on both simulators, at <= 0.2 ms a window.
- *ours*: offline.sim with analytic propellers, each rotor in turn scaled to 0.95 / 0.90 / 0.80 of thrust
  (torque per thrust unchanged), random routes;
- *evalsim*: the evaluation-only simulator's ``effectiveness`` set (RotorPy dynamics, its own controller;
  one rotor losing exactly 5/10/20 % at hover, torque per thrust unchanged or falling 5 %), read back from
  its .tlog files as the monitor reads any log.
Every non-overlapping 5 s window after the first 5 s is one estimate: the damaged rotor's effectiveness
under the one-rotor hypothesis of that rotor, with the airframe known (nominal priors, as after
``propwatch adapt``), read as diagnose reports it (``Priors.for_measurement``: the loss left to the data);
"best set right" is the window's most probable set under the register's priors. Printed per loss: windows, median and p95 of |error| in points, share within 2 points,
and how often the window's most probable set is the truth. Cost: this thread's CPU time for window_balance +
window_posterior per window (CPU, not wall time: on a shared machine waiting for a core is not the estimator's
cost); ``--reference``: through Evidence + posterior, the information-form path a flight's many windows take
(run with PYTHONPATH at an older tree to time its code the same way).

Run: ``python -m bench.bench_effectiveness [--out out/effectiveness] [--flights 24]`` (a few minutes).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from monitor.decision.effectiveness import HYPOTHESES, Evidence, HypothesisBank, Priors, RotorGeometry, window_balance
from monitor.diagnose.physics import usable_window_starts
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.evalsim.score import read_tables
from offline.evalsim.sets import write_set

WINDOW = 100
SKIP = 100  # the first 5 s (take-off transients)


REFERENCE = False  # --reference: time the information-form path instead


def score(bank: HypothesisBank, balance, priors):
    """One window's verdict, as the daemon scores it (``window_posterior``), or through ``Evidence``."""
    if not REFERENCE:
        return bank.window_posterior(*balance)
    ev = Evidence()
    ev.add(*balance, priors)
    return bank.posterior(ev)


def window_estimates(rpm, rates, rotor: int, bank: HypothesisBank, geometry, priors, rate_hz, starts):
    """Per window: (effectiveness of ``rotor`` under its own hypothesis, most probable set, seconds)."""
    k = HYPOTHESES.index((rotor,))
    measuring = HypothesisBank(priors.for_measurement(), geometry)
    out = []
    for a in starts:
        t0 = time.thread_time()
        balance = window_balance(rpm[a : a + WINDOW], rates[a : a + WINDOW], geometry, rate_hz)
        v = score(bank, balance, priors)
        dt = time.thread_time() - t0
        eta = float(score(measuring, balance, priors).thrust_fraction[k][rotor - 1])
        out.append((eta, HYPOTHESES[v.best], dt))
    return out


def ours(vehicle, geometry, bank, priors, seed: int) -> list[tuple[float, tuple, tuple, float, float]]:
    from offline.sim.mission import random_waypoints
    from offline.sim.propeller import QuadraticPropeller
    from offline.sim.simulator import SimConfig, simulate

    losses = (0.05, 0.10, 0.20)
    cases = [(loss, r) for loss in losses for r in range(4)]
    scale = np.ones((len(cases), 4))
    for i, (loss, r) in enumerate(cases):
        scale[i, r] = 1.0 - loss
    log = simulate(
        vehicle,
        random_waypoints(len(cases), 5, seed=seed),
        QuadraticPropeller.for_vehicle(vehicle, scale, scale),
        SimConfig(duration_s=40.0),
        seed=seed,
    )
    sig = log.signals()
    rates = np.stack([sig["roll_rate_rad_s"], sig["pitch_rate_rad_s"], sig["yaw_rate_rad_s"]], axis=-1)
    rows = []
    starts = np.arange(SKIP, log.motor_rpm.shape[1] - WINDOW + 1, WINDOW)
    for i, (loss, r) in enumerate(cases):
        for eta, best, sec in window_estimates(log.motor_rpm[i], rates[i], r + 1, bank, geometry, priors, 20.0, starts):
            rows.append((loss, best, (r + 1,), eta, sec))
    return rows


def evalsim(folder: Path, flights: int, seed: int, bank, geometry, priors) -> list[tuple[float, tuple, tuple, float, float]]:
    if not (folder / "manifest.json").is_file():
        write_set("effectiveness", folder, flights=flights, seed=seed)
    rows = []
    for truth, table in read_tables(folder):
        (rotor,) = truth["faulty_propellers"]
        loss = round(1.0 - truth["thrust_factor_at_hover"][rotor - 1], 3)
        sig = table.signals()
        rates = np.stack([sig["roll_rate_rad_s"], sig["pitch_rate_rad_s"], sig["yaw_rate_rad_s"]], axis=-1)
        starts = [a for a in usable_window_starts(table, WINDOW) if a >= SKIP]
        for eta, best, sec in window_estimates(sig["motor_rpm"], rates, rotor, bank, geometry, priors, table.rate_hz, starts):
            rows.append((loss, best, (rotor,), eta, sec))
    return rows


def report(name: str, rows) -> None:
    for loss in sorted({r[0] for r in rows}):
        sel = [r for r in rows if r[0] == loss]
        err = np.abs(np.array([r[3] for r in sel]) - (1.0 - loss)) * 100
        best = np.mean([r[1] == r[2] for r in sel])
        print(
            f"{name:8s} loss {100 * loss:4.1f} %: {len(sel):3d} windows  |error| median {np.median(err):.2f} p95 "
            f"{np.percentile(err, 95):.2f} points  within 2 points {100 * np.mean(err <= 2):5.1f} %  "
            f"best set right {100 * best:5.1f} %",
            flush=True,
        )
    sec = np.array([r[4] for r in rows]) * 1e3
    print(f"{name:8s} CPU per window (balance + posterior): median {np.median(sec):.3f} ms, p95 {np.percentile(sec, 95):.3f} ms")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/effectiveness", help="folder for the evalsim set (reused when present)")
    ap.add_argument("--flights", type=int, default=24, help="evalsim flights (24 = both torque variants)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--reference", action="store_true", help="time Evidence + posterior (the path before window_posterior)")
    args = ap.parse_args(argv)
    global REFERENCE
    REFERENCE = args.reference
    vehicle = load_vehicle(DEFAULT_VEHICLE)
    geometry, priors = RotorGeometry.from_vehicle(vehicle), Priors()
    bank = HypothesisBank(priors, geometry)
    report("ours", ours(vehicle, geometry, bank, priors, args.seed + 11))
    report("evalsim", evalsim(Path(args.out), args.flights, args.seed, bank, geometry, priors))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
