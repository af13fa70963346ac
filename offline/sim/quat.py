"""Batched quaternion helpers, scalar-first (w, x, y, z), rotating body (FRD) into world (NED).

Arrays have the flight on the leading axis: quaternions (B, 4), vectors (B, 3).
Formulas are written out component by component: for a handful of flights
that is several times faster than building (B, 3, 3) matrices.
"""

from __future__ import annotations

import numpy as np


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b, (B, 4)."""
    aw, ax, ay, az = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    bw, bx, by, bz = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    return np.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        axis=1,
    )


def quat_conj(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_from_euler(roll_rad, pitch_rad, yaw_rad) -> np.ndarray:
    """ZYX Euler angles -> (B, 4) quaternion."""
    cr, sr = np.cos(np.asarray(roll_rad) / 2), np.sin(np.asarray(roll_rad) / 2)
    cp, sp = np.cos(np.asarray(pitch_rad) / 2), np.sin(np.asarray(pitch_rad) / 2)
    cy, sy = np.cos(np.asarray(yaw_rad) / 2), np.sin(np.asarray(yaw_rad) / 2)
    q = np.stack(
        (
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ),
        axis=-1,
    )
    return np.atleast_2d(q)


def quat_to_euler(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(..., 4) quaternion -> ZYX (roll, pitch, yaw) in rad, each (...)."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def rotate_body_to_world(q: np.ndarray, v_body: np.ndarray) -> np.ndarray:
    """R_world_body @ v for (..., 4) quaternions and (..., 3) vectors."""
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v_body)
    return v_body + q[..., :1] * t + np.cross(u, t)


def rotate_world_to_body(q: np.ndarray, v_world: np.ndarray) -> np.ndarray:
    """R_world_body.T @ v."""
    u = -q[..., 1:]
    t = 2.0 * np.cross(u, v_world)
    return v_world + q[..., :1] * t + np.cross(u, t)


def _mul_tensor() -> np.ndarray:
    """C (4, 4, 4) with (a ⊗ b)_i = sum_jk a_j b_k C[j, k, i]: the product as one bilinear map."""
    eye = np.eye(4)
    c = np.empty((4, 4, 4))
    for j in range(4):
        c[j] = quat_mul(np.repeat(eye[j : j + 1], 4, axis=0), eye)
    return c


# Bilinear maps written as matrices, so that a batched product costs one outer
# product and one matmul instead of a dozen column operations.
QUAT_MUL = _mul_tensor().reshape(16, 4)  # vec(a outer b) @ QUAT_MUL = a ⊗ b
QUAT_CONJ_MUL = (_mul_tensor() * np.array([1.0, -1.0, -1.0, -1.0])[:, None, None]).reshape(16, 4)  # conj(a) ⊗ b
QUAT_MUL_PURE = _mul_tensor()[:, 1:, :].reshape(12, 4)  # vec(q outer w) @ QUAT_MUL_PURE = q ⊗ (0, w)


def _body_z_tensor() -> np.ndarray:
    """Z (16, 3): vec(q outer q) @ Z = R_world_body[:, 2] (body z axis in the world) for a unit q."""
    z = np.zeros((4, 4, 3))
    w, x, y, zz = 0, 1, 2, 3
    z[x, zz, 0] = z[zz, x, 0] = 1.0  # 2(xz + wy)
    z[w, y, 0] = z[y, w, 0] = 1.0
    z[y, zz, 1] = z[zz, y, 1] = 1.0  # 2(yz - wx)
    z[w, x, 1] = z[x, w, 1] = -1.0
    z[w, w, 2], z[x, x, 2], z[y, y, 2], z[zz, zz, 2] = 1.0, -1.0, -1.0, 1.0  # w2 - x2 - y2 + z2
    return z.reshape(16, 3)


BODY_Z = _body_z_tensor()


def state_products_map(dt_s: float, gyro_map: np.ndarray) -> np.ndarray:
    """(49, 10): vec(x outer x) @ map, x = [q (4), w (3)], gives in one matmul
    [-dt R[:, 2] (3), dt/2 q ⊗ (0, w) (4), dt gyro_map(w outer w) (3)]."""
    m = np.zeros((7, 7, 10))
    m[:4, :4, :3] = -dt_s * BODY_Z.reshape(4, 4, 3)
    m[:4, 4:, 3:7] = 0.5 * dt_s * QUAT_MUL_PURE.reshape(4, 3, 4)
    m[4:, 4:, 7:] = dt_s * gyro_map.reshape(3, 3, 3)
    return m.reshape(49, 10)


def _quat_to_rot_map() -> np.ndarray:
    """M (16, 9) with vec(R_world_body) = vec(q q^T) @ M for a unit quaternion (w, x, y, z)."""
    m = np.zeros((16, 9))
    w, x, y, z = range(4)

    def put(row: int, col: int, terms) -> None:
        for coef, i, j in terms:
            m[i * 4 + j, row * 3 + col] += coef

    put(0, 0, [(1, w, w), (1, x, x), (-1, y, y), (-1, z, z)])
    put(0, 1, [(2, x, y), (-2, w, z)])
    put(0, 2, [(2, x, z), (2, w, y)])
    put(1, 0, [(2, x, y), (2, w, z)])
    put(1, 1, [(1, w, w), (-1, x, x), (1, y, y), (-1, z, z)])
    put(1, 2, [(2, y, z), (-2, w, x)])
    put(2, 0, [(2, x, z), (-2, w, y)])
    put(2, 1, [(2, y, z), (2, w, x)])
    put(2, 2, [(1, w, w), (-1, x, x), (-1, y, y), (1, z, z)])
    return m


QUAT_TO_ROT = _quat_to_rot_map()


def rotation_matrices(q: np.ndarray) -> np.ndarray:
    """R_world_body (B, 3, 3) of unit quaternions (B, 4), as one outer product and one matmul."""
    return (np.multiply(q[:, :, None], q[:, None, :]).reshape(len(q), 16) @ QUAT_TO_ROT).reshape(len(q), 3, 3)
