"""Load-cell sweeps whose damaged-blade signature is drawn from the assumption register, not fixed.

The shipped LSTMs learned one guessed signature per condition (``faults.BENT``,
``faults.CRACKED``). With ``propwatch train-propellers --signatures register``
each damaged condition is measured as ``n_sweeps`` consecutive sweeps, sweep k
with the signature of ``draw_flight(register, SeedSequence([seed, k]))`` (rotor
1's draw; ``offline/sim/assumptions.py``), so the LSTM learns the register's
spread rather than one point in it. The chronological test split then holds
the last sweeps: signatures the network never saw, which is the honest test.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from monitor.vehicle import VehicleConfig
from offline.propellers.loadcell import LoadCellConfig, run_load_cell
from offline.propellers.lstm_train import formula_of
from offline.sim.faults import FaultSignature


def register_signatures(condition: str, seed: int, n_sweeps: int, register=None) -> list[FaultSignature]:
    from offline.sim.assumptions import REGISTER, draw_flights

    phys = draw_flights(REGISTER if register is None else register, seed, range(n_sweeps))
    return [p.signature(0, condition) for p in phys]


def drawn_sweeps(
    vehicle: VehicleConfig, condition: str, cfg: LoadCellConfig, signatures: list[FaultSignature]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s (T,), y (T, 2), formula (T, 2)): the sweeps one after another, each ``cfg.duration_s / n`` long,
    in the LSTM's normalised units; ``formula`` is each sweep's own noise-free mean map."""
    parts = []
    for k, sig in enumerate(signatures):
        one = dataclasses.replace(
            cfg,
            duration_s=cfg.duration_s / len(signatures),
            seed=int(np.random.SeedSequence([cfg.seed, k]).generate_state(1)[0]),
            signatures={**cfg.signatures, condition: sig},
        )
        s, y = run_load_cell(vehicle, condition, one).normalised(vehicle)
        parts.append((s, y, formula_of(sig, s)))
    return tuple(np.concatenate([p[i] for p in parts]) for i in range(3))
