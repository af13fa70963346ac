"""Batched fault vibration: once-per-revolution ripple and flutter, as multiplicative factors.

Shared by the analytic and the learned propellers, because the LSTM predicts
the *mean* thrust and torque (it is trained with MSE on noisy load-cell
samples); the zero-mean vibration of a damaged blade is added on top from the
same ``FaultSignature`` that the virtual load cell measured.
"""

from __future__ import annotations

import numpy as np

NOISE_BLOCK_STEPS = 256  # flutter noise is drawn for this many steps at once (one RNG call, not one per step)
WRAP_EVERY_STEPS = 256  # blade angles wrapped to [0, 2π) this often: < 800 rad, so the float32 sine errs < 1e-4


def per_rotor(signatures, conditions: np.ndarray, attr: str) -> np.ndarray:
    """(B, 4) float64 values of ``attr``: ``signatures`` is a table indexed by condition code (0, 1, 2) or a
    (B, 4) grid with one signature per rotor."""
    if isinstance(signatures, np.ndarray) and signatures.dtype == object:
        if signatures.shape != np.shape(conditions):
            raise ValueError(f"signatures: grid {signatures.shape} does not match conditions {np.shape(conditions)}")
        return np.array([[getattr(x, attr) for x in row] for row in signatures], dtype=np.float64)
    return np.array([getattr(s, attr) for s in signatures], dtype=np.float64)[conditions]


class FaultVibration:
    """State per rotor: blade angle (1P ripple) and an Ornstein-Uhlenbeck flutter state.

    The ripple uses whole-batch arrays (zero amplitude on healthy rotors) and a
    float32 sine (6x cheaper than float64; the angle itself stays float64).
    Flutter, whose Gaussian draws dominate the cost, runs on the fluttering
    rotors only.
    """

    def __init__(self, conditions: np.ndarray, signatures, omega_max_rad_s: float, rng):
        """``rng``: one Generator for the batch, or a sequence of B (one per flight, so a flight's vibration
        does not depend on the batch it is simulated in)."""
        cond = np.asarray(conditions)
        self._rng = rng
        self._per_flight_rng = not isinstance(rng, np.random.Generator)
        if self._per_flight_rng and len(rng) != cond.shape[0]:
            raise ValueError(f"rng: {len(rng)} generators for {cond.shape[0]} flights")
        self._inv_omega_max2 = 1.0 / float(omega_max_rad_s) ** 2

        def rotor_values(attr: str) -> np.ndarray:
            return per_rotor(signatures, cond, attr)

        self._rip_t, self._rip_q = rotor_values("ripple_1p_thrust"), rotor_values("ripple_1p_torque")
        flt = np.stack([rotor_values("flutter_thrust_std"), rotor_values("flutter_torque_std")]).reshape(2, -1)
        self._flt_idx = np.flatnonzero(np.any(flt > 0, axis=0))
        self._flt_std = flt[:, self._flt_idx]
        self._flt_tau = rotor_values("flutter_time_constant_s").reshape(-1)[self._flt_idx]
        self._has_flutter = bool(self._flt_idx.size)
        self.active = bool(self._has_flutter or np.any(self._rip_t > 0) or np.any(self._rip_q > 0))
        self._angle = np.zeros(cond.shape)
        self._flutter = np.zeros((2, self._flt_idx.size))
        self._noise = np.empty((0, 2, self._flt_idx.size))
        self._noise_pos = 0
        self._steps = 0
        self._decay_dt: float | None = None
        self._decay = (np.ones(self._flt_idx.size), np.zeros(self._flt_idx.size))

    def reset(self) -> None:
        # Random blade phase per rotor: rotors are not synchronised in flight.
        if self._per_flight_rng:
            self._angle = np.stack([g.uniform(0.0, 2.0 * np.pi, self._angle.shape[1:]) for g in self._rng])
        else:
            self._angle = self._rng.uniform(0.0, 2.0 * np.pi, self._angle.shape)
        self._flutter[:] = 0.0

    def _noise_block(self) -> np.ndarray:
        shape = (NOISE_BLOCK_STEPS,) + self._flutter.shape
        if not self._per_flight_rng:
            return self._rng.standard_normal(shape)
        # Fluttering rotors are sorted by flight, so each flight's columns are one contiguous run.
        flight = self._flt_idx // self._angle.shape[1]
        out = np.empty(shape)
        for b in np.unique(flight):
            cols = np.flatnonzero(flight == b)
            out[:, :, cols] = self._rng[b].standard_normal((NOISE_BLOCK_STEPS, 2, cols.size))
        return out

    def step(self, omega_rad_s: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Advance by dt; returns (thrust_factor, torque_factor), each shaped like omega, mean 1."""
        self._angle += omega_rad_s * dt_s
        self._steps += 1
        if self._steps % WRAP_EVERY_STEPS == 0:
            np.mod(self._angle, 2.0 * np.pi, out=self._angle)
        sin = np.sin(self._angle.astype(np.float32))
        ft = 1.0 + self._rip_t * sin
        fq = 1.0 + self._rip_q * sin
        if self._has_flutter:
            if self._decay_dt != dt_s:
                a = np.exp(-dt_s / self._flt_tau)
                self._decay_dt, self._decay = dt_s, (a, np.sqrt(1.0 - a * a))
            if self._noise_pos >= len(self._noise):
                self._noise = self._noise_block()
                self._noise_pos = 0
            a, b = self._decay
            self._flutter *= a
            self._flutter += b * self._noise[self._noise_pos]
            self._noise_pos += 1
            s2 = np.square(omega_rad_s.reshape(-1)[self._flt_idx]) * self._inv_omega_max2
            add = self._flt_std * s2 * self._flutter
            ft.reshape(-1)[self._flt_idx] += add[0]
            fq.reshape(-1)[self._flt_idx] += add[1]
        return ft, fq
