"""A calibrated vehicle as a vehicle-memory normal: its predicted hover omega^2 shares, and normals built on them.

Measurement only (``python -m offline.vehicles.localise``, ``python -m offline.vehicles.residual``); nothing here
changes ``monitor/``.

Predicted shares (``hover_shares``): the static trim of a vehicle in level hover: total thrust m g, roll and pitch
moments about its (calibrated) CG zero, yaw torque zero (``offline.calibrate.physics.trim_thrusts``). Each rotor's
speed follows from its thrust (kf), the speed it is commanded to from its motor efficiency (a motor at efficiency e
reaches e times its commanded speed), the command from the vehicle's ESC curve
(``offline.calibrate.physics.trim_commands``). The log does not see that speed: ``monitor.logs`` reads omega^2 as
the *nominal* ESC curve applied to the logged command, so the predicted share is that of
``nominal_esc.cmd_to_rpm(cmd)^2``, what ``monitor.memory.summary`` would measure on the trimmed vehicle.

Normals (the judge, ``monitor.memory.judge.judge``, unchanged):

- ``pulled_normal``: the vehicle's own normal with its intercept pulled towards a predicted one, as a conjugate
  prior on the mean: the prediction weighs ``PREDICTION_FLIGHTS`` flights, so the intercept is
  (k * predicted + m * own mean) / (k + m), and the prediction interval's 1/n becomes 1/(k + m).
- ``prior_normal``: no history at all: the predicted intercept, the population covariance
  (``monitor.memory.thresholds.PRIOR_COV``), the judged flight's own tilt slopes and within-flight wander.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np

from monitor.config import from_mapping
from monitor.esc import EscCurve
from monitor.memory import thresholds as th
from monitor.memory.normal import Normal, slopes_of
from monitor.memory.summary import FlightSummary
from monitor.vehicle import GRAVITY_M_S2, VehicleConfig
from offline.calibrate.physics import trim_commands, trim_thrusts

# How many flights a predicted intercept weighs against the vehicle's own: the prior's stated weight
# (``thresholds.PRIOR_FLIGHTS``, the weight the population covariance has), not tuned on any fleet.
PREDICTION_FLIGHTS = th.PRIOR_FLIGHTS


def hover_trim(vehicle: VehicleConfig) -> dict[str, np.ndarray]:
    """Level hover of ``vehicle``: per-rotor thrust (N), the ESC command holding it, total thrust and moments."""
    weight_n = np.array([vehicle.mass_kg * GRAVITY_M_S2])
    f = trim_thrusts(vehicle, weight_n)[0]
    cmd = trim_commands(vehicle, weight_n)[0]
    r = vehicle.rotor_positions_array_m - np.asarray(vehicle.cg_offset_frd_m)
    yaw = float((vehicle.spin_sign * vehicle.ktau_nm_per_rad_s2 / vehicle.kf_n_per_rad_s2 * f).sum())
    return {
        "thrust_n": f,
        "cmd": cmd,
        "total_thrust_n": float(f.sum()),
        "moment_nm": np.array([-(f * r[:, 1]).sum(), (f * r[:, 0]).sum(), yaw]),
    }


def hover_shares(vehicle: VehicleConfig, measured_esc: EscCurve) -> np.ndarray:
    """(4,) the omega^2 shares (mean 1) a log of ``vehicle`` in level hover shows, read through ``measured_esc``."""
    cmd = hover_trim(vehicle)["cmd"]
    w2 = measured_esc.cmd_to_rpm(cmd) ** 2
    return w2 / w2.mean()


def pulled_normal(normal: Normal, predicted: np.ndarray, weight_flights: float = PREDICTION_FLIGHTS) -> Normal:
    """``normal`` with its intercept pulled towards ``predicted`` (shares at zero tilt) as ``weight_flights`` flights."""
    m = normal.n_flights
    centre = (weight_flights * np.asarray(predicted) + m * normal.intercept) / (weight_flights + m)
    return dataclasses.replace(normal, intercept=centre, n_flights=weight_flights + m)


def prior_normal(predicted: np.ndarray, flight: FlightSummary, weight_flights: float = PREDICTION_FLIGHTS) -> Normal:
    """A normal with no history: ``predicted`` shares, the population covariance, ``flight``'s own slopes and wander."""
    within = flight.within_cov()
    return Normal(
        intercept=np.asarray(predicted, dtype=np.float64),
        slopes=slopes_of([flight]),
        cov=np.asarray(th.PRIOR_COV, dtype=np.float64),
        own_cov=np.zeros((4, 4)),
        within_block_cov=within if within is not None else np.zeros((4, 4)),
        n_flights=weight_flights,
    )


def calibrated_vehicle(files: list[str], nominal: VehicleConfig, cache_dir: Path | None = None) -> tuple[VehicleConfig, dict]:
    """``propwatch calibrate``'s calibrated vehicle from ``files`` (and its findings), cached in ``cache_dir`` (keyed by
    the logs, the nominal vehicle and the calibrator's source, so a changed calibrator fits again)."""
    calibrator = Path(__file__).resolve().parents[1] / "calibrate"
    code = sorted((p.name, hashlib.sha256(p.read_bytes()).hexdigest()) for p in calibrator.glob("*.py"))
    key = hashlib.sha256(json.dumps([str(Path(f).resolve()) for f in files] + [repr(nominal), code]).encode()).hexdigest()[:16]
    path = cache_dir / f"{key}.json" if cache_dir else None
    if path and path.is_file():
        d = json.loads(path.read_text())
        return from_mapping(VehicleConfig, d["vehicle"], origin=str(path))[0], d["result"]
    from offline.calibrate.calibrate import calibrate_vehicle
    from offline.calibrate.cli import read_measured

    tables = [t for f in files for t in read_measured(Path(f), None, nominal)]
    r = calibrate_vehicle(tables, nominal)
    result = {
        "logs": [str(f) for f in files],
        "cause": r.cause,
        "named": [f["effect"] for f in r.findings],
        "params": {f["effect"]: f["params"] for f in r.findings},
        "gain": {k: v for k, v in r.gain.items() if k != "classifier"},
    }
    if path:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps({"vehicle": dataclasses.asdict(r.calibrated), "result": result}, indent=1))
        tmp.replace(path)
    return r.calibrated, result
