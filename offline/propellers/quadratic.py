"""Analytic propellers for the simulator: kF·ω², kτ·ω² times each rotor's fault signature.

Works without trained weights; a bent or cracked rotor already differs from a
normal one through ``offline.sim.faults``. Implements the simulator's
``PropellerModel`` protocol: ``reset(omega_rad_s (B,4))`` and
``__call__(omega_rad_s (B,4), dt_s) -> (thrust_n, torque_nm)``, magnitudes
(thrust along body -z, drag torque >= 0; the simulator applies the spin sign).
"""

from __future__ import annotations

import numpy as np

from monitor.vehicle import VehicleConfig
from offline.propellers.vibration import FaultVibration, per_rotor


def _per_rotor(signatures, conditions: np.ndarray, attr: str) -> np.ndarray:
    """(B, 4) values of ``attr``: from a table indexed by condition code, or from a (B, 4) grid of
    signatures (one per rotor, e.g. drawn from the assumption register)."""
    return per_rotor(signatures, conditions, attr)


class QuadraticFaultPropeller:
    def __init__(
        self,
        vehicle: VehicleConfig,
        conditions: np.ndarray,
        signatures,  # tuple indexed by condition code, or a (B, 4) grid of FaultSignature
        rng: np.random.Generator,
        vibration: bool = True,
    ):
        cond = np.asarray(conditions, dtype=np.int64)
        self.conditions = cond
        self.kf = vehicle.kf_n_per_rad_s2
        self.ktau = vehicle.ktau_nm_per_rad_s2
        self.omega_max_rad_s = vehicle.omega_max_rad_s
        # thrust = ω²·(a + b·ω²): the signatures' s² terms folded into per-rotor coefficients once.
        t_lo = _per_rotor(signatures, cond, "thrust_loss_low")
        q_lo = _per_rotor(signatures, cond, "torque_gain_low")
        inv_w2 = 1.0 / self.omega_max_rad_s**2
        self._t_a = self.kf * (1.0 - t_lo)
        self._t_b = -self.kf * (_per_rotor(signatures, cond, "thrust_loss_high") - t_lo) * inv_w2
        self._q_a = self.ktau * (1.0 + q_lo)
        self._q_b = self.ktau * (_per_rotor(signatures, cond, "torque_gain_high") - q_lo) * inv_w2
        vib = FaultVibration(cond, signatures, vehicle.omega_max_rad_s, rng)
        self._vibration = vib if (vibration and vib.active) else None

    def mean(self, omega_rad_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Steady thrust and torque without vibration (what a load cell averages to)."""
        w2 = np.square(omega_rad_s)
        return w2 * (self._t_a + self._t_b * w2), w2 * (self._q_a + self._q_b * w2)

    def reset(self, omega_rad_s: np.ndarray) -> None:
        if self._vibration is not None:
            self._vibration.reset()

    def __call__(self, omega_rad_s: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        omega = np.maximum(np.asarray(omega_rad_s, dtype=np.float64), 0.0)
        thrust, torque = self.mean(omega)
        if self._vibration is not None:
            ft, fq = self._vibration.step(omega, dt_s)
            thrust, torque = thrust * ft, torque * fq
        return np.maximum(thrust, 0.0), np.maximum(torque, 0.0)
