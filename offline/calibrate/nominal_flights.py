"""Healthy flights of the NOMINAL vehicle from our own simulator, as a user's log would carry them.

The gates of ``offline.calibrate.fit`` are set on these (``python -m offline.calibrate.derive_gates``):
flights where no term of the library is off its nominal value, so whatever the calibrator names there is
named wrongly. Every other entry of the assumption register (``offline/sim/assumptions.py``) is drawn per
flight: wind and turbulence, controller gains, battery sag and the ESC's voltage dependence,
quadratic drag, blade flapping, IMU and attitude noise, and the telemetry's attitude delay, jitter and drops.
The entries the term library fits (``LIBRARY_ENTRIES``) stay at their nominal values.

Telemetry is applied to the 20 Hz table as ``offline.sim.telemetry`` applies it to the training signals, per
message group (motor outputs; attitude, rates and velocity from the estimator, read ``attitude_log_delay_s``
earlier than the motor outputs), so the calibrator sees the same link a real log has.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from monitor.flight import FlightTable
from monitor.vehicle import VehicleConfig
from offline.sim.assumptions import REGISTER, AssumptionRegister, draw_flights, nominal_airframe
from offline.sim.telemetry import degrade_flight

# Register entries a term of offline.calibrate.terms fits, or that say the airframe differs from its file
# (AIRFRAME_TERMS, held at nominal by ``nominal_airframe``): fixed at their nominal values.
LIBRARY_ENTRIES = (
    "inertia_error_frac",
    "linear_drag_n_per_m_s",
    "motor_time_constant_s",
    "gyro_bias_frd_rad_s",
    "rotor_inertia_kg_m2",
)
MOTOR_GROUP = ("motor_cmd", "motor_rpm")
ESTIMATOR_GROUPS = (
    ("roll_rad", "pitch_rad", "yaw_rad"),
    ("roll_rate_rad_s", "pitch_rate_rad_s", "yaw_rate_rad_s"),
    ("vel_ned_m_s",),
)


def nominal_register(register: AssumptionRegister = REGISTER) -> AssumptionRegister:
    """``register`` with the airframe's own terms and every library term at nominal: a vehicle as its file says."""
    register = nominal_airframe(register)
    for name in LIBRARY_ENTRIES:
        a = register[name]
        register = register.with_range(name, a.nominal, a.nominal)
    return register


def degrade_table(
    tab: FlightTable, delay_s: float, jitter_std_s: float, drop_prob: float, rng: np.random.Generator
) -> FlightTable:
    """A copy of ``tab`` with the link's jitter and drops per message group and the estimator's delay."""
    groups = (MOTOR_GROUP, *ESTIMATOR_GROUPS)
    signals = {name: np.asarray(getattr(tab, name), dtype=np.float64) for g in groups for name in g}
    return dataclasses.replace(tab, **degrade_flight(signals, tab.rate_hz, delay_s, jitter_std_s, drop_prob, rng, groups))


def _simulate(vehicle: VehicleConfig, flights: int, seed: int, duration_s: float, per_flight=None):
    from offline.sim.mission import random_waypoints
    from offline.sim.propeller import QuadraticPropeller
    from offline.sim.simulator import SimConfig, simulate

    wps = random_waypoints(flights, 5, seed=seed)
    prop = QuadraticPropeller.for_vehicle(vehicle)
    return simulate(vehicle, wps, prop, SimConfig(duration_s=duration_s), seed=seed, per_flight=per_flight)


def nominal_flights(
    vehicle: VehicleConfig, flights: int, seed: int, duration_s: float = 40.0, register: AssumptionRegister | None = None
) -> list[FlightTable]:
    """``flights`` healthy flights of ``vehicle`` (random routes), each with its own register draw; flight i
    depends only on (seed, i)."""
    from offline.sim.perflight import PerFlightTerms

    register = nominal_register() if register is None else register
    phys = draw_flights(register, seed, range(flights))
    log = _simulate(vehicle, flights, seed, duration_s, PerFlightTerms.from_flights(phys, vehicle))
    out = []
    for i, f in enumerate(phys):
        tab = log.to_flight_table(i, source=f"nominal-{seed}-{i}")
        rng = np.random.default_rng([int(f["noise_seed"]) % 2**63, 2])
        out.append(degrade_table(tab, f["attitude_log_delay_s"], f["telemetry_jitter_std_s"], f["telemetry_drop_prob"], rng))
    return out


def fixed_flights(vehicle: VehicleConfig, flights: int, seed: int, duration_s: float = 40.0) -> list[FlightTable]:
    """``flights`` flights of our simulator's fixed path (random routes, no register draws, exact 20 Hz): ``vehicle``
    exactly as it is, for hidden-effect checks with nothing else in the way."""
    log = _simulate(vehicle, flights, seed, duration_s)
    return [log.to_flight_table(i, source=f"fixed-{seed}-{i}") for i in range(flights)]
