"""Faults that switch on mid-flight: a propeller model that changes condition at a time per flight.

Both models are stepped every physics step so the learned (stateful) one is
warm at the switch; before ``onset_s`` a flight gets the first model's forces,
from then on the second's. Implements the simulator's ``PropellerModel``.
"""

from __future__ import annotations

import numpy as np


class SwitchedPropellers:
    def __init__(self, before, after, onset_s: np.ndarray):
        self.before, self.after = before, after
        self.onset_s = np.asarray(onset_s, dtype=np.float64).reshape(-1, 1)
        self.t_s = 0.0

    def reset(self, omega_rad_s: np.ndarray) -> None:
        self.before.reset(omega_rad_s)
        self.after.reset(omega_rad_s)
        self.t_s = 0.0

    def __call__(self, omega_rad_s: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        thrust_b, torque_b = self.before(omega_rad_s, dt_s)
        thrust_a, torque_a = self.after(omega_rad_s, dt_s)
        on = self.t_s >= self.onset_s  # (B, 1)
        self.t_s += dt_s
        return np.where(on, thrust_a, thrust_b), np.where(on, torque_a, torque_b)
