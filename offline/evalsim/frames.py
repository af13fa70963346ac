"""The one boundary between RotorPy's frames and numbering and the project's (PX4 NED/FRD, quad-X).

RotorPy's world has z up and its body z up. We take its world as NWU (x north,
y west, z up) and its body as FLU (forward, left, up); then both conversions are
the same proper rotation ``FLIP = diag(1, -1, -1)`` (π about x):

    v_ned = FLIP @ v_nwu,   v_frd = FLIP @ v_flu,   R_ned_frd = FLIP @ R_nwu_flu @ FLIP.

RotorPy quaternions are scalar-last ``[x, y, z, w]`` (scipy); the project's are
scalar-first ``[w, x, y, z]``; conjugating by FLIP negates y and z.

RotorPy's rotors (our choice, as its Hummingbird file): r1 front-left, r2
front-right, r3 rear-right, r4 rear-left. PX4 quad-X: 1 front-right CCW, 2
rear-left CCW, 3 front-left CW, 4 rear-right CW. RotorPy's ``rotor_directions``
give the sign of each rotor's drag torque about body +z (up): a CCW rotor (seen
from above) pushes the body clockwise seen from above, i.e. about -z up, so
direction = -1 for CCW and +1 for CW.
"""

from __future__ import annotations

import numpy as np

FLIP = np.diag([1.0, -1.0, -1.0])
# PX4 number (1..4) of RotorPy rotor r1..r4.
PX4_OF_ROTORPY = (3, 1, 4, 2)
# Index into a PX4-ordered array giving RotorPy order: rotorpy = px4[RP_FROM_PX4].
RP_FROM_PX4 = np.array([p - 1 for p in PX4_OF_ROTORPY])
# Index into a RotorPy-ordered array giving PX4 order: px4 = rotorpy[PX4_FROM_RP].
PX4_FROM_RP = np.argsort(RP_FROM_PX4)


def px4_to_rotorpy(per_rotor_px4: np.ndarray) -> np.ndarray:
    """A per-rotor array (last axis 4) in PX4 order -> RotorPy order."""
    return np.asarray(per_rotor_px4)[..., RP_FROM_PX4]


def rotorpy_to_px4(per_rotor_rp: np.ndarray) -> np.ndarray:
    """A per-rotor array (last axis 4) in RotorPy order -> PX4 order."""
    return np.asarray(per_rotor_rp)[..., PX4_FROM_RP]


def rotorpy_directions(spin_px4: tuple[str, str, str, str]) -> np.ndarray:
    """RotorPy ``rotor_directions`` (RotorPy order) from PX4 spins ('ccw'/'cw', PX4 order)."""
    d_px4 = np.array([-1.0 if s == "ccw" else 1.0 for s in spin_px4])
    return px4_to_rotorpy(d_px4)


def positions_flu_rotorpy(positions_frd_px4_m: np.ndarray) -> np.ndarray:
    """(4, 3) rotor positions FRD in PX4 order -> FLU in RotorPy order."""
    return px4_to_rotorpy(np.asarray(positions_frd_px4_m, dtype=np.float64).T).T @ FLIP


def vec_to_ned(v_nwu: np.ndarray) -> np.ndarray:
    """World or body vectors (last axis 3) NWU/FLU -> NED/FRD (FLIP is its own inverse)."""
    return np.asarray(v_nwu) * np.array([1.0, -1.0, -1.0])


vec_from_ned = vec_to_ned


def quat_rotorpy_to_px4(q_xyzw: np.ndarray) -> np.ndarray:
    """RotorPy ``[x, y, z, w]`` (R_nwu_flu) -> project ``[w, x, y, z]`` (R_ned_frd)."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    return np.stack([q[..., 3], q[..., 0], -q[..., 1], -q[..., 2]], axis=-1)


def quat_px4_to_rotorpy(q_wxyz: np.ndarray) -> np.ndarray:
    q = np.asarray(q_wxyz, dtype=np.float64)
    return np.stack([q[..., 1], -q[..., 2], -q[..., 3], q[..., 0]], axis=-1)


def rotation_matrix_wxyz(q: np.ndarray) -> np.ndarray:
    """R (rotating body vectors into the world) of a unit scalar-first quaternion."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def euler_zyx(R_ned_frd: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in rad of R_ned_frd, PX4's ZYX convention."""
    roll = float(np.arctan2(R_ned_frd[2, 1], R_ned_frd[2, 2]))
    pitch = float(-np.arcsin(np.clip(R_ned_frd[2, 0], -1.0, 1.0)))
    yaw = float(np.arctan2(R_ned_frd[1, 0], R_ned_frd[0, 0]))
    return roll, pitch, yaw


def rotation_matrices_wxyz(q: np.ndarray) -> np.ndarray:
    """(B, 3, 3) R (body -> world) of (B, 4) unit scalar-first quaternions."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1),
        ],
        axis=1,
    )


def euler_zyx_batch(R: np.ndarray) -> np.ndarray:
    """(B, 3) roll, pitch, yaw of (B, 3, 3) R_ned_frd."""
    return np.column_stack(
        [
            np.arctan2(R[:, 2, 1], R[:, 2, 2]),
            -np.arcsin(np.clip(R[:, 2, 0], -1.0, 1.0)),
            np.arctan2(R[:, 1, 0], R[:, 0, 0]),
        ]
    )
