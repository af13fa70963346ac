"""Quad-X airframes of other sizes than the paper quad, and the ``strangers_*`` evaluation sets flown on them.

NEVER used for training or model selection (see the package docstring): they score whether propwatch diagnoses a
quad-X it was never told about, from its first flight.

Each airframe class is derived physically from a few design choices (mass, arm, propeller diameter and thrust
coefficient, motor time constant, thrust-to-weight ratio, pack):

- kF = C_T ρ D⁴ / (4π²) (thrust T = kF ω², ω in rad/s); kτ = kF (C_Q/C_T) D with the paper quad's C_Q/C_T
  (kτ/kF = 0.01517 m at D = 0.254 m, models/vehicle.yaml), so the drag torque per unit thrust grows with the
  propeller;
- hover ω_h = sqrt(m g / 4 kF), ω_max = ω_h sqrt(thrust-to-weight);
- the ESC is the paper's load-cell fit (``monitor.esc.PAPER_ESC``) scaled so 2000 us gives ω_max: the same curve
  shape, another motor KV; the controller knows this curve, so a command maps to the RPM the motor reaches;
- inertia as the paper quad's scaled by mass and arm² (the same mass distribution, another size);
- body drag (c_D) scaled by arm², rotor H-force (k_d) by D³;
- the controller's attitude and rate loops scaled to the motors: bandwidth k = sqrt(30 ms / τ_motor), clipped to
  0.75-1.5 (rate P and attitude P ∝ k, rate I ∝ k², rate D unchanged), its torques through the class's nominal
  inertia; its allocator gives up collective thrust before roll and pitch, as PX4's does. Attitude error (angle
  between the body z axis and its setpoint; README.md): RMS 2-5° on gentle routes as the paper quad's 4°, 7-17° on
  hard manoeuvres where the heavy classes saturate.

Every flight's airframe is a class drawn with quirks as ``vehicles`` has them: motor thrust efficiency ±4-8 %, a CG
offset of up to ``CG_ARM_FRACTION_MAX`` of the arm in a random direction, inertia ±10 % per axis, motor lag ×0.85-1.6.
A payload of 0 to +25 % of the mass sits off the CG (up to ``PAYLOAD_ARM_FRACTION_MAX`` of the arm): it moves the CG
and adds its own inertia. The controller knows the class only (its file), never the quirks or payload.

Hard manoeuvres: PX4's default horizontal speed (12 m/s), 40° tilt and 3 m/s climbs, so the heavier classes
saturate their outputs on some flights (``saturated_fraction`` in truth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from monitor.esc import PAPER_ESC, RPM_PER_RAD_S, EscCurve
from monitor.resample import US_PER_S
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.evalsim.airframe import Airframe, Damage
from offline.evalsim.controller import ControllerGains
from offline.evalsim.flight import FlightSpec, truth
from offline.evalsim.names import STRANGER_SETS
from offline.evalsim.sets import DAY_US, _damage, _gusty_wind, _light_wind, _rng, _spec, write_json
from offline.fleet_sim import UID_BASE, append_autopilot_version
from offline.sim.io_tlog import DEFAULT_WALL_BOOT_US, write_tlog
from offline.sim.log import BOOT_OFFSET_US, FlightLog

AIR_DENSITY_KG_M3 = 1.225  # ISA sea level
G_M_S2 = 9.81  # RotorPy's gravity (the body's)
# The paper quad's drag torque per unit thrust per metre of propeller: kτ/kF / D = (1.632e-7 / 1.076e-5) / 0.254 m
# (models/vehicle.yaml; 10-inch propellers assumed for Tong et al.'s quad).
TORQUE_PER_THRUST_PER_DIAMETER = (1.632e-7 / 1.076e-5) / 0.254
NOMINAL_ARM_M = 0.16  # models/vehicle.yaml arm_length_m: the reference for scaling inertia and drag
NOMINAL_PROP_DIAMETER_M = 0.254
NOMINAL_MOTOR_TIME_CONSTANT_S = 0.03  # evalsim's paper-quad motors (Airframe default), for which the gains were set

CG_ARM_FRACTION_MAX = 0.09  # quirk CG offset radius / arm (vehicles: ±1 cm per axis on a 0.16 m arm, i.e. up to 0.09)
PAYLOAD_FRACTION = (0.0, 0.25)  # payload mass / airframe mass
PAYLOAD_ARM_FRACTION_MAX = 0.35  # payload's horizontal distance from the airframe's CG / arm
ONSET_LOSS = (0.06, 0.20)  # in-air single-propeller thrust loss at hover
TAKEOFF_LOSS = (0.10, 0.25)  # damage present from take-off
MEMORY_LOSS = (0.06, 0.20)
STOP_TAIL_S = 2.0  # a stopped-motor flight's log ends this long after the stop (falling, no ground: a real one crashes)
HARD_EVERY = 4  # one healthy flight in HARD_EVERY flies hard manoeuvres
MEMORY_FLIGHTS = 12  # per airframe of ``strangers_memory``
MEMORY_REFERENCES = 3
MEMORY_HEALTHY_LATER = (0, 3, 6, 8)  # later flights (k - MEMORY_REFERENCES) that stay healthy; j = 6 flies hard
MEMORY_HARD_LATER = (6,)
MEMORY_ONSET_LATER = (2, 5)  # later flights whose propeller is damaged in the air; the rest: from take-off
SATURATION_MARGIN_US = 1.0  # an output within this of the ESC's command limits counts as saturated


@dataclass(frozen=True)
class StrangerClass:
    """The design of one airframe size (SI). Everything else is derived (module docstring)."""

    name: str
    mass_kg: float
    arm_m: float
    prop_diameter_m: float
    thrust_coefficient: float  # C_T in T = C_T ρ n² D⁴ (n rev/s)
    motor_time_constant_s: float
    thrust_to_weight: float
    battery_capacity_mah: float
    battery_internal_resistance_ohm: float

    @property
    def kf_n_per_rad_s2(self) -> float:
        return self.thrust_coefficient * AIR_DENSITY_KG_M3 * self.prop_diameter_m**4 / (4 * math.pi**2)

    @property
    def ktau_nm_per_rad_s2(self) -> float:
        return self.kf_n_per_rad_s2 * TORQUE_PER_THRUST_PER_DIAMETER * self.prop_diameter_m

    @property
    def hover_omega_rad_s(self) -> float:
        return math.sqrt(self.mass_kg * G_M_S2 / (4 * self.kf_n_per_rad_s2))

    @property
    def omega_max_rad_s(self) -> float:
        return self.hover_omega_rad_s * math.sqrt(self.thrust_to_weight)

    @property
    def control_bandwidth_scale(self) -> float:
        return float(np.clip(math.sqrt(NOMINAL_MOTOR_TIME_CONSTANT_S / self.motor_time_constant_s), 0.75, 1.5))


# Propeller sizes fit the arm (a quad-X's neighbouring hubs are arm * sqrt(2) apart); C_T of two-blade propellers
# 0.075-0.095, of the 6-inch three-blade 0.125; thrust-to-weight falls with size as on real builds.
STRANGER_CLASSES = (
    StrangerClass("micro-6in", 0.50, 0.11, 0.152, 0.125, 0.015, 4.0, 1000.0, 0.045),
    StrangerClass("quad-7in", 0.70, 0.14, 0.178, 0.095, 0.020, 3.5, 1500.0, 0.035),
    StrangerClass("longarm-9in", 1.00, 0.20, 0.229, 0.085, 0.030, 3.0, 2200.0, 0.030),
    StrangerClass("heavy-12in", 2.00, 0.225, 0.305, 0.082, 0.045, 2.5, 5000.0, 0.020),
    StrangerClass("large-15in", 2.80, 0.30, 0.381, 0.075, 0.060, 2.2, 8000.0, 0.015),
)


def esc_for(c: StrangerClass) -> EscCurve:
    """The paper's ESC curve scaled so its top command gives the class's ω_max."""
    s = c.omega_max_rad_s * RPM_PER_RAD_S / float(PAPER_ESC.cmd_to_rpm(PAPER_ESC.cmd_max))
    e = PAPER_ESC
    return EscCurve(e.a_rpm_per_cmd2 * s, e.b_rpm_per_cmd * s, e.c_rpm * s, e.cmd_min, e.cmd_max, e.cmd_unit)


def nominal_airframe(c: StrangerClass) -> Airframe:
    """The class as its file would say: no quirk, no payload."""
    h = c.arm_m / math.sqrt(2.0)
    size = (c.mass_kg / 1.5) * (c.arm_m / NOMINAL_ARM_M) ** 2
    esc = esc_for(c)
    return Airframe(
        mass_kg=c.mass_kg,
        inertia_diag_kg_m2=(0.0123 * size, 0.0123 * size, 0.0224 * size),
        rotor_positions_frd_m=((h, h, 0.0), (-h, -h, 0.0), (h, -h, 0.0), (-h, h, 0.0)),
        rotor_spin=("ccw", "ccw", "cw", "cw"),
        kf_n_per_rad_s2=c.kf_n_per_rad_s2,
        ktau_nm_per_rad_s2=c.ktau_nm_per_rad_s2,
        hover_omega_rad_s=c.hover_omega_rad_s,
        omega_min_rad_s=float(esc.cmd_to_rpm(esc.cmd_min)) / RPM_PER_RAD_S,
        omega_max_rad_s=c.omega_max_rad_s,
        motor_time_constant_s=(c.motor_time_constant_s,) * 4,
        drag_quadratic_n_per_m2_s2=tuple(x * (c.arm_m / NOMINAL_ARM_M) ** 2 for x in (0.02, 0.02, 0.04)),
        rotor_drag_kg_per_rad=2.0e-5 * (c.prop_diameter_m / NOMINAL_PROP_DIAMETER_M) ** 3,
        esc=esc,
        battery_capacity_mah=c.battery_capacity_mah,
        battery_internal_resistance_ohm=c.battery_internal_resistance_ohm,
    )


def gains_for(c: StrangerClass, hard: bool) -> ControllerGains:
    """evalsim's gains with the attitude and rate loops scaled to the class's motors; ``hard``: PX4's default speed
    and climb limits, 40° tilt."""
    g, k = ControllerGains(), c.control_bandwidth_scale
    g = replace(
        g,
        att_rp_p=g.att_rp_p * k,
        att_yaw_p=g.att_yaw_p * k,
        rate_rp_p=g.rate_rp_p * k,
        rate_rp_i=g.rate_rp_i * k * k,
        rate_yaw_p=g.rate_yaw_p * k,
        rate_yaw_i=g.rate_yaw_i * k * k,
        collective_yields=True,
    )
    if hard:
        g = replace(g, vel_xy_max_m_s=12.0, vel_z_max_m_s=3.0, tilt_max_rad=float(np.deg2rad(40.0)))
    return g


def quirky(c: StrangerClass, rng: np.random.Generator) -> Airframe:
    """The class with one airframe's quirks (motor spread, CG, inertia error, motor lag), drawn from ``rng``."""
    af = nominal_airframe(c)
    spread = rng.uniform(0.04, 0.08)
    eff = tuple(float(x) for x in 1.0 + rng.uniform(-spread, spread, 4))
    r, a = rng.uniform(0.0, CG_ARM_FRACTION_MAX) * c.arm_m, rng.uniform(0.0, 2 * np.pi)
    inertia = np.asarray(af.inertia_diag_kg_m2) * (1.0 + rng.uniform(-0.1, 0.1, 3))
    lag = c.motor_time_constant_s * rng.uniform(0.85, 1.6, 4)
    return af.with_(
        motor_thrust_efficiency=eff,
        cg_offset_frd_m=(float(r * np.cos(a)), float(r * np.sin(a)), 0.0),
        inertia_diag_kg_m2=tuple(float(x) for x in inertia),
        motor_time_constant_s=tuple(float(x) for x in lag),
    )


