"""Same-airframe fleets on our own simulator: each vehicle drawn once from the assumption register, flown many times.

Airframe a's terms (``AIRFRAME_KEYS``: CG, motor spread, arm and ESC errors, inertia, drag, lag, the PX4 tune) are
drawn once from the register and shared by all its flights; each flight draws its own wind, noise, telemetry and
damage. Flights per airframe follow ``offline.evalsim.sets``'s ``vehicles`` set: 3 healthy references (no payload),
then 9 later flights (payload 0 to +25 % of the mass, new routes): 4 healthy and 5 with one propeller damaged from
take-off (the register's bent or cracked signature of that flight). Every log ends in landing and disarm, one day
after the airframe's previous flight, and carries the airframe's AUTOPILOT_VERSION uid.

Two options make a development set for judging a flight through time against its vehicle's normal: ``onset_s``
(lo, hi) switches each damaged later flight's propeller from healthy to damaged in the air at a time drawn in that
range (``offline.dataset.onset.SwitchedPropellers``), and ``payload_offset_arm`` places each later flight's payload
at a horizontal point drawn uniformly in a disc of that radius (a fraction of the arm) instead of at the CG: the CG
moves to the mass-weighted mean of the airframe's and the payload's (the payload's own inertia is left out).

Written like an evalsim set: ``NAME.tlog`` + ``NAME.json`` (truth) + ``manifest.json`` (last). Used to measure the
vehicle-memory thresholds; never the evaluation-only simulator.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monitor.esc import RPM_PER_RAD_S
from monitor.labels import label_for
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.evalsim.sets import DAY_US, VEHICLE_FLIGHTS, VEHICLE_HEALTHY_LATER, VEHICLE_REFERENCES, write_json
from offline.fleet_sim import append_autopilot_version, vehicle_uid
from offline.manifest import make_manifest, write_manifest

# The register's values that belong to the airframe (and its tune), not to one flight.
AIRFRAME_KEYS = (
    "cg_offset_frd_m",
    "motor_efficiency_spread_frac",
    "motor_efficiency_unit",
    "arm_position_error_m",
    "esc_offset_rpm",
    "healthy_torque_per_thrust_spread_frac",
    "inertia_error_frac",
    "linear_drag_n_per_m_s",
    "quadratic_drag_n_per_m2_s2",
    "motor_time_constant_s",
    "rotor_inertia_kg_m2",
    "esc_voltage_exponent",
    "battery_internal_resistance_ohm",
    "blade_flapping_trim_per_m_s",
    "mc_rollrate_p",
    "mc_rollrate_i",
    "mc_rollrate_d",
    "mc_yawrate_p",
    "mc_yawrate_i",
    "mc_roll_p",
    "mc_yaw_p",
    "mpc_xy_vel_p_acc",
    "mpc_xy_vel_i_acc",
    "mpc_z_vel_p_acc",
    "mpc_z_vel_i_acc",
)
PAYLOAD_FRAC = (0.0, 0.25)  # later flights' payload, fraction of the vehicle's mass
CHUNK = 24  # flights simulated together
SEED_CODE = 7301  # keeps these draws apart from every other use of the register's seeds


def flight_plan(
    n_flights: int, seed: int, onset_s: tuple[float, float] | None = None, payload_offset_arm: float = 0.0
) -> list[dict]:
    """Flight i of the fleet: its airframe, index in the airframe's history, damage (from take-off, or from
    ``onset_s`` seconds where given) and payload with its horizontal place (fraction of the arm; no simulation)."""
    plan = []
    for i in range(n_flights):
        a, k = divmod(i, VEHICLE_FLIGHTS)
        rng = np.random.default_rng([seed, SEED_CODE, i])
        j = k - VEHICLE_REFERENCES
        damaged = k >= VEHICLE_REFERENCES and j not in VEHICLE_HEALTHY_LATER
        kind = ("bent" if rng.random() < 0.5 else "cracked") if damaged else ""
        payload = 0.0 if k < VEHICLE_REFERENCES else float(rng.uniform(*PAYLOAD_FRAC))
        # drawn after the fleet's original draws, so that a fleet without these options is the same as before
        angle, radius = rng.uniform(0.0, 2.0 * np.pi), payload_offset_arm * np.sqrt(rng.uniform())
        onset = float(rng.uniform(*onset_s)) if damaged and onset_s is not None else None
        plan.append(
            {
                "name": f"ours_vehicles_{i:04d}",
                "airframe": a,
                "k": k,
                "reference": k < VEHICLE_REFERENCES,
                "rotor": (a + j) % 4 + 1 if damaged else 0,
                "kind": kind,
                "payload_frac": payload,
                "payload_xy_arm": [float(radius * np.cos(angle)), float(radius * np.sin(angle))] if payload else [0.0, 0.0],
                "onset_s": onset,
            }
        )
    return plan


def _physics(seed: int, plan: list[dict], vehicle):
    """Each flight's register draw with its airframe's keys replaced by the airframe's own draw, and its CG moved
    toward a payload placed off it."""
    from offline.sim.assumptions import REGISTER, FlightPhysics, draw_flights

    own = draw_flights(REGISTER, seed * 1000 + SEED_CODE, [p["airframe"] for p in plan])
    each = draw_flights(REGISTER, seed, [SEED_CODE * 100_000 + i for i in range(len(plan))])
    base_cg_m = np.asarray(vehicle.cg_offset_frd_m, dtype=np.float64)[:2]
    out = []
    for p, af, f in zip(plan, own, each, strict=True):
        vals = dict(f.values)
        vals.update({k: af.values[k] for k in AIRFRAME_KEYS if k in af.values})
        if p["payload_frac"] and any(p["payload_xy_arm"]):
            payload_xy_m = np.asarray(p["payload_xy_arm"]) * vehicle.arm_length_m
            cg_m = base_cg_m + np.asarray(vals["cg_offset_frd_m"], dtype=np.float64)
            frac = p["payload_frac"] / (1.0 + p["payload_frac"])  # the payload's part of the total mass
            vals["cg_offset_frd_m"] = (1.0 - frac) * cg_m + frac * payload_xy_m - base_cg_m
        out.append(FlightPhysics(vals))
    return out


def write_fleet(
    out_dir: str | Path,
    n_flights: int,
    seed: int = 0,
    duration_s: float = 80.0,
    onset_s: tuple[float, float] | None = None,
    payload_offset_arm: float = 0.0,
) -> Path:
    """Simulate the first ``n_flights`` of the fleet into ``out_dir`` (tlogs, truth, manifest last); ``onset_s`` and
    ``payload_offset_arm`` as in the module docstring."""
    from offline.dataset.generate import DatasetSpec, flight_sim_seed, routes, sim_config
    from offline.dataset.onset import SwitchedPropellers
    from offline.propellers import build_propellers
    from offline.sim.io_tlog import DEFAULT_WALL_BOOT_US, write_tlog
    from offline.sim.log import BOOT_OFFSET_US
    from offline.sim.perflight import PerFlightTerms
    from offline.sim.simulator import simulate

    vehicle = load_vehicle(DEFAULT_VEHICLE)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plan = flight_plan(n_flights, seed, onset_s, payload_offset_arm)
    phys = _physics(seed, plan, vehicle)
    spec = DatasetSpec(
        "vehicles", waypoints=("random",), duration_s=duration_s, propellers="quadratic", physics="randomised", seed=seed
    )
    wps = routes(spec, n_flights, seed=seed * 1000 + SEED_CODE)[0]
    entries = []
    for c0 in range(0, n_flights, CHUNK):
        idx = np.arange(c0, min(n_flights, c0 + CHUNK))
        cond = np.zeros((len(idx), 4), dtype=int)
        healthy = np.array([[phys[i].healthy_signature(r) for r in range(4)] for i in idx], dtype=object)
        sigs = healthy.copy()
        for b, i in enumerate(idx):
            p = plan[i]
            if p["rotor"]:
                r = p["rotor"] - 1
                cond[b, r] = 1 if p["kind"] == "bent" else 2
                sigs[b, r] = phys[i].signature(r, p["kind"])
        seeds = np.array([flight_sim_seed(seed * 1000 + SEED_CODE, int(i)) for i in idx])
        props = build_propellers(vehicle, cond, kind="quadratic", rng_seed=seeds, rotor_signatures=sigs)
        onset = np.array([np.inf if plan[i]["onset_s"] is None else plan[i]["onset_s"] for i in idx])
        if np.isfinite(onset).any():
            before = build_propellers(vehicle, np.zeros_like(cond), kind="quadratic", rng_seed=seeds, rotor_signatures=healthy)
            props = SwitchedPropellers(before, props, np.where(np.isfinite(onset), onset, 1e9))
        payload = np.array([plan[i]["payload_frac"] * vehicle.mass_kg for i in idx])
        flog = simulate(
            vehicle, wps[idx], props, sim_config(spec), payload_kg=payload, seed=seeds,
            per_flight=PerFlightTerms.from_flights([phys[i] for i in idx], vehicle),
        )  # fmt: skip
        rpm = flog.signals()["motor_rpm"]
        for b, i in enumerate(idx):
            p = plan[i]
            tlog = out / f"{p['name']}.tlog"
            write_tlog(tlog, flog, b, wall_boot_us=DEFAULT_WALL_BOOT_US + p["k"] * DAY_US, landing=True)
            append_autopilot_version(tlog, vehicle_uid(1000 + p["airframe"]))
            s_hover = np.median(rpm[b], axis=0) / (vehicle.omega_max_rad_s * RPM_PER_RAD_S)
            factor = [float(sigs[b, r].thrust_factor(s_hover[r])) for r in range(4)]
            faulty = [p["rotor"]] if p["rotor"] else []
            truth = {
                **p,
                "file": tlog.name,
                "label": label_for(tuple(faulty)),
                "faulty_propellers": faulty,
                "index": p["k"],
                "fault_onset_s": 0.0 if p["onset_s"] is None else p["onset_s"],
                "fault_onset_boot_s": None if p["onset_s"] is None else BOOT_OFFSET_US / 1e6 + p["onset_s"],
                "thrust_factor_at_hover": factor,
                "airframe_id": f"ours-vehicle-{p['airframe']:03d}",
            }
            write_json(out / f"{p['name']}.json", truth)
            entries.append(
                {k: truth[k] for k in ("file", "label", "faulty_propellers", "airframe_id", "reference")}
                | {"truth": f"{p['name']}.json"}
            )
    config = {"flights": n_flights, "duration_s": duration_s}
    if onset_s is not None or payload_offset_arm:
        config |= {"onset_s": None if onset_s is None else list(onset_s), "payload_offset_arm": payload_offset_arm}
    manifest = make_manifest("propwatch-ours-vehicles", config, seed, flights=entries)
    write_manifest(out / "manifest.json", manifest)
    return out
