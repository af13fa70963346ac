"""Batched fault vibration: once-per-revolution ripple and flutter, as multiplicative factors.

Shared by the analytic and the learned propellers, because the LSTM predicts
the *mean* thrust and torque (it is trained with MSE on noisy load-cell
samples); the zero-mean vibration of a damaged blade is added on top from the
same ``FaultSignature`` that the virtual load cell measured.
"""

from __future__ import annotations

import numpy as np

from offline.propellers.faults import FaultSignature


class FaultVibration:
    """State per rotor: blade angle (for the 1P ripple) and an Ornstein-Uhlenbeck flutter state."""

    def __init__(self, conditions: np.ndarray, signatures: tuple[FaultSignature, ...], omega_max_rad_s: float,
                 rng: np.random.Generator):
        cond = np.asarray(conditions)
        self._rng = rng
        self._omega_max = float(omega_max_rad_s)

        def per_rotor(attr: str) -> np.ndarray:
            return np.array([getattr(s, attr) for s in signatures])[cond]

        self._ripple = np.stack([per_rotor("ripple_1p_thrust"), per_rotor("ripple_1p_torque")], axis=-1)
        self._flutter_std = np.stack([per_rotor("flutter_thrust_std"), per_rotor("flutter_torque_std")], axis=-1)
        self._flutter_tau = per_rotor("flutter_time_constant_s")[..., None]
        self.active = bool(np.any(self._ripple > 0) or np.any(self._flutter_std > 0))
        self._angle = np.zeros(cond.shape)
        self._flutter = np.zeros(cond.shape + (2,))

    def reset(self) -> None:
        # Random blade phase per rotor: rotors are not synchronised in flight.
        self._angle = self._rng.uniform(0.0, 2.0 * np.pi, self._angle.shape)
        self._flutter[:] = 0.0

    def step(self, omega_rad_s: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Advance by dt; returns (thrust_factor, torque_factor), each (B,4), mean 1."""
        self._angle = np.mod(self._angle + omega_rad_s * dt_s, 2.0 * np.pi)
        ripple = self._ripple * np.sin(self._angle)[..., None]
        a = np.exp(-dt_s / self._flutter_tau)
        self._flutter = a * self._flutter + np.sqrt(1.0 - a * a) * self._rng.standard_normal(self._flutter.shape)
        s2 = np.square(omega_rad_s / self._omega_max)[..., None]
        f = 1.0 + ripple + self._flutter_std * s2 * self._flutter
        return f[..., 0], f[..., 1]