def with_payload(af: Airframe, c: StrangerClass, fraction: float, rng: np.random.Generator) -> Airframe:
    """``af`` carrying ``fraction`` of its mass as a point mass off its CG: the CG moves towards it, its inertia adds
    (parallel axes), and damage is specified at the loaded hover speed."""
    m, mp = af.mass_kg, fraction * af.mass_kg
    r, a = rng.uniform(0.0, PAYLOAD_ARM_FRACTION_MAX) * c.arm_m, rng.uniform(0.0, 2 * np.pi)
    cg0 = np.asarray(af.cg_offset_frd_m)
    p = cg0 + np.array([r * np.cos(a), r * np.sin(a), 0.0])
    cg = (m * cg0 + mp * p) / (m + mp)
    d0, dp = cg0 - cg, p - cg  # the airframe's and the payload's CG relative to the new CG
    extra = [m * (d0[1] ** 2 + d0[2] ** 2) + mp * (dp[1] ** 2 + dp[2] ** 2)]
    extra.append(m * (d0[0] ** 2 + d0[2] ** 2) + mp * (dp[0] ** 2 + dp[2] ** 2))
    extra.append(m * (d0[0] ** 2 + d0[1] ** 2) + mp * (dp[0] ** 2 + dp[1] ** 2))
    return af.with_(
        payload_kg=float(mp),
        cg_offset_frd_m=tuple(float(x) for x in cg),
        inertia_diag_kg_m2=tuple(float(i + e) for i, e in zip(af.inertia_diag_kg_m2, extra, strict=True)),
        hover_omega_rad_s=math.sqrt((m + mp) * G_M_S2 / (4 * af.kf_n_per_rad_s2)),
    )


