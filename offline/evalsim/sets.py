"""Named, seeded, deterministic evaluation sets: lists of ``FlightSpec``, and a writer to a folder.

NEVER used for training or model selection (see the package docstring).

| set | what varies |
| paper | 1.5 kg paper quad, new routes, all 16 labels, evalsim's own bent/cracked-like damage |
| shift | as paper + 30 % payload, motor efficiency spread ±4-8 %, CG offset ±1 cm, inertia error ±10 %, gusty wind |
| shift_half, shift_quarter | ``shift`` flight for flight with the airframe spread (motor, CG, inertia) halved /
  quartered: how localisation degrades as the airframe leaves its file |
| healthy | healthy flights, each with ONE nuisance (``NUISANCES``) |
| onset | a fault (single propeller or pair, 5-20 % thrust loss) starting mid-flight at a recorded time |
| hidden | per airframe one hidden effect (CG, weak motor, motor lag, linear drag, ESC curve): 2 healthy + 4 single faults |
| effectiveness | one rotor losing exactly 5, 10 or 20 % thrust, torque per thrust unchanged or falling |
| forward_flight | healthy flights at up to 10 m/s with blade flapping drawn from 0 to the forward-flight trim of a
  real hard-flown quad (ArduPilot log171, ``FLAPPING_MAX``): the aerodynamic trim neither simulator had before |
| vehicles | vehicle memory: airframe a = i // 12 drawn like ``shift`` (motors ±4-8 %, CG ±1 cm, inertia ±10 %) plus
  motor lag 25-50 ms; its flights 3 healthy references (no payload, light wind), then 9 later ones (payload 0 to
  +25 %, light or gusty wind, new routes): 4 healthy and 5 with one propeller damaged from take-off (thrust loss
  3-20 %); each ends in landing and disarm, one day after the last, with the airframe's own AUTOPILOT_VERSION uid |
| paper_torque_rising | CONTROL: ``paper`` flight for flight (same seeds, routes, losses) but the damaged blade's
  drag torque at equal speed RISES by |δ| (training's ``torque_factor = 1 + gain``) instead of its torque per
  thrust falling by |δ| |
| strangers_healthy | quad-X airframes of other sizes (``strangers.STRANGER_CLASSES``: 0.5-2.8 kg, arms 0.11-0.30 m,
  hover RPM x0.64-1.32 of the nominal), class i mod 5, each flight its own quirks (motors ±4-8 %, CG up to 0.09 arm,
  inertia ±10 %, motor lag x0.85-1.6) and payload (0 to +25 % of the mass, off the CG); one flight in 4 of each class
  flies hard manoeuvres (12 m/s, 40° tilt, 3 m/s climbs; the heavy classes saturate outputs). Healthy |
| strangers_onset | as strangers_healthy (gentle), class (i // 4) mod 5, propeller i mod 4 + 1 loses 6-20 % thrust at
  hover from a recorded time (30-60 % of the flight; ``fault_onset_boot_s`` in truth) |
| strangers_takeoff | the same, propeller i mod 4 + 1 damaged from take-off, 10-25 % loss; ``cg_offset_m`` and
  ``cg_offset_arm_fraction`` (quirk and payload together) in truth |
| strangers_stopped | the same, motor i mod 4 + 1's output forced to the ESC's minimum at a recorded time (35-75 % of
  the flight; ``stop_boot_s``), the log ending ``strangers.STOP_TAIL_S`` later |
| strangers_memory | airframe a = i // 12 (class a mod 5, quirks drawn once): 3 healthy references (no payload, light
  wind), then 9 later flights with a payload of 0 to +25 % placed anew each time: 4 healthy (one hard), 3 with one
  propeller damaged from take-off and 2 damaged in the air (6-20 % loss) |

Every ``strangers_*`` flight ends in landing and disarm, carries its airframe's own AUTOPILOT_VERSION uid and its own
date (``strangers_memory``: one per airframe, a day apart), and its truth records the class, payload, CG offset,
onset/stop on the boot clock and the share of samples with an output at its limit (``saturated_fraction``).
Evaluation seed: ``names.STRANGERS_EVAL_SEED``, committed before the first-flight thresholds were set; develop on
``names.STRANGERS_DEV_SEED``.

``flights`` is the number of flights; labels / nuisances / patterns cycle, so
``flights=32`` on ``paper`` gives every label twice. Flight i of a set depends
only on (set, seed, i): asking for more flights extends a set.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from monitor.esc import EscCurve
from monitor.labels import LABEL_TABLE
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.evalsim.airframe import Airframe, Damage
from offline.evalsim.environment import Sensors, Telemetry, Wind
from offline.evalsim.flight import FlightSpec, simulate_flights, truth
from offline.evalsim.names import DEFAULT_DURATION_S, SET_NAMES
from offline.fleet_sim import append_autopilot_version, vehicle_uid
from offline.manifest import make_manifest, write_manifest
from offline.sim.io_tlog import DEFAULT_WALL_BOOT_US, write_tlog

_SET_CODES = {n: i + 101 for i, n in enumerate(SET_NAMES)}
BATCH = 32  # flights integrated together (memory ~ BATCH * duration)

# Route box (NED, m): new routes, not offline/sim's box (±15 m, 4..16 m up).
ROUTE_BOX_NED_M = ((-20.0, 20.0), (-20.0, 20.0), (-14.0, -6.0))
N_WAYPOINTS = 5

NUISANCES = (
    "route",
    "payload",
    "wind_gusts",
    "body_drag",
    "cg_offset",
    "slow_motor",
    "weak_motor",
    "battery_sag",
    "imu_noise",
    "inertia",
    "payload_pickup",
)
HIDDEN_EFFECTS = ("cg_offset", "weak_motor", "motor_lag", "linear_drag", "esc_curve")
ONSET_PATTERNS = ((1,), (2,), (3,), (4,), (1, 2), (1, 3), (1, 4), (2, 3), (2, 4), (3, 4))
EFFECTIVENESS_LOSSES = (0.05, 0.10, 0.20)

# The damage ranges (each damaged rotor draws its own values). Torque per unit thrust FALLS
# (training assumed +2..+10 %); thrust loss constant or falling with speed.
DAMAGE_RANGES = {
    "bent": {
        "thrust_loss_at_hover": (0.08, 0.13),
        "loss_speed_exponent": (0.0, 0.5),
        "torque_per_thrust_change": (-0.08, -0.02),
        "flutter_thrust_std": (0.005, 0.01),
        "vibration_1p_m_s2": (0.4, 1.0),
    },
    "cracked": {
        "thrust_loss_at_hover": (0.12, 0.20),
        "loss_speed_exponent": (0.0, 0.3),
        "torque_per_thrust_change": (-0.12, -0.04),
        "flutter_thrust_std": (0.01, 0.03),
        "vibration_1p_m_s2": (0.2, 0.6),
    },
}


def flight_seed(set_name: str, seed: int, i: int) -> int:
    return int(np.random.SeedSequence([seed, _SET_CODES[set_name], i]).generate_state(1)[0])


def _rng(set_name: str, seed: int, i: int) -> np.random.Generator:
    return np.random.default_rng([seed, _SET_CODES[set_name], i, 7])


def _route(rng: np.random.Generator) -> tuple[tuple[float, float, float], ...]:
    box = np.asarray(ROUTE_BOX_NED_M)
    wps = box[:, 0] + rng.random((N_WAYPOINTS, 3)) * (box[:, 1] - box[:, 0])
    return tuple(tuple(float(x) for x in w) for w in wps)


def _damage(rng: np.random.Generator, faulty: tuple[int, ...], kind: str, onset_s: float = 0.0) -> Damage:
    ranges = DAMAGE_RANGES[kind]
    vals = {k: [0.0] * 4 for k in ranges}
    for p in faulty:
        for k, (lo, hi) in ranges.items():
            vals[k][p - 1] = float(rng.uniform(lo, hi))
    return Damage(**{k: tuple(v) for k, v in vals.items()}, onset_time_s=onset_s)


def _base(v, rng: np.random.Generator, spread: float = 0.01) -> Airframe:
    """The paper quad with a small healthy motor spread (±``spread`` thrust efficiency)."""
    eff = tuple(float(x) for x in 1.0 + rng.uniform(-spread, spread, 4))
    return Airframe.from_vehicle(v, motor_thrust_efficiency=eff)


def _light_wind(rng: np.random.Generator) -> Wind:
    heading = rng.uniform(0, 2 * np.pi)
    speed = rng.uniform(0.0, 1.5)
    return Wind(mean_ned_m_s=(speed * np.cos(heading), speed * np.sin(heading), 0.0), gust_std_m_s=(0.2, 0.2, 0.1))


def _gusty_wind(rng: np.random.Generator) -> Wind:
    heading = rng.uniform(0, 2 * np.pi)
    speed = rng.uniform(2.0, 5.0)
    g = rng.uniform(0.8, 1.5)
    return Wind(mean_ned_m_s=(speed * np.cos(heading), speed * np.sin(heading), 0.0), gust_std_m_s=(g, g, 0.5 * g))


def _spec(set_name, seed, i, af, rng, duration_s, wind=None, **kw) -> FlightSpec:
    return FlightSpec(
        name=f"{set_name}_{i:04d}",
        airframe=af,
        waypoints_ned_m=_route(rng),
        duration_s=duration_s,
        seed=flight_seed(set_name, seed, i),
        wind=wind if wind is not None else _light_wind(rng),
        **kw,
    )


def _paper(v, seed, i, duration_s) -> FlightSpec:
    rng = _rng("paper", seed, i)
    label = i % 16 + 1
    kind = "bent" if (i // 16) % 2 == 0 else "cracked"
    af = _base(v, rng).with_(damage=_damage(rng, LABEL_TABLE[label], kind))
    return _spec("paper", seed, i, af, rng, duration_s, nuisance=kind)


def _paper_torque_rising(v, seed, i, duration_s) -> FlightSpec:
    """``paper``'s flight i with the damaged blade's drag torque RISING by |δ| at equal speed, as training's
    ``torque_factor = 1 + gain`` (offline/sim/faults.py): per unit thrust that is
    (1 + |δ|) / (1 - loss) - 1, i.e. +10..+35 % where ``paper`` has -2..-12 %."""
    spec = _paper(v, seed, i, duration_s)
    d = spec.airframe.damage
    change = tuple(
        (1.0 + abs(dq)) / (1.0 - loss) - 1.0 if loss > 0 else 0.0
        for dq, loss in zip(d.torque_per_thrust_change, d.thrust_loss_at_hover, strict=True)
    )
    rising = replace(d, torque_per_thrust_change=change)
    return replace(spec, name=f"paper_torque_rising_{i:04d}", airframe=spec.airframe.with_(damage=rising))


def _shift_scaled(scale: float, set_name: str) -> Callable:
    """``shift`` with its airframe spread (motor efficiency, CG offset, inertia error) scaled by ``scale``; the
    routes, payload, damage, wind and noise are ``shift``'s flight for flight (same random draws, same flight
    seeds), so a set of scale 0.25 differs from ``shift`` only in how far the airframe is from its file."""

    def build(v, seed, i, duration_s) -> FlightSpec:
        rng = _rng("shift", seed, i)
        label = i % 16 + 1
        kind = "bent" if (i // 16) % 2 == 0 else "cracked"
        spread = scale * rng.uniform(0.04, 0.08)
        af = _base(v, rng, spread)
        cg = (float(scale * rng.uniform(-0.01, 0.01)), float(scale * rng.uniform(-0.01, 0.01)), 0.0)
        inertia = np.asarray(v.inertia_diag_kg_m2) * (1 + scale * rng.uniform(-0.1, 0.1, 3))
        af = af.with_(
            payload_kg=0.3 * v.mass_kg,
            cg_offset_frd_m=cg,
            inertia_diag_kg_m2=tuple(float(x) for x in inertia),
            damage=_damage(rng, LABEL_TABLE[label], kind),
        )
        spec = _spec("shift", seed, i, af, rng, duration_s, wind=_gusty_wind(rng), nuisance=kind)
        return spec if set_name == "shift" else replace(spec, name=f"{set_name}_{i:04d}")

    return build


_shift = _shift_scaled(1.0, "shift")


def _with_nuisance(af: Airframe, v, rng: np.random.Generator, name: str, duration_s: float):
    """(airframe, wind or None, sensors or None) with the one nuisance ``name`` applied."""
    wind = sensors = None
    if name == "payload":
        af = af.with_(payload_kg=0.3 * v.mass_kg)
    elif name == "wind_gusts":
        wind = _gusty_wind(rng)
    elif name == "body_drag":
        af = af.with_(drag_quadratic_n_per_m2_s2=(0.12, 0.12, 0.2), rotor_drag_kg_per_rad=8e-5)
    elif name == "cg_offset":
        r, a = rng.uniform(0.015, 0.025), rng.uniform(0, 2 * np.pi)
        af = af.with_(cg_offset_frd_m=(float(r * np.cos(a)), float(r * np.sin(a)), 0.0))
    elif name in ("slow_motor", "motor_lag"):
        tau = list(af.motor_time_constant_s)
        tau[int(rng.integers(4))] = float(rng.uniform(0.045, 0.075))
        af = af.with_(motor_time_constant_s=tuple(tau))
    elif name == "weak_motor":
        eff = list(af.motor_thrust_efficiency)
        eff[int(rng.integers(4))] *= 0.94
        af = af.with_(motor_thrust_efficiency=tuple(eff))
    elif name == "battery_sag":
        af = af.with_(battery_start_soc=0.35, battery_internal_resistance_ohm=0.06, esc_rpm_per_volt=0.03)
    elif name == "imu_noise":
        s = Sensors()
        sensors = replace(
            s,
            gyro_noise_std_rad_s=4 * s.gyro_noise_std_rad_s,
            gyro_bias_std_rad_s=3 * s.gyro_bias_std_rad_s,
            accel_noise_std_m_s2=4 * s.accel_noise_std_m_s2,
            attitude_noise_std_rad=3 * s.attitude_noise_std_rad,
        )
    elif name == "inertia":
        af = af.with_(inertia_diag_kg_m2=tuple(float(x) * 1.25 for x in af.inertia_diag_kg_m2))
    elif name == "payload_pickup":
        af = af.with_(payload_kg=0.3 * v.mass_kg, payload_pickup_time_s=float(rng.uniform(0.3, 0.5) * duration_s))
    elif name == "linear_drag":
        af = af.with_(rotor_drag_kg_per_rad=float(rng.uniform(1.0e-4, 2.0e-4)))
    elif name == "esc_curve":
        e = af.esc
        gain = rng.uniform(0.96, 0.98) if rng.random() < 0.5 else rng.uniform(1.02, 1.04)
        af = af.with_(
            esc=EscCurve(e.a_rpm_per_cmd2 * gain, e.b_rpm_per_cmd * gain, e.c_rpm * gain, e.cmd_min, e.cmd_max, e.cmd_unit)
        )
    elif name != "route":
        raise ValueError(f"unknown nuisance {name!r}")
    return af, wind, sensors


def _healthy(v, seed, i, duration_s) -> FlightSpec:
    rng = _rng("healthy", seed, i)
    name = NUISANCES[i % len(NUISANCES)]
    af, wind, sensors = _with_nuisance(_base(v, rng), v, rng, name, duration_s)
    kw = {"sensors": sensors} if sensors is not None else {}
    return _spec("healthy", seed, i, af, rng, duration_s, wind=wind, nuisance=name, **kw)


# Blade flapping, the largest coefficient drawn (N m per rad/s per m/s). No measurement of our vehicle; bounded by
# the one real flight here flown fast: ArduPilot log171 trims its front rotors' yaw-free omega^2 share by up to
# ~0.025 per m/s of forward speed (0.11-0.27 at 5-10 m/s; docs/ALERTS.md "On real flights"). On the paper quad a
# share offset s is a pitch moment s m g a_x (a_x = 0.113 m), flapping's is k 4 w_h v, so
# k = 0.025 * 1.5 * 9.81 * 0.113 / (4 * 584.7) = 1.78e-5.
FLAPPING_MAX = 1.8e-5
FORWARD_FLIGHT_VEL_XY_MAX_M_S = 10.0  # log171's fastest legs; PX4's MPC_XY_VEL_MAX default is 12


def _forward_flight(v, seed, i, duration_s) -> FlightSpec:
    rng = _rng("forward_flight", seed, i)
    af = _base(v, rng).with_(flapping_nm_per_rad_s_m_s=float(rng.uniform(0.0, FLAPPING_MAX)))
    return _spec(
        "forward_flight", seed, i, af, rng, duration_s, nuisance="forward_flight", vel_xy_max_m_s=FORWARD_FLIGHT_VEL_XY_MAX_M_S
    )


def _onset(v, seed, i, duration_s) -> FlightSpec:
    rng = _rng("onset", seed, i)
    faulty = ONSET_PATTERNS[i % len(ONSET_PATTERNS)]
    dmg = _damage(rng, faulty, "bent" if rng.random() < 0.5 else "cracked", float(rng.uniform(0.3, 0.6) * duration_s))
    loss = tuple(float(rng.uniform(0.05, 0.20)) if p + 1 in faulty else 0.0 for p in range(4))
    af = _base(v, rng).with_(damage=replace(dmg, thrust_loss_at_hover=loss))
    return _spec("onset", seed, i, af, rng, duration_s, nuisance="onset")


def _hidden(v, seed, i, duration_s) -> FlightSpec:
    """Airframe a = i // 6 has one hidden effect; its flights: 2 healthy, then propellers 1..4 faulty."""
    a, k = divmod(i, 6)
    effect = HIDDEN_EFFECTS[a % len(HIDDEN_EFFECTS)]
    arng = _rng("hidden", seed, 100_000 + a)  # the airframe: shared by its flights
    af, _, _ = _with_nuisance(_base(v, arng), v, arng, effect, duration_s)
    rng = _rng("hidden", seed, i)
    if k >= 2:
        af = af.with_(damage=_damage(rng, (k - 1,), "bent" if rng.random() < 0.5 else "cracked"))
    return _spec("hidden", seed, i, af, rng, duration_s, nuisance=effect, airframe_id=f"hidden-{a:03d}-{effect}")


