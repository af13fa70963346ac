"""Generate labelled fault data sets with the hybrid simulator (paper Sec. IV-B, Table 4.2).

A data set is ``flights_per_label`` flights for each of the 16 labels, in
label order. In a flight the faulty rotors of the label are all bent, all
cracked, or each bent or cracked at random (``fault="mixed"``), or one of those three drawn per flight (``"varied"``). Shift options
(random routes, payload ranges, wind, randomised model terms) are drawn per
flight or per vehicle variant from the spec's seed, so a data set is a pure
function of (spec, vehicle, code).

``physics="randomised"``: every flight's physics is drawn from the register of
unmeasured assumptions (``offline/sim/assumptions.py``): flight i gets
``draw_flight(register, SeedSequence([seed, i]))`` whatever the chunking, so
flights can be sharded by index. Each damaged rotor gets its own drawn
signature (bent or cracked ranges) in place of the fixed ``BENT``/``CRACKED``,
applied by the analytic propellers (``propellers="quadratic"``: an LSTM learned
one signature per condition). Telemetry delay, jitter and drops are applied to
the logged signals. The manifest records the register's ranges and the rule.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from monitor.config import to_mapping
from monitor.errors import ConfigError
from monitor.features import SAMPLE_RATE_HZ
from monitor.labels import LABEL_MASKS
from monitor.progress import bar, interactive
from monitor.vehicle import VehicleConfig
from offline.dataset.records import FaultDataset, concat
from offline.manifest import make_manifest

FAULTS = ("bent", "cracked", "mixed", "varied")
ROUTES = ("A", "B", "random")
PHYSICS = ("fixed", "randomised")
AIRFRAMES = ("drawn", "nominal")


@dataclass(frozen=True)
class DatasetSpec:
    name: str
    fault: str = "bent"
    waypoints: tuple[str, ...] = ("A",)  # cycled over flights; "random" draws a fresh route per flight
    payload_kg: tuple[float, float] = (0.0, 0.0)  # extra mass over the vehicle's, uniform per flight
    flights_per_label: int = 2
    duration_s: float = 80.0  # paper: 80 s flights
    propellers: str = "lstm"
    wind_max_m_s: float = 0.0  # steady wind, random direction and speed per vehicle variant
    motor_efficiency_spread: float = 0.0  # +- fraction per rotor per variant
    cg_offset_max_m: float = 0.0  # +- per horizontal axis per variant
    vehicle_variants: int = 1  # the simulator takes one vehicle per call; variants carry the randomised terms
    sensor_noise_scale: float = 1.0  # times the simulator's default gyro and attitude noise; 0 = off
    seed: int = 0
    chunk_flights: int = 64  # flights per simulator call (memory)
    physics: str = "fixed"  # "randomised": every flight's physics drawn from the assumption register
    # Under randomised physics: "drawn" draws the airframe's own terms too (an unmeasured airframe); "nominal"
    # fixes them (offline.sim.assumptions.AIRFRAME_TERMS), as for an airframe `propwatch adapt` calibrated.
    airframe: str = "drawn"

    def __post_init__(self) -> None:
        if self.fault not in FAULTS:
            raise ConfigError(f"fault: must be one of {FAULTS}, got {self.fault!r}")
        bad = [w for w in self.waypoints if w not in ROUTES]
        if bad or not self.waypoints:
            raise ConfigError(f"waypoints: each must be one of {ROUTES}, got {list(self.waypoints)}")
        if self.flights_per_label < 1 or self.vehicle_variants < 1:
            raise ConfigError("flights_per_label and vehicle_variants: must be >= 1")
        if not 0.0 <= self.payload_kg[0] <= self.payload_kg[1]:
            raise ConfigError(f"payload_kg: need 0 <= low <= high, got {self.payload_kg}")
        if self.physics not in PHYSICS:
            raise ConfigError(f"physics: must be one of {PHYSICS}, got {self.physics!r}")
        if self.airframe not in AIRFRAMES:
            raise ConfigError(f"airframe: must be one of {AIRFRAMES}, got {self.airframe!r}")
        if self.airframe != "drawn" and self.physics != "randomised":
            raise ConfigError("airframe: only physics 'randomised' draws an airframe")
        if self.physics == "randomised":
            if self.propellers != "quadratic":
                raise ConfigError(
                    "propellers: physics 'randomised' draws a signature per damaged rotor, which only the analytic "
                    "'quadratic' propellers apply (each LSTM learned one signature)"
                )
            clash = (
                [k for k in ("wind_max_m_s", "motor_efficiency_spread", "cg_offset_max_m") if getattr(self, k) != 0.0]
                + (["vehicle_variants"] if self.vehicle_variants != 1 else [])
                + (["sensor_noise_scale"] if self.sensor_noise_scale != 1.0 else [])
            )
            if clash:
                raise ConfigError(f"{', '.join(clash)}: drawn from the assumption register under physics 'randomised'")


# The paper's three simulated sets (Table 4.2) on its 1.5 kg quad; C's 1.95 kg is 0.45 kg of payload.
PRESETS = {
    "A": dict(waypoints=("A",), payload_kg=(0.0, 0.0)),
    "B": dict(waypoints=("B",), payload_kg=(0.0, 0.0)),
    "C": dict(waypoints=("A",), payload_kg=(0.45, 0.45)),
}


def flight_conditions(fault: str, flights_per_label: int, rng: np.random.Generator) -> np.ndarray:
    """(16 * k, 4) int8 conditions in label order: 0 normal, 1 bent, 2 cracked."""
    mask = np.repeat(LABEL_MASKS > 0, flights_per_label, axis=0)
    if fault == "mixed":
        kind = rng.integers(1, 3, mask.shape)
    elif fault == "varied":
        # A third of the flights all bent, a third all cracked, a third each propeller at random: "mixed" alone
        # makes a flight whose faulty propellers share one kind rare (1 in 8 for label 16), yet it is the
        # likely case after one event and the paper's whole test set.
        mode = rng.integers(0, 3, len(mask))
        kind = np.where((mode == 2)[:, None], rng.integers(1, 3, mask.shape), (mode + 1)[:, None])
    else:
        kind = np.full(mask.shape, 1 if fault == "bent" else 2)
    return (mask * kind).astype(np.int8)


def vehicle_variant(vehicle: VehicleConfig, spec: DatasetSpec, rng: np.random.Generator) -> VehicleConfig:
    """The nominal vehicle with this spec's randomised terms drawn once."""
    eff = tuple(float(e) for e in 1.0 + rng.uniform(-1, 1, 4) * spec.motor_efficiency_spread)
    cg = (*(float(v) for v in rng.uniform(-1, 1, 2) * spec.cg_offset_max_m), vehicle.cg_offset_frd_m[2])
    heading = rng.uniform(0, 2 * math.pi)
    speed = rng.uniform(0, spec.wind_max_m_s)
    wind = (speed * math.cos(heading), speed * math.sin(heading), 0.0)
    return dataclasses.replace(
        vehicle,
        motor_efficiency=tuple(a * b for a, b in zip(vehicle.motor_efficiency, eff)),
        cg_offset_frd_m=tuple(a + b for a, b in zip(vehicle.cg_offset_frd_m, cg)),
        wind_ned_m_s=tuple(a + b for a, b in zip(vehicle.wind_ned_m_s, wind)),
    )


