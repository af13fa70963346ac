"""The hidden physics of one evaluation flight: a frozen dataclass, PX4 rotor order, SI units.

Nothing here is visible to a predictor; ``truth.json`` records all of it. A
propeller's damage is a function of its speed (``thrust_factor``,
``torque_factor``): evalsim's own fault model, deliberately not the training
simulator's (see README.md, "assumptions").
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np

from monitor.esc import PAPER_ESC, EscCurve
from monitor.vehicle import VehicleConfig

Vec3 = tuple[float, float, float]
Vec4 = tuple[float, float, float, float]
ONES4: Vec4 = (1.0, 1.0, 1.0, 1.0)
ZEROS4: Vec4 = (0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Damage:
    """Per-rotor propeller damage (PX4 order). Healthy rotors have zeros.

    Thrust loss at speed ω: ``L(ω) = thrust_loss_at_hover * (ω / ω_hover) ** -loss_speed_exponent``
    (exponent >= 0: constant or falling with speed), capped at ``MAX_LOSS``. The drag torque
    per unit thrust changes by ``torque_per_thrust_change`` (negative: falling).
    """

    thrust_loss_at_hover: Vec4 = ZEROS4
    loss_speed_exponent: Vec4 = ZEROS4
    torque_per_thrust_change: Vec4 = ZEROS4
    flutter_thrust_std: Vec4 = ZEROS4  # relative thrust noise (correlated over FLUTTER_TAU_S)
    vibration_1p_m_s2: Vec4 = ZEROS4  # 1P imbalance: accelerometer amplitude at hover speed
    onset_time_s: float = 0.0  # damage applies from this flight time on

    MAX_LOSS = 0.5

    @property
    def faulty(self) -> tuple[int, ...]:
        """PX4 numbers of the damaged propellers."""
        return tuple(i + 1 for i in range(4) if self.thrust_loss_at_hover[i] > 0)


@dataclass(frozen=True)
class Airframe:
    """Every physical parameter of one simulated vehicle + flight (PX4 rotor order)."""

    mass_kg: float
    inertia_diag_kg_m2: Vec3
    rotor_positions_frd_m: tuple[Vec3, Vec3, Vec3, Vec3]
    rotor_spin: tuple[str, str, str, str]
    kf_n_per_rad_s2: float  # nominal (vehicle.yaml)
    ktau_nm_per_rad_s2: float
    hover_omega_rad_s: float  # ω at which damage is specified (nominal hover)
    omega_min_rad_s: float
    omega_max_rad_s: float
    # A weak motor reaches sqrt(efficiency) of the speed its ESC command asks for, so it makes
    # ``efficiency`` of the thrust; ESC telemetry shows the lower speed.
    motor_thrust_efficiency: Vec4 = ONES4
    motor_time_constant_s: Vec4 = (0.03, 0.03, 0.03, 0.03)
    cg_offset_frd_m: Vec3 = (0.0, 0.0, 0.0)
    drag_quadratic_n_per_m2_s2: Vec3 = (0.02, 0.02, 0.04)  # RotorPy c_Dx, c_Dy, c_Dz (body)
    rotor_drag_kg_per_rad: float = 2.0e-5  # RotorPy k_d: H-force, linear in airspeed and ω
    # Blade flapping (RotorPy's k_flap, off in every RotorPy preset): each rotor adds a moment
    # k * ω_i * (v_i x e_z) (FLU, v_i its hub's airspeed), nose-up when flying forward (blowback). 0 = none.
    flapping_nm_per_rad_s_m_s: float = 0.0
    esc: EscCurve = PAPER_ESC  # the ESC's real curve (the controller assumes PAPER_ESC)
    esc_rpm_per_volt: float = 0.01  # fractional RPM loss per volt below esc_reference_v
    esc_reference_v: float = 16.0
    battery_full_v: float = 16.8
    battery_empty_v: float = 14.0
    battery_start_soc: float = 1.0
    battery_capacity_mah: float = 5000.0
    battery_internal_resistance_ohm: float = 0.02
    power_efficiency: float = 0.75  # shaft power / electrical power
    damage: Damage = field(default_factory=Damage)
    payload_kg: float = 0.0
    payload_pickup_time_s: float = 0.0  # payload carried from this time on (0: from the start)
    # A motor or ESC failure: from ``motor_stop_time_s`` on, PX4 rotor ``motor_stop_rotor`` (1..4; 0: none) gets the
    # ESC's minimum command whatever the controller asks, and the log shows that command.
    motor_stop_rotor: int = 0
    motor_stop_time_s: float = 0.0

    def asdict(self) -> dict:
        d = asdict(self)
        d["esc"] = asdict(self.esc)
        return d

    def with_(self, **kw) -> Airframe:
        return replace(self, **kw)

    @staticmethod
    def from_vehicle(v: VehicleConfig, **kw) -> Airframe:
        return Airframe(
            mass_kg=v.mass_kg,
            inertia_diag_kg_m2=tuple(v.inertia_diag_kg_m2),
            rotor_positions_frd_m=tuple(tuple(p) for p in v.rotor_positions_frd_m),
            rotor_spin=tuple(v.rotor_spin),
            kf_n_per_rad_s2=v.kf_n_per_rad_s2,
            ktau_nm_per_rad_s2=v.ktau_nm_per_rad_s2,
            hover_omega_rad_s=v.hover_omega_rad_s,
            omega_min_rad_s=v.omega_min_rad_s,
            omega_max_rad_s=v.omega_max_rad_s,
            battery_full_v=v.battery_full_v,
            battery_empty_v=v.battery_empty_v,
            battery_capacity_mah=v.battery_capacity_mah,
            battery_internal_resistance_ohm=v.battery_internal_resistance_ohm,
            **kw,
        )


def thrust_torque_factors(af: Airframe, omega_rad_s: np.ndarray, damaged: bool) -> tuple[np.ndarray, np.ndarray]:
    """Propeller (thrust factor, torque factor) per rotor (PX4 order) at ``omega_rad_s``, healthy = 1.

    Torque factor = thrust factor * (1 + torque_per_thrust_change): damage scales the
    blade's drag torque with its lift, then changes their ratio.
    """
    if not damaged:
        return np.ones(4), np.ones(4)
    d = af.damage
    loss0 = np.asarray(d.thrust_loss_at_hover)
    ratio = np.maximum(np.asarray(omega_rad_s), 1.0) / af.hover_omega_rad_s
    loss = np.minimum(loss0 * ratio ** (-np.asarray(d.loss_speed_exponent)), Damage.MAX_LOSS)
    thrust = 1.0 - loss
    return thrust, thrust * (1.0 + np.asarray(d.torque_per_thrust_change))
