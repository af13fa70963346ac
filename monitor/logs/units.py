"""Outside units and frames met in logs, each converted here once.

Quaternions are scalar-first (w, x, y, z) rotating body FRD into world NED
(PX4's ``vehicle_attitude.q`` convention); Euler angles are ZYX (yaw, pitch,
roll), as everywhere in propwatch.
"""

from __future__ import annotations

import math

import numpy as np

from monitor.resample import US_PER_S  # noqa: F401  (the one definition; re-exported for the readers)
from monitor.vehicle import GRAVITY_M_S2

RAD_PER_DEG = math.pi / 180.0
US_PER_MS = 1000
V_PER_MV = 1e-3
V_PER_CV = 1e-2  # ArduCopter 3.3's CURR.Volt is an int16 in centivolts
M_S2_PER_G = GRAVITY_M_S2


def deg_to_rad(deg):
    return np.asarray(deg, dtype=np.float64) * RAD_PER_DEG


def wrap_pi(angle_rad):
    """Into [-pi, pi): ArduPilot logs yaw as 0..360 deg."""
    a = np.asarray(angle_rad, dtype=np.float64)
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def ms_to_us(t_ms):
    return np.round(np.asarray(t_ms, dtype=np.float64) * US_PER_MS).astype(np.int64)


def quat_wxyz_to_euler_zyx(q) -> np.ndarray:
    """(N, 4) scalar-first quaternions -> (N, 3) roll, pitch, yaw in rad."""
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)