VEHICLE_FLIGHTS = 12  # per airframe of the ``vehicles`` set
VEHICLE_REFERENCES = 3  # its first flights: healthy references
VEHICLE_HEALTHY_LATER = (0, 3, 6, 8)  # later flights (k - VEHICLE_REFERENCES) that stay healthy
VEHICLE_LOSS = (0.03, 0.20)  # thrust loss at hover of a damaged propeller


def _vehicles(v, seed, i, duration_s) -> FlightSpec:
    """Airframe a = i // VEHICLE_FLIGHTS, drawn once and flown again and again (``vehicles`` in the table above)."""
    a, k = divmod(i, VEHICLE_FLIGHTS)
    arng = _rng("vehicles", seed, 100_000 + a)  # the airframe: shared by its flights
    af = _base(v, arng, arng.uniform(0.04, 0.08))
    cg = (float(arng.uniform(-0.01, 0.01)), float(arng.uniform(-0.01, 0.01)), 0.0)
    inertia = np.asarray(v.inertia_diag_kg_m2) * (1 + arng.uniform(-0.1, 0.1, 3))
    lag = tuple(float(x) for x in arng.uniform(0.025, 0.05, 4))
    af = af.with_(cg_offset_frd_m=cg, inertia_diag_kg_m2=tuple(float(x) for x in inertia), motor_time_constant_s=lag)
    rng = _rng("vehicles", seed, i)
    if k < VEHICLE_REFERENCES:
        return _spec("vehicles", seed, i, af, rng, duration_s, nuisance="reference", airframe_id=f"vehicle-{a:03d}")
    j = k - VEHICLE_REFERENCES
    af = af.with_(payload_kg=float(rng.uniform(0.0, 0.25)) * v.mass_kg)
    wind = _gusty_wind(rng) if rng.random() < 0.5 else _light_wind(rng)
    if j in VEHICLE_HEALTHY_LATER:
        return _spec("vehicles", seed, i, af, rng, duration_s, wind=wind, nuisance="later", airframe_id=f"vehicle-{a:03d}")
    rotor = (a + j) % 4 + 1
    dmg = _damage(rng, (rotor,), "bent" if rng.random() < 0.5 else "cracked")
    loss = tuple(float(rng.uniform(*VEHICLE_LOSS)) if p + 1 == rotor else 0.0 for p in range(4))
    af = af.with_(damage=replace(dmg, thrust_loss_at_hover=loss))
    return _spec("vehicles", seed, i, af, rng, duration_s, wind=wind, nuisance="later", airframe_id=f"vehicle-{a:03d}")


