"""Bitcraze motor numbering against the project's PX4 rotor order, and hover.

models/crazyflie.yaml derives (from the firmware mixer) that the Crazyflie is a
PX4 quad-X up to numbering: project rotors 1..4 (front-right CCW, rear-left CCW,
front-left CW, rear-right CW) are Bitcraze M1, M3, M4, M2.
"""

from __future__ import annotations

import math

import numpy as np

from monitor.vehicle import GRAVITY_M_S2, VehicleConfig

G_M_S2 = GRAVITY_M_S2

# BITCRAZE_OF_PROJECT[i] is the Bitcraze motor at project rotor index i.
BITCRAZE_OF_PROJECT: tuple[str, str, str, str] = ("M1", "M3", "M4", "M2")
# Project rotor index of Bitcraze M1..M4.
PROJECT_INDEX_OF_BITCRAZE: dict[str, int] = {m: i for i, m in enumerate(BITCRAZE_OF_PROJECT)}


def bitcraze_order(project_cols: np.ndarray) -> np.ndarray:
    """(..., 4) columns in project order -> (..., 4) columns as M1, M2, M3, M4."""
    idx = [PROJECT_INDEX_OF_BITCRAZE[f"M{k}"] for k in range(1, 5)]
    return np.asarray(project_cols)[..., idx]


def hover_cmd(vehicle: VehicleConfig, extra_mass_kg: float = 0.0) -> float:
    """Motor command at which four equal rotors carry the vehicle (static hover)."""
    omega = math.sqrt((vehicle.mass_kg + extra_mass_kg) * G_M_S2 / (4.0 * vehicle.kf_n_per_rad_s2))
    return float(vehicle.esc.omega_rad_s_to_cmd(omega))


def torque_signs_frd(vehicle: VehicleConfig) -> np.ndarray:
    """(3, 4) signs of each rotor's roll, pitch, yaw torque (FRD) for more thrust.

    A rotor at (x, y) pushing along -z gives torque (-y F, x F); its drag yaws
    the body by ``spin_sign`` (CCW rotor: nose right).
    """
    p = vehicle.rotor_positions_array_m
    return np.sign(np.stack([-p[:, 1], p[:, 0], vehicle.spin_sign]))