def routes(spec: DatasetSpec, n_flights: int, seed: int) -> tuple[np.ndarray, tuple[str, ...]]:
    from offline.sim.mission import random_waypoints, waypoint_set

    names = tuple(spec.waypoints[i % len(spec.waypoints)] for i in range(n_flights))
    fresh = random_waypoints(n_flights, seed=seed)
    wps = np.stack([fresh[i] if n == "random" else waypoint_set(n) for i, n in enumerate(names)])
    return wps, names


def sim_config(spec: DatasetSpec):
    """The simulator's config with this spec's duration and noise (only keys the simulator has)."""
    from offline.sim.simulator import SimConfig

    base = SimConfig()
    return dataclasses.replace(
        base,
        duration_s=spec.duration_s,
        log_rate_hz=int(SAMPLE_RATE_HZ),
        gyro_noise_std_rad_s=base.gyro_noise_std_rad_s * spec.sensor_noise_scale,
        attitude_noise_std_rad=base.attitude_noise_std_rad * spec.sensor_noise_scale,
    )


def simulate_flights(
    vehicle: VehicleConfig,
    waypoints: np.ndarray,
    conditions: np.ndarray,
    payload_kg: np.ndarray,
    spec: DatasetSpec,
    seed: int,
    propellers=None,
):
    """One simulator call; returns the FlightLog. ``propellers`` overrides the condition-built model (onset runs)."""
    from offline.propellers import build_propellers
    from offline.sim.simulator import simulate

    if propellers is None:
        propellers = build_propellers(vehicle, conditions, kind=spec.propellers, rng_seed=seed)
    return simulate(vehicle, waypoints, propellers, sim_config(spec), payload_kg=payload_kg, seed=seed)