def _single_damage(rng: np.random.Generator, rotor: int, loss_range, onset_s: float = 0.0) -> Damage:
    dmg = _damage(rng, (rotor,), "bent" if rng.random() < 0.5 else "cracked", onset_s)
    loss = float(rng.uniform(*loss_range))
    return replace(dmg, thrust_loss_at_hover=tuple(loss if p + 1 == rotor else 0.0 for p in range(4)))


def _stranger_spec(set_name, seed, i, c, af, rng, duration_s, *, hard=False, wind=None, nuisance="", airframe_id=""):
    gains = gains_for(c, hard)
    if wind is None:
        wind = _gusty_wind(rng) if rng.random() < 0.4 else _light_wind(rng)
    return _spec(
        set_name,
        seed,
        i,
        af,
        rng,
        duration_s,
        wind=wind,
        nuisance=nuisance or ("hard" if hard else "gentle"),
        airframe_id=airframe_id or f"{set_name}-{i:04d}-{c.name}",
        vel_xy_max_m_s=gains.vel_xy_max_m_s,
        nominal=nominal_airframe(c),
        gains=gains,
    )


def _one_off(set_name: str, seed: int, i: int, cls: int) -> tuple[StrangerClass, Airframe, np.random.Generator]:
    """A flight's own airframe (class ``cls`` with its quirks and a payload), and the flight's generator."""
    rng = _rng(set_name, seed, i)
    c = STRANGER_CLASSES[cls % len(STRANGER_CLASSES)]
    af = quirky(c, rng)
    return c, with_payload(af, c, float(rng.uniform(*PAYLOAD_FRACTION)), rng), rng


