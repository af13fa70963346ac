"""The library of candidate model extensions: each a named term with parameters.

A term maps its parameter vector onto ``VehicleConfig`` fields (the same fields
the simulator reads), so a fitted term *is* a calibrated vehicle. ``scale`` is
the smallest change of each parameter that matters physically; it sets the
optimiser's step scale and the identifiability test (a parameter whose
standard error exceeds its scale is not identifiable from the data).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from monitor.vehicle import VehicleConfig


@dataclass(frozen=True)
class Term:
    name: str
    params: tuple[str, ...]
    get: Callable[[VehicleConfig], np.ndarray]  # current values, in ``params`` order
    set: Callable[[VehicleConfig, np.ndarray], VehicleConfig]
    scale: Callable[[VehicleConfig], np.ndarray]
    lower: Callable[[VehicleConfig], np.ndarray]
    upper: Callable[[VehicleConfig], np.ndarray]
    fields: tuple[str, ...]  # VehicleConfig keys this term writes
    why: str  # the physical cause, for the report
    # Parameters fitted with the term (and written with it) whose standard error does not decide whether the term
    # is identifiable: what the named effect needs beside it, not the effect itself.
    nuisance: tuple[str, ...] = ()


# Rotor inertia's resolution: the inertia whose spin-up reaction leads the yaw drag torque by
# ROTOR_INERTIA_LEAD_RESOLUTION_S at hover. Near hover the yaw torque of rotor i moves as
# 2 ktau w_h dw + J_r d(dw)/dt, a lead of J_r / (2 ktau w_h) seconds (52 ms per 1e-5 kg m^2 on models/vehicle.yaml);
# 10 ms is the lag terms' own resolution, so the two are judged alike.
ROTOR_INERTIA_LEAD_RESOLUTION_S = 0.01
# Upper bound: a 300 ms lead, as the lag terms' 0.3 s.
ROTOR_INERTIA_MAX_LEAD_S = 0.3


def _rotor_inertia_resolution(v: VehicleConfig) -> float:
    return ROTOR_INERTIA_LEAD_RESOLUTION_S * 2.0 * v.ktau_nm_per_rad_s2 * v.hover_omega_rad_s


def _rotor_inertia_max(v: VehicleConfig) -> float:
    return ROTOR_INERTIA_MAX_LEAD_S / ROTOR_INERTIA_LEAD_RESOLUTION_S * _rotor_inertia_resolution(v)


# The rotor inertia as a term of its own: get, set, scale, lower, upper.
_ROTOR_INERTIA_ALONE = (
    lambda v: np.array([v.rotor_inertia_kg_m2]),
    lambda v, x: dataclasses.replace(v, rotor_inertia_kg_m2=float(x[0])),
    lambda v: np.array([_rotor_inertia_resolution(v)]),
    lambda _v: np.zeros(1),
    lambda v: np.array([_rotor_inertia_max(v)]),
)


def _const(*v: float) -> Callable[[VehicleConfig], np.ndarray]:
    return lambda _veh: np.array(v, dtype=np.float64)


def _set_cg(v: VehicleConfig, x: np.ndarray) -> VehicleConfig:
    return dataclasses.replace(v, cg_offset_frd_m=(float(x[0]), float(x[1]), v.cg_offset_frd_m[2]))


def _set_rotor_taus(v: VehicleConfig, x: np.ndarray) -> VehicleConfig:
    """Per-rotor time constants (s) written as their mean and each rotor's ratio to it; then the rotor inertia."""
    taus = x[:4]
    tau = float(np.mean(taus))
    return dataclasses.replace(
        v,
        motor_time_constant_s=tau,
        motor_time_constant_ratio=tuple(float(t) / tau for t in taus),
        rotor_inertia_kg_m2=float(x[4]),
    )