def from_log(
    log,
    name: str,
    vehicle: VehicleConfig,
    conditions: np.ndarray,
    payload_kg: np.ndarray,
    waypoint_names: tuple[str, ...],
    manifest: dict,
    onset_step: np.ndarray | None = None,
) -> FaultDataset:
    """A FlightLog-like object (``.signals()`` -> canonical 20 Hz signals) -> FaultDataset."""
    rate = float(getattr(log, "log_rate_hz", SAMPLE_RATE_HZ))
    if abs(rate - SAMPLE_RATE_HZ) > 1e-9:
        raise ConfigError(f"{name}: flights logged at {rate} Hz; the classifier's features are at {SAMPLE_RATE_HZ} Hz")
    sig = {k: np.asarray(v, dtype=np.float32) for k, v in log.signals().items()}
    return FaultDataset(
        name,
        vehicle.name,
        SAMPLE_RATE_HZ,
        sig,
        np.asarray(conditions, np.int8),
        np.asarray(payload_kg, np.float64),
        tuple(waypoint_names),
        manifest,
        onset_step,
    )


def generate(spec: DatasetSpec, vehicle: VehicleConfig, log=print, run_chunks=None, *, register=None) -> FaultDataset:
    """The data set of ``spec``; ``register`` (randomised physics only) defaults to ``assumptions.REGISTER``.

    ``run_chunks`` maps the list of chunk jobs ``(function, keyword arguments)`` to their results, in
    order; default: one after another in this process (``offline.dataset.ray_shard`` runs them as Ray
    tasks: same chunks, same seeds, same arrays)."""
    if spec.physics == "randomised":
        return _generate_randomised(spec, vehicle, log, register, run_chunks)
    rng = np.random.default_rng([spec.seed, 0])
    cond = flight_conditions(spec.fault, spec.flights_per_label, rng)
    n = len(cond)
    payload = rng.uniform(spec.payload_kg[0], spec.payload_kg[1], n)
    wps, names = routes(spec, n, seed=spec.seed)
    variant_of = rng.permutation(np.arange(n) % spec.vehicle_variants)
    variants = [
        vehicle if spec.vehicle_variants == 1 and not _randomised(spec) else vehicle_variant(vehicle, spec, rng)
        for _ in range(spec.vehicle_variants)
    ]
    manifest = make_manifest(
        "fault-dataset",
        to_mapping(spec),
        spec.seed,
        name=spec.name,
        vehicle={"name": vehicle.name, "esc": to_mapping(vehicle.esc)},
        variants=[to_mapping(v) for v in variants] if _randomised(spec) else None,
    )
    jobs, order = [], []
    progress = bar(n, "flight", f"dataset {spec.name}") if interactive() else None
    for v, veh in enumerate(variants):
        idx = np.flatnonzero(variant_of == v)
        for c0 in range(0, len(idx), spec.chunk_flights):
            chunk = idx[c0 : c0 + spec.chunk_flights]
            seed = int(np.random.default_rng([spec.seed, 1, v, c0]).integers(2**31))
            kw = dict(vehicle=veh, waypoints=wps[chunk], conditions=cond[chunk], payload_kg=payload[chunk], spec=spec, seed=seed)
            jobs.append((simulate_flights, kw))
            order.append(chunk)
    parts = []
    for chunk, flight_log in zip(order, (run_chunks or _one_after_another)(jobs)):
        parts.append(
            from_log(flight_log, spec.name, vehicle, cond[chunk], payload[chunk], tuple(names[i] for i in chunk), manifest)
        )
        if progress is not None:
            progress.update(len(chunk))
        else:
            log(f"{spec.name}: simulated {sum(len(o) for o in order[: len(parts)])}/{n} flights")
    if progress is not None:
        progress.close()
    ds = parts[0] if len(parts) == 1 else concat(parts, spec.name)
    back = np.argsort(np.concatenate(order))  # restore label order
    ds = ds.subset(back)
    return dataclasses.replace(ds, manifest=manifest)


def _one_after_another(jobs: list[tuple]):
    for fn, kw in jobs:
        yield fn(**kw)


def _randomised(spec: DatasetSpec) -> bool:
    return spec.wind_max_m_s > 0 or spec.motor_efficiency_spread > 0 or spec.cg_offset_max_m > 0


def flight_sim_seed(seed: int, i: int) -> int:
    """Flight i's simulator seed (sensor noise) under randomised physics, a function of (seed, i) only."""
    return int(np.random.SeedSequence([int(seed), int(i), 1]).generate_state(1)[0])


