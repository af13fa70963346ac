"""Simulated CrazyPAD flights with cut propellers: the classifier's training data.

One recipe, applied to whichever vehicle(s) it is given (nominal or
calibrated), so the two classifiers differ only in the vehicle:

- the CrazyPAD mission (``offline.crazypad.mission``), 16 s airborne;
- the paper's labels 1-11 (no fault, each single propeller, each pair),
  ``flights_per_label`` flights each per vehicle. Triples and all four are
  left out: with command shares as the only signal (below), three or four
  equally weak rotors look like one strong rotor or like none, so those labels
  would only teach the network to confuse the others. The model keeps the
  contract's 16 outputs; 12-16 are never the answer;
- a cut propeller is a thrust and drag-torque loss on that rotor
  (``offline.sim.propeller.QuadraticPropeller`` scales). Its size is drawn from
  physics, not from the fault flights: a cut of up to 8 mm of a 47 mm span
  (rho = span/47 >= 0.83) with thrust ~ rho^k, k in 1..4, is a 5-40 % thrust loss;
  the torque loss is the thrust loss times U(0.7, 1.3) (tip cuts lose more
  torque, R^5 against R^4; ragged edges add profile drag);
- healthy rotors vary by 3 % (thrust, 1 sigma), the flight-to-flight spread of
  the command shares on the healthy flights (std 0.005-0.027 of the share per
  motor and airframe, i.e. up to ~4 % of thrust); payload 0..3 g;
- the motor commands get white noise of a per-flight level drawn from the
  range measured on the healthy calibration flights (0.012-0.045 of the share
  per 20 Hz sample; the simulation alone has 0.005): the real vehicle's
  turbulence and ground effect that the simulator lacks;
- the first ``SETTLE_S`` of each flight (start transient) is blanked (NaN), so
  no window sees it.

Fault codes in the data set: 1 marks a cut rotor (``FaultDataset`` calls code 1
"bent"; the manifest says what it is here).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from monitor.labels import LABEL_MASKS
from monitor.vehicle import VehicleConfig
from offline.crazypad.mission import CRAZYPAD, CrazypadMission, batch_waypoints, sim_config
from offline.dataset.records import FaultDataset, concat
from offline.manifest import make_manifest
from offline.sim.propeller import QuadraticPropeller
from offline.sim.simulator import simulate

SETTLE_S = 0.5


@dataclass(frozen=True)
class Recipe:
    flights_per_label: int = 10
    labels: tuple[int, ...] = tuple(range(1, 12))
    thrust_loss: tuple[float, float] = (0.08, 0.40)
    torque_loss_ratio: tuple[float, float] = (0.7, 1.3)
    healthy_jitter: float = 0.03
    payload_kg: tuple[float, float] = (0.0, 0.003)
    cmd_noise: tuple[float, float] = (0.012, 0.045)
    seed: int = 0


def draw_flights(recipe: Recipe, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Per flight: fault mask (B, 4), thrust and torque scales (B, 4), payload, noise level."""
    masks = np.repeat(LABEL_MASKS[np.asarray(recipe.labels) - 1].astype(bool), recipe.flights_per_label, axis=0)
    b = len(masks)
    thrust = 1.0 + recipe.healthy_jitter * rng.standard_normal((b, 4))
    loss = rng.uniform(*recipe.thrust_loss, size=(b, 4))
    ratio = rng.uniform(*recipe.torque_loss_ratio, size=(b, 4))
    torque = thrust.copy()
    thrust = np.where(masks, 1.0 - loss, thrust)
    torque = np.where(masks, 1.0 - np.minimum(loss * ratio, 0.9), torque)
    return {
        "mask": masks,
        "thrust_scale": thrust,
        "torque_scale": torque,
        "payload_kg": rng.uniform(*recipe.payload_kg, size=b),
        "noise": rng.uniform(*recipe.cmd_noise, size=b),
    }


def simulate_dataset(
    vehicle: VehicleConfig, recipe: Recipe, name: str, mission: CrazypadMission = CRAZYPAD, seed_offset: int = 0
) -> FaultDataset:
    rng = np.random.default_rng([recipe.seed, seed_offset])
    d = draw_flights(recipe, rng)
    sim = sim_config(mission)
    props = QuadraticPropeller.for_vehicle(vehicle, thrust_scale=d["thrust_scale"], torque_scale=d["torque_scale"])
    log = simulate(
        vehicle,
        batch_waypoints(len(d["mask"]), mission),
        props,
        sim,
        payload_kg=d["payload_kg"],
        seed=recipe.seed * 1000 + seed_offset,
    )
    signals = {k: np.array(v, dtype=np.float64) for k, v in log.signals().items()}
    rpm = signals["motor_rpm"] * (1.0 + d["noise"][:, None, None] * rng.standard_normal(signals["motor_rpm"].shape))
    settle = int(round(SETTLE_S * sim.log_rate_hz))
    rpm[:, :settle] = np.nan
    signals["motor_rpm"] = rpm
    manifest = make_manifest(
        "crazypad-sim-dataset",
        {
            "recipe": asdict(recipe),
            "mission": asdict(mission),
            "sim": {"physics_rate_hz": sim.physics_rate_hz, "control_rate_hz": sim.control_rate_hz, "duration_s": sim.duration_s},
        },
        recipe.seed,
        vehicle={
            "name": vehicle.name,
            "esc": asdict(vehicle.esc),
            "motor_efficiency": list(vehicle.motor_efficiency),
            "cg_offset_frd_m": list(vehicle.cg_offset_frd_m),
        },
        fault_code_1="cut propeller (thrust and drag-torque loss)",
        thrust_scale=d["thrust_scale"].round(4).tolist(),
    )
    return FaultDataset(
        name=name,
        vehicle_name=vehicle.name,
        sample_rate_hz=float(sim.log_rate_hz),
        signals=signals,
        conditions=d["mask"].astype(np.int8),
        payload_kg=d["payload_kg"],
        waypoint_set=("crazypad",) * len(d["mask"]),
        manifest=manifest,
    )


def training_set(vehicles: list[VehicleConfig], recipe: Recipe, name: str) -> FaultDataset:
    """The recipe on each vehicle; ``flights_per_label`` is split between them so sizes match."""
    per = max(1, recipe.flights_per_label // len(vehicles))
    parts = [
        simulate_dataset(v, Recipe(**{**asdict(recipe), "flights_per_label": per}), f"{name}-{i}", seed_offset=i)
        for i, v in enumerate(vehicles)
    ]
    if len(parts) == 1:
        return replace(parts[0], name=name)
    # concat() keeps only the parts' manifests; the classifier reads the vehicle (name, ESC curve)
    # from the top level, and every part shares the nominal ESC curve (calibration leaves it).
    first = parts[0].manifest
    return replace(
        concat(parts, name),
        manifest={
            **first,
            "vehicle": {**first["vehicle"], "parts": [p.manifest["vehicle"] for p in parts]},
            "parts": [p.manifest for p in parts],
        },
    )