def _set_esc(v: VehicleConfig, x: np.ndarray) -> VehicleConfig:
    """RPM_true = gain * RPM_curve(cmd) + offset: rewritten as the same quadratic's coefficients."""
    e = v.esc
    gain, offset = float(x[0]), float(x[1])
    esc = dataclasses.replace(
        e, a_rpm_per_cmd2=gain * e.a_rpm_per_cmd2, b_rpm_per_cmd=gain * e.b_rpm_per_cmd, c_rpm=gain * e.c_rpm + offset
    )
    w_max = float(esc.cmd_to_omega_rad_s(esc.cmd_max))
    return dataclasses.replace(v, esc=esc, omega_max_rad_s=max(w_max, v.omega_min_rad_s + 1.0))


TERMS: dict[str, Term] = {
    t.name: t
    for t in (
        Term(
            "cg_offset",
            ("cg_x_m", "cg_y_m"),
            lambda v: np.array(v.cg_offset_frd_m[:2]),
            _set_cg,
            _const(0.004, 0.004),
            _const(-0.1, -0.1),
            _const(0.1, 0.1),
            ("cg_offset_frd_m",),
            "centre of gravity off the rotor centroid: a moment proportional to total thrust",
        ),
        Term(
            "motor_efficiency",
            ("eff_1", "eff_2", "eff_3", "eff_4"),
            lambda v: np.array(v.motor_efficiency),
            lambda v, x: dataclasses.replace(v, motor_efficiency=tuple(float(e) for e in x)),
            _const(0.01, 0.01, 0.01, 0.01),
            _const(0.5, 0.5, 0.5, 0.5),
            _const(1.5, 1.5, 1.5, 1.5),
            ("motor_efficiency",),
            "unequal motors/ESCs: each rotor reaches a scaled speed for its command",
        ),
        Term(
            "mass",
            ("mass_kg",),
            lambda v: np.array([v.mass_kg]),
            lambda v, x: dataclasses.replace(v, mass_kg=float(x[0])),
            lambda v: np.array([0.02 * v.mass_kg]),
            lambda v: np.array([0.3 * v.mass_kg]),
            lambda v: np.array([3.0 * v.mass_kg]),
            ("mass_kg",),
            "mass differs from the nominal (payload, battery): all rotors work harder alike",
        ),
        Term(
            "inertia",
            ("ixx_kg_m2", "iyy_kg_m2", "izz_kg_m2"),
            lambda v: np.array(v.inertia_diag_kg_m2),
            lambda v, x: dataclasses.replace(v, inertia_diag_kg_m2=tuple(float(i) for i in x)),
            lambda v: 0.1 * np.array(v.inertia_diag_kg_m2),
            lambda v: 0.2 * np.array(v.inertia_diag_kg_m2),
            lambda v: 5.0 * np.array(v.inertia_diag_kg_m2),
            ("inertia_diag_kg_m2",),
            "moments of inertia differ: angular accelerations scale per axis",
        ),
        Term(
            "motor_time_constant",
            ("motor_time_constant_s", "rotor_inertia_kg_m2"),
            lambda v: np.array([v.motor_time_constant_s, v.rotor_inertia_kg_m2]),
            lambda v, x: dataclasses.replace(v, motor_time_constant_s=float(x[0]), rotor_inertia_kg_m2=float(x[1])),
            lambda v: np.array([0.01, _rotor_inertia_resolution(v)]),
            _const(0.003, 0.0),
            lambda v: np.array([0.3, _rotor_inertia_max(v)]),
            ("motor_time_constant_s", "rotor_inertia_kg_m2"),
            "rotors lag the ESC command: moments trail the commands (the rotors' spin-up reaction, which leads the "
            "drag torque in yaw, fitted with the lag)",
            nuisance=("rotor_inertia_kg_m2",),
        ),
        Term(
            "rotor_time_constant",
            ("tau_1_s", "tau_2_s", "tau_3_s", "tau_4_s", "rotor_inertia_kg_m2"),
            lambda v: np.append(v.rotor_time_constants_s, v.rotor_inertia_kg_m2),
            _set_rotor_taus,
            lambda v: np.array([0.01, 0.01, 0.01, 0.01, _rotor_inertia_resolution(v)]),
            _const(0.003, 0.003, 0.003, 0.003, 0.0),
            lambda v: np.array([0.3, 0.3, 0.3, 0.3, _rotor_inertia_max(v)]),
            ("motor_time_constant_s", "motor_time_constant_ratio", "rotor_inertia_kg_m2"),
            "one rotor lags its ESC command more than the others (a slow motor or ESC): its moments trail (the "
            "rotors' spin-up reaction fitted with the lags)",
            nuisance=("rotor_inertia_kg_m2",),
        ),
        Term(
            "rotor_inertia",
            ("rotor_inertia_kg_m2",),
            *_ROTOR_INERTIA_ALONE,
            ("rotor_inertia_kg_m2",),
            "spinning a rotor up or down takes motor torque whose reaction yaws the body (rotor inertia x dω/dt): "
            "yaw leads the drag torque",
        ),
        Term(
            "drag",
            ("drag_x_n_per_m_s", "drag_y_n_per_m_s", "drag_z_n_per_m_s"),
            lambda v: np.array(v.linear_drag_n_per_m_s),
            lambda v, x: dataclasses.replace(v, linear_drag_n_per_m_s=tuple(float(d) for d in x)),
            _const(0.03, 0.03, 0.03),
            _const(0.0, 0.0, 0.0),
            _const(5.0, 5.0, 5.0),
            ("linear_drag_n_per_m_s",),
            "airframe drag: a force against the body velocity",
        ),
        Term(
            "esc_curve",
            ("rpm_gain", "rpm_offset"),
            lambda v: np.array([1.0, 0.0]),
            _set_esc,
            _const(0.02, 200.0),
            _const(0.5, -3000.0),
            _const(1.5, 3000.0),
            ("esc", "omega_max_rad_s"),
            "the ESC command-to-speed map differs from the load-cell fit",
        ),
        Term(
            "gyro_bias",
            ("bias_x_rad_s", "bias_y_rad_s", "bias_z_rad_s"),
            lambda v: np.array(v.gyro_bias_frd_rad_s),
            lambda v, x: dataclasses.replace(v, gyro_bias_frd_rad_s=tuple(float(b) for b in x)),
            _const(0.003, 0.003, 0.003),
            _const(-0.5, -0.5, -0.5),
            _const(0.5, 0.5, 0.5),
            ("gyro_bias_frd_rad_s",),
            "the gyro reads a constant offset",
        ),
    )
}


