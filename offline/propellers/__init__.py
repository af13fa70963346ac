"""Propeller models for the simulator: analytic fault signatures and stacked LSTMs.

``build_propellers(vehicle, conditions)`` is the one entry point the simulator
and the data-set generator use. ``conditions`` is (B, 4) int, per rotor:
0 normal, 1 bent, 2 cracked (``CONDITIONS``). The returned object implements
the simulator's ``PropellerModel`` protocol (``offline/sim/propeller.py``):
``reset(omega_rad_s (B,4))`` then ``__call__(omega_rad_s (B,4), dt_s)`` once per
physics step, returning thrust (N, along body -z) and drag torque (N·m, >= 0)
magnitudes, each (B, 4).

Kinds:
- ``"quadratic"``: kF·ω², kτ·ω² times each condition's analytic signature
  (``offline/sim/faults.py``), plus its 1P ripple and flutter; needs no weights.
- ``"lstm"``: the paper's stacked LSTMs trained on the virtual load cell
  (``models/propellers/*.npz``), stepped statefully at the load cell's 25 ms
  sample period; see ``lstm_runtime.py`` for how they meet the physics rate.

Both kinds are relative to the vehicle (speed normalised by its omega_max,
thrust and torque by kF·omega_max² and kτ·omega_max²), so the models trained
around the paper's quad also serve another vehicle such as a Crazyflie.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monitor.errors import ConfigError
from monitor.resources import shipped
from monitor.vehicle import VehicleConfig
from offline.sim.faults import CONDITIONS, SIGNATURES, FaultSignature, signature_table

MODELS_DIR = shipped("propellers")
KINDS = ("quadratic", "lstm")

__all__ = ["CONDITIONS", "KINDS", "MODELS_DIR", "SIGNATURES", "FaultSignature", "build_propellers", "check_conditions"]


def check_conditions(conditions: np.ndarray) -> np.ndarray:
    cond = np.asarray(conditions)
    if cond.ndim != 2 or cond.shape[1] != 4:
        raise ConfigError(f"conditions: expected shape (B, 4), got {cond.shape}")
    if not np.issubdtype(cond.dtype, np.integer):
        raise ConfigError(f"conditions: expected integers 0..{len(CONDITIONS) - 1}, got dtype {cond.dtype}")
    if cond.size and (cond.min() < 0 or cond.max() >= len(CONDITIONS)):
        raise ConfigError(f"conditions: codes must be in 0..{len(CONDITIONS) - 1} ({', '.join(CONDITIONS)})")
    return cond.astype(np.int64)


def build_propellers(
    vehicle: VehicleConfig,
    conditions: np.ndarray,
    kind: str = "lstm",
    models_dir: str | Path = MODELS_DIR,
    rng_seed=None,
    *,
    vibration: bool = True,
    signatures: dict[str, FaultSignature] | None = None,
    rotor_signatures: np.ndarray | None = None,
):
    """A batched ``PropellerModel`` for ``conditions`` (B, 4).

    ``rng_seed`` seeds the blade phases and flutter (None means seed 0, so runs
    are deterministic by default; a sequence of B seeds gives each flight its own
    generator, quadratic kind). ``vibration=False`` gives the mean forces
    only. ``signatures`` overrides the default fault magnitudes (quadratic kind,
    and the vibration of the LSTM kind). ``rotor_signatures``, a (B, 4) object
    array of ``FaultSignature`` (one per rotor, e.g. drawn from the assumption
    register), replaces the per-condition table; only the quadratic kind can
    apply it, since each LSTM learned one signature.
    """
    cond = check_conditions(conditions)
    if np.ndim(rng_seed) == 1:  # one seed per flight: each flight's vibration independent of the batch
        if len(rng_seed) != len(cond):
            raise ConfigError(f"rng_seed: {len(rng_seed)} per-flight seeds for {len(cond)} flights")
        rng = [np.random.default_rng([int(s), 2]) for s in rng_seed]
    else:
        rng = np.random.default_rng(0 if rng_seed is None else rng_seed)
    table = signature_table(signatures)
    if rotor_signatures is not None:
        grid = np.asarray(rotor_signatures, dtype=object)
        if grid.shape != cond.shape or not all(isinstance(x, FaultSignature) for x in grid.ravel()):
            raise ConfigError(f"rotor_signatures: expected a {cond.shape} grid of FaultSignature, got shape {grid.shape}")
        if kind != "quadratic":
            raise ConfigError(
                f"rotor_signatures: only kind 'quadratic' applies a signature per rotor ({kind!r} learned one per condition)"
            )
        table = grid
    if kind == "quadratic":
        from offline.propellers.quadratic import QuadraticFaultPropeller

        return QuadraticFaultPropeller(vehicle, cond, table, rng, vibration=vibration)
    if kind == "lstm":
        from offline.propellers.lstm_runtime import LstmPropeller

        return LstmPropeller(vehicle, cond, Path(models_dir), table, rng, vibration=vibration)
    raise ConfigError(f"kind: must be one of {', '.join(KINDS)}, got {kind!r}")
