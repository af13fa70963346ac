"""RotorPy's ``Multirotor`` with per-rotor coefficients, and a fixed-step RK4 of its state derivative.

``PerRotorMultirotor`` subclasses RotorPy's ``Multirotor`` and replaces only
``compute_body_wrench``: each rotor has its own thrust and drag-torque
coefficient (a callable of rotor speed, so damage may vary with speed), its own
motor time constant (RotorPy's ``tau_m`` broadcasts per rotor) and its position
relative to the centre of mass (a CG offset moves every rotor). Aerodynamics
are RotorPy's: parasitic drag (quadratic, ``c_D``) and rotor H-force (``k_d``,
linear in airspeed); translational lift and flapping are off.

RotorPy integrates each step with ``solve_ivp`` (RK45) and one derivative costs
~140 µs here: an 80 s flight would take minutes. ``BatchedDerivative`` evaluates
the same equations for many flights at once on a (B, 20) state, without dicts
or scipy rotations; a test checks each row equals ``PerRotorMultirotor._s_dot_fn``
(and, with equal rotors, plain ``Multirotor._s_dot_fn``) to rounding.
``rk4_step`` integrates it at a fixed step.

Everything in this module is in RotorPy's frames and rotor order (see frames.py).
State layout (RotorPy's): x[0:3] NWU m, v[3:6] m/s, q[6:10] [x,y,z,w] R_nwu_flu,
w[10:13] FLU rad/s, wind[13:16] NWU m/s, rotor_speeds[16:20] rad/s.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from rotorpy.vehicles.multirotor import Multirotor

RotorCoefficients = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
# rotor speeds (4,) rad/s -> (thrust coeff N/(rad/s)^2, torque coeff Nm/(rad/s)^2), RotorPy order


def rotorpy_params(
    mass_kg: float,
    inertia_diag_kg_m2,
    rotor_pos_flu_m: np.ndarray,
    rotor_directions: np.ndarray,
    kf: float,
    ktau: float,
    tau_m_s: np.ndarray,
    omega_min: float,
    omega_max: float,
    c_d: tuple[float, float, float],
    k_d: float,
    k_flap: float = 0.0,
) -> dict:
    """A RotorPy ``quad_params`` dict (RotorPy order, FLU, CoM-relative rotor positions).

    ``k_flap`` >= 0 is blade flapping with blowback's sign (``Airframe.flapping_nm_per_rad_s_m_s``): RotorPy's own
    term is ``-k_flap * ω (v x e_z)``, nose-down when flying forward for a positive coefficient, so it is stored
    negated; ``PerRotorMultirotor`` and ``BatchedDerivative`` add ``+k_flap * ω (v x e_z)`` themselves."""
    return {
        "mass": mass_kg,
        "Ixx": inertia_diag_kg_m2[0],
        "Iyy": inertia_diag_kg_m2[1],
        "Izz": inertia_diag_kg_m2[2],
        "Ixy": 0.0,
        "Ixz": 0.0,
        "Iyz": 0.0,
        "c_Dx": c_d[0],
        "c_Dy": c_d[1],
        "c_Dz": c_d[2],
        "num_rotors": 4,
        "rotor_pos": {f"r{i + 1}": np.asarray(rotor_pos_flu_m[i], dtype=np.float64) for i in range(4)},
        "rotor_directions": np.asarray(rotor_directions, dtype=np.float64),
        "rotor_speed_min": omega_min,
        "rotor_speed_max": omega_max,
        "k_eta": kf,
        "k_m": ktau,
        "k_d": k_d,
        "k_z": 0.0,
        "k_h": 0.0,
        "k_flap": -k_flap,
        "tau_m": np.asarray(tau_m_s, dtype=np.float64),
        "motor_noise_std": 0.0,
    }


class PerRotorMultirotor(Multirotor):
    """RotorPy ``Multirotor`` whose rotors each have their own thrust and torque coefficients."""

    def __init__(self, quad_params: dict, coefficients: RotorCoefficients):
        super().__init__(quad_params, control_abstraction="cmd_motor_speeds", aero=True, enable_ground=False)
        self.coefficients = coefficients
        self.thrust_multiplier = np.ones(4)  # flutter: held constant over a step by the caller

    def compute_body_wrench(self, body_rates, rotor_speeds, body_airspeed_vector):
        local_airspeeds = body_airspeed_vector[:, np.newaxis] + Multirotor.hat_map(body_rates) @ (self.rotor_geometry.T)
        kf, ktau = self.coefficients(rotor_speeds)
        T = np.zeros((3, 4))
        T[2] = kf * self.thrust_multiplier * rotor_speeds**2
        D = -Multirotor._norm(body_airspeed_vector) * self.drag_matrix @ body_airspeed_vector
        H = -rotor_speeds * (self.rotor_drag_matrix @ local_airspeeds)
        M_force = -np.einsum("ijk, ik->j", Multirotor.hat_map(self.rotor_geometry), T + H)
        M_yaw = np.zeros((3, 4))
        M_yaw[2] = self.rotor_dir * ktau * self.thrust_multiplier * rotor_speeds**2
        # Blade flapping, blowback's sign: k ω (v x e_z) = k ω (v_y, -v_x, 0) per rotor (rotorpy_params stores -k).
        k = -self.k_flap
        M_flap = np.zeros(3)
        if k:
            M_flap[0] = k * np.sum(rotor_speeds * local_airspeeds[1])
            M_flap[1] = -k * np.sum(rotor_speeds * local_airspeeds[0])
        return np.sum(T + H, axis=1) + D, M_force + np.sum(M_yaw, axis=1) + M_flap


class BatchedDerivative:
    """``PerRotorMultirotor._s_dot_fn`` for B vehicles at once: the same equations on a (B, 20) state.

    Built from one ``PerRotorMultirotor`` per flight (``from_multirotors``); a test
    checks each row equals RotorPy's own ``_s_dot_fn`` to rounding. Inertia is
    diagonal (as every evalsim airframe's). ``coefficients`` maps rotor speeds (B, 4)
    to per-rotor (thrust, torque) coefficients (B, 4); ``thrust_multiplier`` (B, 4)
    is held over a step (flutter).
    """

    def __init__(self, mrs: list[PerRotorMultirotor], coefficients: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]):
        self.mrs = mrs
        self.coefficients = coefficients
        r = np.stack([np.asarray(m.rotor_geometry, dtype=np.float64) for m in mrs])  # (B, 4, 3)
        self.rx, self.ry, self.rz = r[..., 0], r[..., 1], r[..., 2]
        self.dirs = np.stack([np.asarray(m.rotor_dir, dtype=np.float64) for m in mrs])
        self.kd = np.array([[m.k_d] for m in mrs], dtype=np.float64)
        self.kz = np.array([[m.k_z] for m in mrs], dtype=np.float64)
        self.kflap = np.array([[-m.k_flap] for m in mrs], dtype=np.float64)  # blowback's sign (rotorpy_params)
        self.cd = np.array([[m.c_Dx, m.c_Dy, m.c_Dz] for m in mrs], dtype=np.float64)
        for m in mrs:
            if np.any(np.asarray(m.inertia) != np.diag(np.diag(m.inertia))):
                raise ValueError("BatchedDerivative: inertia must be diagonal")
        self.thrust_multiplier = np.ones((len(mrs), 4))
        self.refresh()

    def refresh(self) -> None:
        """Re-read the mass terms of every vehicle (payload picked up mid-flight)."""
        self.I = np.stack([np.diag(m.inertia) for m in self.mrs]).astype(np.float64)  # (B, 3)
        self.mass = np.array([m.mass for m in self.mrs], dtype=np.float64)
        self.g = np.array([m.g for m in self.mrs], dtype=np.float64)
        self.inv_tau = 1.0 / np.stack([np.broadcast_to(np.asarray(m.tau_m, dtype=np.float64), (4,)) for m in self.mrs])

    def __call__(self, s: np.ndarray, cmd_rotor_speeds: np.ndarray) -> np.ndarray:
        qx, qy, qz, qw = s[:, 6], s[:, 7], s[:, 8], s[:, 9]
        # R_nwu_flu rows, each (B,)
        r00, r01, r02 = 1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)
        r10, r11, r12 = 2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)
        r20, r21, r22 = 2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)
        ax, ay, az = s[:, 3] - s[:, 13], s[:, 4] - s[:, 14], s[:, 5] - s[:, 15]
        bx = r00 * ax + r10 * ay + r20 * az  # body airspeed R^T (v - wind)
        by = r01 * ax + r11 * ay + r21 * az
        bz = r02 * ax + r12 * ay + r22 * az
        wx, wy, wz = s[:, 10:11], s[:, 11:12], s[:, 12:13]
        rx, ry, rz = self.rx, self.ry, self.rz
        lx = bx[:, None] + wy * rz - wz * ry  # airspeed at each hub (B, 4)
        ly = by[:, None] + wz * rx - wx * rz
        lz = bz[:, None] + wx * ry - wy * rx
        omega = s[:, 16:20]
        kf, ktau = self.coefficients(omega)
        w2m = omega * omega * self.thrust_multiplier
        fx = -omega * self.kd * lx
        fy = -omega * self.kd * ly
        fz = kf * w2m - omega * self.kz * lz
        speed = np.sqrt(bx * bx + by * by + bz * bz)
        Fx = fx.sum(1) - speed * self.cd[:, 0] * bx
        Fy = fy.sum(1) - speed * self.cd[:, 1] * by
        Fz = fz.sum(1) - speed * self.cd[:, 2] * bz
        Mx = (ry * fz - rz * fy).sum(1) + (self.kflap * omega * ly).sum(1)
        My = (rz * fx - rx * fz).sum(1) - (self.kflap * omega * lx).sum(1)
        Mz = (rx * fy - ry * fx).sum(1) + (self.dirs * ktau * w2m).sum(1)
        out = np.empty_like(s)
        out[:, 0:3] = s[:, 3:6]
        out[:, 3] = (r00 * Fx + r01 * Fy + r02 * Fz) / self.mass
        out[:, 4] = (r10 * Fx + r11 * Fy + r12 * Fz) / self.mass
        out[:, 5] = (r20 * Fx + r21 * Fy + r22 * Fz) / self.mass - self.g
        wx, wy, wz = s[:, 10], s[:, 11], s[:, 12]
        # RotorPy's quat_dot (Graf), scalar-last.
        out[:, 6] = 0.5 * (qw * wx - qz * wy + qy * wz)
        out[:, 7] = 0.5 * (qz * wx + qw * wy - qx * wz)
        out[:, 8] = 0.5 * (-qy * wx + qx * wy + qw * wz)
        out[:, 9] = 0.5 * (-qx * wx - qy * wy - qz * wz)
        Ix, Iy, Iz = self.I[:, 0], self.I[:, 1], self.I[:, 2]
        out[:, 10] = (Mx - (wy * Iz * wz - wz * Iy * wy)) / Ix
        out[:, 11] = (My - (wz * Ix * wx - wx * Iz * wz)) / Iy
        out[:, 12] = (Mz - (wx * Iy * wy - wy * Ix * wx)) / Iz
        out[:, 13:16] = 0.0
        out[:, 16:20] = self.inv_tau * (cmd_rotor_speeds - omega)
        return out


def rk4_step(f: BatchedDerivative, s: np.ndarray, cmd_rotor_speeds: np.ndarray, dt_s: float) -> np.ndarray:
    """One classical RK4 step with the command held; quaternion renormalised as RotorPy does."""
    k1 = f(s, cmd_rotor_speeds)
    k2 = f(s + 0.5 * dt_s * k1, cmd_rotor_speeds)
    k3 = f(s + 0.5 * dt_s * k2, cmd_rotor_speeds)
    k4 = f(s + dt_s * k3, cmd_rotor_speeds)
    out = s + (dt_s / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    out[:, 6:10] /= np.linalg.norm(out[:, 6:10], axis=1, keepdims=True)
    return out