def without_spin_up(term: Term) -> Term:
    """A lag term as the library had it before the spin-up reaction joined it: the time constants alone, the rotor
    inertia left at the vehicle's value. For before/after comparisons (``bench/yaw_spinup.py``), not for selection."""
    if term.params[-1] != "rotor_inertia_kg_m2":
        raise ValueError(f"{term.name}: not a lag term fitted with the spin-up reaction")
    k = len(term.params) - 1
    return dataclasses.replace(
        term,
        params=term.params[:k],
        get=lambda v: term.get(v)[:k],
        set=lambda v, x: term.set(v, np.append(x, v.rotor_inertia_kg_m2)),
        scale=lambda v: term.scale(v)[:k],
        lower=lambda v: term.lower(v)[:k],
        upper=lambda v: term.upper(v)[:k],
        fields=tuple(f for f in term.fields if f != "rotor_inertia_kg_m2"),
        nuisance=(),
    )


def apply_terms(vehicle: VehicleConfig, terms: list[Term], x: np.ndarray) -> VehicleConfig:
    """Set each term's parameters (consecutive slices of ``x``) on ``vehicle``."""
    i = 0
    for t in terms:
        k = len(t.params)
        vehicle = t.set(vehicle, x[i : i + k])
        i += k
    return vehicle


def stacked(vehicle: VehicleConfig, terms: list[Term], what: str) -> np.ndarray:
    arrays = [getattr(t, what)(vehicle) for t in terms]
    return np.concatenate(arrays) if arrays else np.zeros(0)
