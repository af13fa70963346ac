"""Propeller models: the one interface between rotor speed and rotor forces.

A propeller model is any object with

    reset(omega_rad_s: (B, 4)) -> None
    __call__(omega_rad_s: (B, 4), dt_s: float) -> (thrust_n (B, 4), torque_nm (B, 4))

``thrust_n`` is the thrust magnitude along body -z (up); ``torque_nm`` is the
drag-torque magnitude (>= 0). The simulator applies each rotor's spin sign
(``VehicleConfig.spin_sign``). It is called once per physics step, so a
learned model may keep internal state and run its own internal rate.
Rotor columns follow PX4 quad-X order (see ``monitor.vehicle``).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class PropellerModel(Protocol):
    def reset(self, omega_rad_s: np.ndarray) -> None: ...

    def __call__(self, omega_rad_s: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]: ...


class QuadraticPropeller:
    """Static quadratic law ``T = kF w^2``, ``tau = ktau w^2`` (Tong et al. Table 4.1 / Sec. IV).

    ``thrust_scale`` / ``torque_scale`` ((B, 4) or None) scale individual
    rotors: a crude damaged propeller, or a test's known imbalance.
    """

    def __init__(
        self,
        kf_n_per_rad_s2: float,
        ktau_nm_per_rad_s2: float,
        thrust_scale: np.ndarray | None = None,
        torque_scale: np.ndarray | None = None,
    ):
        self.kf_n_per_rad_s2 = float(kf_n_per_rad_s2)
        self.ktau_nm_per_rad_s2 = float(ktau_nm_per_rad_s2)
        self.thrust_scale = None if thrust_scale is None else np.asarray(thrust_scale, dtype=np.float64)
        self.torque_scale = None if torque_scale is None else np.asarray(torque_scale, dtype=np.float64)
        self._kf = self._ktau = None

    @classmethod
    def for_vehicle(cls, vehicle, thrust_scale=None, torque_scale=None) -> QuadraticPropeller:
        return cls(vehicle.kf_n_per_rad_s2, vehicle.ktau_nm_per_rad_s2, thrust_scale, torque_scale)

    def reset(self, omega_rad_s: np.ndarray) -> None:
        shape = np.shape(omega_rad_s)
        # Fold the per-rotor scales into per-rotor coefficients once, so a step costs 3 ops.
        self._kf = np.broadcast_to(self.kf_n_per_rad_s2 * (1.0 if self.thrust_scale is None else self.thrust_scale), shape).copy()
        self._ktau = np.broadcast_to(
            self.ktau_nm_per_rad_s2 * (1.0 if self.torque_scale is None else self.torque_scale), shape
        ).copy()

    def __call__(self, omega_rad_s: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        if self._kf is None or self._kf.shape != omega_rad_s.shape:
            self.reset(omega_rad_s)
        w2 = omega_rad_s * omega_rad_s
        return self._kf * w2, self._ktau * w2