def _healthy(v, seed, i, duration_s) -> FlightSpec:
    c, af, rng = _one_off("strangers_healthy", seed, i, i)
    hard = (i // len(STRANGER_CLASSES)) % HARD_EVERY == HARD_EVERY - 1
    return _stranger_spec("strangers_healthy", seed, i, c, af, rng, duration_s, hard=hard)


def _onset(v, seed, i, duration_s) -> FlightSpec:
    c, af, rng = _one_off("strangers_onset", seed, i, i // 4)
    dmg = _single_damage(rng, i % 4 + 1, ONSET_LOSS, float(rng.uniform(0.3, 0.6) * duration_s))
    return _stranger_spec("strangers_onset", seed, i, c, af.with_(damage=dmg), rng, duration_s)


def _takeoff(v, seed, i, duration_s) -> FlightSpec:
    c, af, rng = _one_off("strangers_takeoff", seed, i, i // 4)
    dmg = _single_damage(rng, i % 4 + 1, TAKEOFF_LOSS)
    return _stranger_spec("strangers_takeoff", seed, i, c, af.with_(damage=dmg), rng, duration_s)


def _stopped(v, seed, i, duration_s) -> FlightSpec:
    c, af, rng = _one_off("strangers_stopped", seed, i, i // 4)
    stop_s = float(rng.uniform(0.35, 0.75) * duration_s)
    af = af.with_(motor_stop_rotor=i % 4 + 1, motor_stop_time_s=stop_s)
    spec = _stranger_spec("strangers_stopped", seed, i, c, af, rng, duration_s)
    return replace(spec, duration_s=min(duration_s, stop_s + STOP_TAIL_S))


def _memory(v, seed, i, duration_s) -> FlightSpec:
    """Airframe a = i // MEMORY_FLIGHTS (class a mod 5, its quirks drawn once): 3 healthy references without payload
    in light wind, then later flights with a payload of 0 to +25 % placed anew each time, healthy (one hard) or one
    propeller damaged from take-off or in the air."""
    a, k = divmod(i, MEMORY_FLIGHTS)
    c = STRANGER_CLASSES[a % len(STRANGER_CLASSES)]
    af = quirky(c, _rng("strangers_memory", seed, 100_000 + a))
    rng = _rng("strangers_memory", seed, i)
    aid = f"strangers-memory-{a:03d}-{c.name}"
    if k < MEMORY_REFERENCES:
        return _stranger_spec(
            "strangers_memory", seed, i, c, af, rng, duration_s, wind=_light_wind(rng), nuisance="reference", airframe_id=aid
        )
    j = k - MEMORY_REFERENCES
    af = with_payload(af, c, float(rng.uniform(*PAYLOAD_FRACTION)), rng)
    if j not in MEMORY_HEALTHY_LATER:
        onset = float(rng.uniform(0.3, 0.6) * duration_s) if j in MEMORY_ONSET_LATER else 0.0
        af = af.with_(damage=_single_damage(rng, (a + j) % 4 + 1, MEMORY_LOSS, onset))
    hard = j in MEMORY_HARD_LATER
    return _stranger_spec("strangers_memory", seed, i, c, af, rng, duration_s, hard=hard, nuisance="later", airframe_id=aid)


BUILDERS = {
    # name -> (builder, default flight count: one cycle)
    "strangers_healthy": (_healthy, len(STRANGER_CLASSES) * HARD_EVERY),
    "strangers_onset": (_onset, 4 * len(STRANGER_CLASSES)),
    "strangers_takeoff": (_takeoff, 4 * len(STRANGER_CLASSES)),
    "strangers_stopped": (_stopped, 4 * len(STRANGER_CLASSES)),
    "strangers_memory": (_memory, MEMORY_FLIGHTS * len(STRANGER_CLASSES)),
}
if tuple(BUILDERS) != STRANGER_SETS:
    raise RuntimeError("offline.evalsim.strangers: BUILDERS and names.STRANGER_SETS disagree")


def class_of(spec: FlightSpec) -> StrangerClass:
    return next(c for c in STRANGER_CLASSES if nominal_airframe(c) == spec.nominal)


def uid_of(set_name: str, seed: int, spec: FlightSpec) -> int:
    """The AUTOPILOT_VERSION uid of the flight's airframe: one per airframe (``airframe_id``), per set and seed."""
    code = STRANGER_SETS.index(set_name) + 1
    h = np.random.SeedSequence([seed, code, *spec.airframe_id.encode()]).generate_state(1)[0]
    return UID_BASE | (0x20 + code) << 40 | int(h)


def flight_day(set_name: str, i: int) -> int:
    """Days after the first flight of the set: each flight its own date (``strangers_memory``: per airframe)."""
    return i % MEMORY_FLIGHTS if set_name == "strangers_memory" else i


def saturated_fraction(log: FlightLog, esc: EscCurve, before_s: float = np.inf) -> float:
    """Share of samples before ``before_s`` whose ESC command of some rotor sits at a command limit."""
    pwm = log.pwm_us[0][log.time_s < before_s]
    at = (pwm >= esc.cmd_max - SATURATION_MARGIN_US) | (pwm <= esc.cmd_min + SATURATION_MARGIN_US)
    return float(at.any(axis=1).mean()) if len(pwm) else 0.0


def stranger_truth(set_name: str, seed: int, i: int, spec: FlightSpec, log: FlightLog, file: str, uid: int) -> dict:
    """``flight.truth`` plus what a ``strangers_*`` score reads: the class, payload, CG offset, onset and stop on the
    boot clock, and what the log shows (saturation, hover command and RPM)."""
    c, af = class_of(spec), spec.airframe
    t = truth(spec, file=file)
    boot_s = BOOT_OFFSET_US / US_PER_S
    cg = float(np.hypot(*af.cg_offset_frd_m[:2]))
    stop = af.motor_stop_rotor
    onset = af.damage.onset_time_s if af.damage.faulty and af.damage.onset_time_s > 0 else None  # None: from take-off
    reference = load_vehicle(DEFAULT_VEHICLE).hover_omega_rad_s
    events = ([onset] if onset is not None else []) + ([af.motor_stop_time_s] if stop else [])
    first_event = min(events, default=np.inf)
    esc = spec.nominal.esc
    calm = log.time_s < min(first_event, 10.0)
    t.update(
        {
            "set": set_name,
            "set_seed": seed,
            "index": i,
            "airframe_class": c.name,
            "class_mass_kg": c.mass_kg,
            "arm_m": c.arm_m,
            "prop_diameter_m": c.prop_diameter_m,
            "hover_rpm_ratio": c.hover_omega_rad_s / reference,
            "hover_rpm_ratio_loaded": af.hover_omega_rad_s / reference,
            "payload_fraction": af.payload_kg / af.mass_kg,
            "cg_offset_m": cg,
            "cg_offset_arm_fraction": cg / c.arm_m,
            "hard_manoeuvre": spec.nuisance == "hard" or spec.controller_gains.vel_xy_max_m_s > 3.0,
            "fault_onset_boot_s": boot_s + onset if onset is not None else None,
            "stopped_motor": stop,
            "stop_time_s": af.motor_stop_time_s if stop else None,
            "stop_boot_s": boot_s + af.motor_stop_time_s if stop else None,
            "uid": uid,
            "saturated_fraction": saturated_fraction(log, esc, first_event),
            "first_10s_median_cmd_us": float(np.median(log.pwm_us[0][calm])),
            "first_10s_median_rpm": float(np.median(log.motor_omega_rad_s[0][calm]) * RPM_PER_RAD_S),
            "controller_gains": {k: float(v) for k, v in spec.controller_gains.__dict__.items()},
        }
    )
    return t


def write_flight(set_name: str, seed: int, i: int, spec: FlightSpec, log: FlightLog, out: Path) -> dict:
    """One flight's .tlog (landing and disarm at the end, its date, its airframe's uid) and truth JSON; the truth."""
    tlog = out / f"{spec.name}.tlog"
    af = spec.airframe
    write_tlog(
        tlog,
        log,
        0,
        wall_boot_us=DEFAULT_WALL_BOOT_US + flight_day(set_name, i) * DAY_US,
        battery_full_v=af.battery_full_v,
        battery_capacity_mah=af.battery_capacity_mah,
        landing=True,
    )
    uid = uid_of(set_name, seed, spec)
    append_autopilot_version(tlog, uid)
    t = stranger_truth(set_name, seed, i, spec, log, tlog.name, uid)
    write_json(out / f"{spec.name}.json", t)
    return t


__all__ = ["BUILDERS", "STRANGER_CLASSES", "StrangerClass", "nominal_airframe", "write_flight"]