def _effectiveness(v, seed, i, duration_s) -> FlightSpec:
    rng = _rng("effectiveness", seed, i)
    rotor = i % 4 + 1
    loss_v = EFFECTIVENESS_LOSSES[(i // 4) % 3]
    dq = 0.0 if (i // 12) % 2 == 0 else -0.05
    loss = tuple(loss_v if p + 1 == rotor else 0.0 for p in range(4))
    dmg = Damage(
        thrust_loss_at_hover=loss,
        torque_per_thrust_change=tuple(dq if p + 1 == rotor else 0.0 for p in range(4)),
        vibration_1p_m_s2=tuple(0.5 if p + 1 == rotor else 0.0 for p in range(4)),
    )
    af = _base(v, rng, spread=0.0).with_(damage=dmg)
    return _spec("effectiveness", seed, i, af, rng, duration_s, nuisance=f"loss {loss_v:.2f}, torque/thrust {dq:+.2f}")


def motor_lag_specs(
    taus_s, flights: int = 2, seed: int = 0, duration_s: float = DEFAULT_DURATION_S, jitter_s: float | None = None
) -> list[FlightSpec]:
    """Healthy flights of one paper-quad airframe whose rotors lag by ``taus_s`` (4, s, PX4 order): the calibrator's
    lag sweep (bench/evalsim_lag.py) and its test. ``jitter_s`` overrides the telemetry jitter (None: the default
    4 ms with drops; 0: exact 20 Hz, no drops). Flight i depends only on (taus_s, seed, i, duration_s, jitter_s)."""
    v = load_vehicle(DEFAULT_VEHICLE)
    af = _base(v, np.random.default_rng([seed, 901])).with_(motor_time_constant_s=tuple(float(t) for t in taus_s))
    tel = Telemetry() if jitter_s is None else Telemetry(jitter_std_s=jitter_s, drop_probability=0.003 if jitter_s > 0 else 0.0)
    specs = []
    for i in range(flights):
        rng = np.random.default_rng([seed, 902, i])
        specs.append(
            FlightSpec(
                name=f"lag_{seed}_{i}",
                airframe=af,
                waypoints_ned_m=_route(rng),
                duration_s=float(duration_s),
                seed=int(rng.integers(2**31)),
                wind=_light_wind(rng),
                telemetry=tel,
                nuisance="motor_lag",
            )
        )
    return specs


_BUILDERS: dict[str, tuple[Callable, int]] = {
    # name -> (builder, default flight count: one cycle)
    "paper": (_paper, 16),
    "shift": (_shift, 16),
    "shift_quarter": (_shift_scaled(0.25, "shift_quarter"), 16),
    "shift_half": (_shift_scaled(0.5, "shift_half"), 16),
    "healthy": (_healthy, len(NUISANCES)),
    "onset": (_onset, len(ONSET_PATTERNS)),
    "hidden": (_hidden, 6 * len(HIDDEN_EFFECTS)),
    "effectiveness": (_effectiveness, 12),
    "paper_torque_rising": (_paper_torque_rising, 16),
    "forward_flight": (_forward_flight, 16),
    "vehicles": (_vehicles, 5 * VEHICLE_FLIGHTS),
}
DAY_US = 86_400 * 1_000_000


def build_set(
    name: str, flights: int | None = None, seed: int = 0, duration_s: float = DEFAULT_DURATION_S, vehicle_path=DEFAULT_VEHICLE
) -> list[FlightSpec]:
    """The flight specs of set ``name`` (``flights`` defaults to one cycle of its labels / effects)."""
    if name not in _BUILDERS:
        raise ValueError(f"unknown evalsim set {name!r}; choose from {', '.join(SET_NAMES)}")
    return build_specs(_BUILDERS[name], flights, seed, duration_s, vehicle_path)


def build_specs(builder_and_n, flights, seed, duration_s, vehicle_path=DEFAULT_VEHICLE) -> list[FlightSpec]:
    """``flights`` specs of one builder (``(builder(v, seed, i, duration_s), default flights)``)."""
    builder, default_n = builder_and_n
    if duration_s < 5.0:
        raise ValueError(f"duration_s: at least 5 s, got {duration_s}")
    n = default_n if flights is None else int(flights)
    if n < 1:
        raise ValueError(f"flights: at least 1, got {flights}")
    v = load_vehicle(vehicle_path)
    return [builder(v, seed, i, float(duration_s)) for i in range(n)]


def batches(specs: list[FlightSpec]) -> list[list[FlightSpec]]:
    """``specs`` in batches of at most ``BATCH`` flights that share one controller (nominal vehicle and gains), in
    order of first appearance; a flight is the same whichever batch flies it."""
    groups: dict[tuple, list[FlightSpec]] = {}
    for s in specs:
        groups.setdefault((s.nominal, s.controller_gains), []).append(s)
    return [g[b : b + BATCH] for g in groups.values() for b in range(0, len(g), BATCH)]


def write_set(
    name: str,
    out_dir: str | Path,
    flights: int | None = None,
    seed: int = 0,
    duration_s: float = DEFAULT_DURATION_S,
    progress: Callable[[int], None] | None = None,
    specs: list[FlightSpec] | None = None,
    writer: Callable | None = None,
) -> Path:
    """Simulate set ``name`` into ``out_dir``: one .tlog + one truth .json per flight + manifest.json.

    ``specs`` and ``writer(i, spec, log, out) -> truth`` come from another module's sets
    (``offline.evalsim.catalog``); by default this module's set ``name`` and its own writing.
    Files are written to temporary names and renamed, the manifest last, so a
    folder with a manifest is complete.
    """
    from offline.evalsim.assumptions import ASSUMPTIONS

    specs = build_set(name, flights, seed, duration_s) if specs is None else specs
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    entries = []
    for chunk in batches(specs):
        logs = simulate_flights(chunk)
        for spec, log in zip(chunk, logs, strict=True):
            tlog = f"{spec.name}.tlog"
            i = int(spec.name.rsplit("_", 1)[1])
            if writer is not None:
                t = writer(i, spec, log, out)
            elif name == "vehicles":  # each airframe's flights a day apart, ending in landing and disarm, with its uid
                a, k = divmod(i, VEHICLE_FLIGHTS)
                write_tlog(out / tlog, log, 0, wall_boot_us=DEFAULT_WALL_BOOT_US + k * DAY_US, landing=True)
                append_autopilot_version(out / tlog, vehicle_uid(a))
                t = truth(spec, file=tlog)
                write_json(out / f"{spec.name}.json", t)
            else:
                write_tlog(out / tlog, log, 0)
                t = truth(spec, file=tlog)
                write_json(out / f"{spec.name}.json", t)
            entries.append(
                {
                    "file": tlog,
                    "truth": f"{spec.name}.json",
                    "label": t["label"],
                    "faulty_propellers": t["faulty_propellers"],
                    "nuisance": spec.nuisance,
                    "airframe_id": spec.airframe_id,
                    "seed": spec.seed,
                }
            )
        if progress is not None:
            progress(len(chunk))
    entries.sort(key=lambda e: e["file"])
    manifest = make_manifest(
        "propwatch-evalsim-set",
        {"set": name, "flights": len(specs), "duration_s": duration_s, "vehicle_path": str(DEFAULT_VEHICLE)},
        seed,
        flights=entries,
        assumptions=ASSUMPTIONS,
        evaluation_only=True,
    )
    write_manifest(out / "manifest.json", manifest)
    return out


def write_json(path: Path, obj: dict) -> None:
    """A truth or manifest-side JSON file of a set, written to a temporary name and renamed (sorted keys)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(obj, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def load_truth(path: str | Path) -> dict:
    return json.loads(Path(path).read_text(encoding="utf-8"))


__all__ = ["SET_NAMES", "Telemetry", "build_set", "flight_seed", "load_truth", "motor_lag_specs", "write_set"]
