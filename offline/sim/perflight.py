"""Per-flight physics for one simulator call: the drawn assumptions of B flights as arrays (leading axis = flight).

``PerFlightTerms.from_flights(flights, vehicle)`` stacks ``assumptions.FlightPhysics``
draws onto the nominal vehicle. ``simulate(..., per_flight=terms)`` then uses
these arrays instead of the vehicle's single values; without it the simulator
runs its fixed, bit-identical path.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.esc import RAD_S_PER_RPM
from monitor.vehicle import GRAVITY_M_S2, VehicleConfig
from offline.sim.assumptions import FlightPhysics
from offline.sim.wind import mean_wind_ned

# PX4 parameters the register draws, mapped onto ControllerConfig fields (roll and pitch share a tune).
GAIN_FIELDS = {
    "mc_rollrate_p": ("mc_rollrate_p", "mc_pitchrate_p"),
    "mc_rollrate_i": ("mc_rollrate_i", "mc_pitchrate_i"),
    "mc_rollrate_d": ("mc_rollrate_d", "mc_pitchrate_d"),
    "mc_yawrate_p": ("mc_yawrate_p",),
    "mc_yawrate_i": ("mc_yawrate_i",),
    "mc_roll_p": ("mc_roll_p", "mc_pitch_p"),
    "mc_yaw_p": ("mc_yaw_p",),
    "mpc_xy_vel_p_acc": ("mpc_xy_vel_p_acc",),
    "mpc_xy_vel_i_acc": ("mpc_xy_vel_i_acc",),
    "mpc_z_vel_p_acc": ("mpc_z_vel_p_acc",),
    "mpc_z_vel_i_acc": ("mpc_z_vel_i_acc",),
}


def flapping_coefficient(flight: FlightPhysics, vehicle: VehicleConfig) -> float:
    """The flapping coefficient k (N m per rad/s per m/s) that makes the drawn trim on ``vehicle``.

    A yaw-free share offset s on each front rotor (and +s on each rear one) is a pitch moment
    4 s (m g / 4) a_x = s m g a_x (a_x: the rotors' mean |x| arm); flapping's is k 4 omega_h v at hover speed
    omega_h. Equal for a trim s = t v: k = t m g a_x / (4 omega_h).
    """
    trim = float(flight.values.get("blade_flapping_trim_per_m_s", 0.0))
    a_x = float(np.mean(np.abs(np.array(vehicle.rotor_positions_frd_m, dtype=np.float64)[:, 0])))
    return trim * vehicle.mass_kg * GRAVITY_M_S2 * a_x / (4.0 * vehicle.hover_omega_rad_s)


@dataclass(frozen=True)
class PerFlightTerms:
    motor_efficiency: np.ndarray  # (B, 4) speed scale, vehicle's times drawn
    esc_offset_rad_s: np.ndarray  # (B, 4)
    motor_time_constant_s: np.ndarray  # (B,)
    rotor_positions_frd_m: np.ndarray  # (B, 4, 3) with mounting errors
    cg_offset_frd_m: np.ndarray  # (B, 3)
    inertia_diag_kg_m2: np.ndarray  # (B, 3)
    linear_drag_n_per_m_s: np.ndarray  # (B, 3)
    rotor_inertia_kg_m2: np.ndarray  # (B,)
    esc_voltage_exponent: np.ndarray  # (B,)
    battery_internal_resistance_ohm: np.ndarray  # (B,)
    gains: dict[str, np.ndarray]  # ControllerConfig field -> (B,)
    gyro_bias_frd_rad_s: np.ndarray  # (B, 3)
    gyro_noise_std_rad_s: np.ndarray  # (B,)
    attitude_noise_std_rad: np.ndarray  # (B,)
    wind_mean_ned_m_s: np.ndarray  # (B, 3)
    turbulence_sigma_w_m_s: np.ndarray  # (B,)
    noise_seeds: np.ndarray  # (B,) uint64, the flights' own gust noise
    # (B,) blade flapping, N m per (rad/s of rotor speed) per (m/s of airspeed): each rotor adds
    # k omega (-v_right, +v_forward, 0) in body FRD (blowback: nose-up flying forward). 0 = none.
    flapping_nm_per_rad_s_m_s: np.ndarray | None = None
    # (B, 3) body-axis parasitic drag, N per (m/s)^2: the force is -c |v_air| v_air per axis. None = none.
    quadratic_drag_n_per_m2_s2: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.motor_time_constant_s)

    @classmethod
    def from_flights(cls, flights: list[FlightPhysics], vehicle: VehicleConfig) -> PerFlightTerms:
        def col(name: str) -> np.ndarray:
            return np.array([np.asarray(f[name], dtype=np.float64) for f in flights])

        n = len(flights)
        pos = np.broadcast_to(np.array(vehicle.rotor_positions_frd_m, dtype=np.float64), (n, 4, 3)).copy()
        pos[:, :, :2] += col("arm_position_error_m")
        cg = np.broadcast_to(np.array(vehicle.cg_offset_frd_m, dtype=np.float64), (n, 3)).copy()
        cg[:, :2] += col("cg_offset_frd_m")
        gains = {}
        for key, fields in GAIN_FIELDS.items():
            for f in fields:
                gains[f] = col(key)
        return cls(
            motor_efficiency=np.array(vehicle.motor_efficiency) * np.array([f.motor_efficiency() for f in flights]),
            esc_offset_rad_s=col("esc_offset_rpm") * RAD_S_PER_RPM,
            motor_time_constant_s=col("motor_time_constant_s"),
            rotor_positions_frd_m=pos,
            cg_offset_frd_m=cg,
            inertia_diag_kg_m2=np.array(vehicle.inertia_diag_kg_m2) * (1.0 + col("inertia_error_frac")),
            linear_drag_n_per_m_s=np.array(vehicle.linear_drag_n_per_m_s) + col("linear_drag_n_per_m_s"),
            rotor_inertia_kg_m2=vehicle.rotor_inertia_kg_m2 + col("rotor_inertia_kg_m2"),
            esc_voltage_exponent=col("esc_voltage_exponent"),
            battery_internal_resistance_ohm=col("battery_internal_resistance_ohm"),
            gains=gains,
            gyro_bias_frd_rad_s=np.array(vehicle.gyro_bias_frd_rad_s) + col("gyro_bias_frd_rad_s"),
            gyro_noise_std_rad_s=col("gyro_noise_std_rad_s"),
            attitude_noise_std_rad=col("attitude_noise_std_rad"),
            wind_mean_ned_m_s=np.array(vehicle.wind_ned_m_s)
            + np.array([mean_wind_ned(f["wind_mean_m_s"], f["wind_heading_rad"]) for f in flights]),
            turbulence_sigma_w_m_s=col("turbulence_sigma_w_m_s"),
            noise_seeds=np.array([f["noise_seed"] for f in flights], dtype=np.uint64),
            flapping_nm_per_rad_s_m_s=np.array([flapping_coefficient(f, vehicle) for f in flights]),
            quadratic_drag_n_per_m2_s2=np.array(
                [np.asarray(f.values.get("quadratic_drag_n_per_m2_s2", np.zeros(3)), dtype=np.float64) for f in flights]
            ),
        )
