"""The paper's unbalance ratio (Tong et al. eqs. 14-17), as a special case of ``motor_efficiency``.

Eq. 14: ``U_r^i = mean(w_i) / mean(w_1)`` from the measured hover speeds.
Eq. 15 as printed, ``U_r(w_i) = 1 + w_i / max(w_i) * U_r^i``, would quarter
every rotor's thrust at full speed (``U_r`` near 2 for all motors); the
reading that matches the text ("motor 4 is weaker ... so it must rotate
faster") and equals 1 when all motors agree is
``U_r(w_i) = 1 + w_i / max(w_i) * (U_r^i - 1)``, used here.
Eqs. 16-17: ``F_i = kf * w_i**2 / U_r**2`` and the same for the torque, which
is a rotor *speed* scale ``1 / U_r(w_i)``: ``motor_efficiency`` with a value
computed from the mean speeds instead of fitted, and drifting with speed.

It attributes every per-motor speed difference to the motors, and takes
motor 1 as the healthy baseline; the comparison in ``calibrate`` shows what
that costs when the cause is elsewhere (a CG offset also spreads the mean
speeds) or when motor 1 is the weak one (the ratio then "corrects" the three
healthy motors and doubles the residual, in the tests).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.vehicle import VehicleConfig
from offline.calibrate.physics import target_omega_rad_s
from offline.calibrate.prepare import Segment


@dataclass(frozen=True)
class UnbalanceRatio:
    ratio: np.ndarray  # (4,) U_r^i, motor 1 = 1
    omega_max_rad_s: np.ndarray  # (4,) max(w_i) over the flights

    def speed_scale(self, omega_cmd_rad_s: np.ndarray) -> np.ndarray:
        u = 1.0 + np.clip(omega_cmd_rad_s / self.omega_max_rad_s, 0.0, None) * (self.ratio - 1.0)
        return 1.0 / u

    def params(self) -> dict[str, float]:
        return {f"ur_{i + 1}": float(r) for i, r in enumerate(self.ratio)}


def unbalance_ratio(segments: list[Segment], masks: list[np.ndarray], vehicle: VehicleConfig) -> UnbalanceRatio:
    """Eq. 14 from the commanded speeds on the masked (fit) samples."""
    w = np.concatenate([target_omega_rad_s(s, vehicle)[m] for s, m in zip(segments, masks)])
    mean = w.mean(axis=0)
    return UnbalanceRatio(ratio=mean / mean[0], omega_max_rad_s=w.max(axis=0))