def simulate_randomised(
    spec: DatasetSpec, vehicle: VehicleConfig, idx: np.ndarray, cond: np.ndarray, payload: np.ndarray, wps: np.ndarray, register
) -> dict[str, np.ndarray]:
    """Flights ``idx`` (indices into the data set) with their drawn physics -> canonical signals (float32).

    Everything per flight comes from (spec.seed, index): a shard of indices gives the same flights as the whole.
    """
    from offline.propellers import build_propellers
    from offline.sim.assumptions import draw_flights
    from offline.sim.perflight import PerFlightTerms
    from offline.sim.simulator import simulate

    phys = draw_flights(register, spec.seed, idx)
    grid = np.empty((len(idx), 4), dtype=object)
    for b, (f, row) in enumerate(zip(phys, cond)):
        for r, c in enumerate(row):
            grid[b, r] = f.healthy_signature(r) if c == 0 else f.signature(r, "bent" if c == 1 else "cracked")
    seeds = np.array([flight_sim_seed(spec.seed, i) for i in idx])
    props = build_propellers(vehicle, cond, kind="quadratic", rng_seed=seeds, rotor_signatures=grid)
    flog = simulate(
        vehicle,
        wps,
        props,
        sim_config(spec),
        payload_kg=payload,
        seed=seeds,
        per_flight=PerFlightTerms.from_flights(phys, vehicle),
    )
    return degraded_signals(flog, phys, np.float32)


def degraded_signals(flog, phys, dtype=np.float64) -> dict[str, np.ndarray]:
    """A batch's canonical signals with each flight's drawn telemetry delay, jitter and drops applied
    (``offline.sim.telemetry.degrade_flight``, seeded by the flight's own noise seed)."""
    from offline.sim.telemetry import degrade_flight

    sig = flog.signals()
    out = {k: np.empty(np.shape(v), dtype) for k, v in sig.items()}
    for b, f in enumerate(phys):
        one = degrade_flight(
            {k: v[b] for k, v in sig.items()},
            float(flog.log_rate_hz),
            f["attitude_log_delay_s"],
            f["telemetry_jitter_std_s"],
            f["telemetry_drop_prob"],
            np.random.default_rng([int(f["noise_seed"]) % 2**63, 1]),
        )
        for k, v in one.items():
            out[k][b] = v
    return out


class _Signals:
    """A FlightLog-like holder of canonical signals (for ``from_log``)."""

    def __init__(self, signals: dict[str, np.ndarray], rate_hz: float):
        self._signals, self.log_rate_hz = signals, rate_hz

    def signals(self) -> dict[str, np.ndarray]:
        return self._signals


def _generate_randomised(spec: DatasetSpec, vehicle: VehicleConfig, log, register, run_chunks=None) -> FaultDataset:
    from offline.sim.assumptions import REGISTER, nominal_airframe

    register = REGISTER if register is None else register
    if spec.airframe == "nominal":
        register = nominal_airframe(register)
    rng = np.random.default_rng([spec.seed, 0])
    cond = flight_conditions(spec.fault, spec.flights_per_label, rng)
    n = len(cond)
    payload = rng.uniform(spec.payload_kg[0], spec.payload_kg[1], n)
    wps, names = routes(spec, n, seed=spec.seed)
    manifest = make_manifest(
        "fault-dataset",
        to_mapping(spec),
        spec.seed,
        name=spec.name,
        vehicle={"name": vehicle.name, "esc": to_mapping(vehicle.esc)},
        assumptions=register.to_mapping(),
        physics_draws={
            "rule": "flight i: offline.sim.assumptions.draw_flight(register, SeedSequence([seed, i])); "
            "simulator noise seed offline.dataset.generate.flight_sim_seed(seed, i); flights in label order",
            "seed": spec.seed,
            "flights": n,
        },
    )
    chunks = [np.arange(c0, min(n, c0 + spec.chunk_flights)) for c0 in range(0, n, spec.chunk_flights)]
    jobs = [
        (
            simulate_randomised,
            dict(spec=spec, vehicle=vehicle, idx=idx, cond=cond[idx], payload=payload[idx], wps=wps[idx], register=register),
        )
        for idx in chunks
    ]
    parts = []
    for idx, sig in zip(chunks, (run_chunks or _one_after_another)(jobs)):
        parts.append(
            from_log(
                _Signals(sig, SAMPLE_RATE_HZ), spec.name, vehicle, cond[idx], payload[idx], tuple(names[i] for i in idx), manifest
            )
        )
        log(f"{spec.name}: simulated {idx[-1] + 1}/{n} flights (randomised physics)")
    ds = parts[0] if len(parts) == 1 else concat(parts, spec.name)
    return dataclasses.replace(ds, manifest=manifest)
