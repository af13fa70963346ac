"""Steady-state calibration of the Crazyflie on its healthy CrazyPAD flights.

Why not ``propwatch calibrate`` directly: its equation-error view needs body
rates and the full attitude, and CrazyPAD's motor logs have neither body rates
nor pitch (``offline.calibrate.prepare`` rejects them: "no airborne stretch
... with motor commands, attitude and rates"). What the motor logs do carry is
the steady-state view of issue 7 (the per-motor command at hover and cruise),
so this module fits that view with the calibrator's own pieces: its term
library (``offline.calibrate.terms.TERMS``) and its trim physics
(``offline.calibrate.physics.trim_commands``).

Data: per flight, the mean command of each motor over the core phases
(``offline.crazypad.real.core_mask``). Model: the trim commands of the vehicle
with the term applied. Each candidate term is fitted by least squares on the
``calibration`` flights of one airframe, scored on its ``holdout`` flights,
and ranked by BIC on the fit flights (k parameters, n = 4 x flights means);
the cause is the best-ranked term that beats the nominal model by more than
``MIN_DELTA_BIC``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from monitor.vehicle import VehicleConfig
from offline.calibrate.physics import G_M_S2, trim_commands
from offline.calibrate.terms import TERMS, Term, apply_terms, stacked

CANDIDATES = ("motor_efficiency", "cg_offset", "mass", "esc_curve")
MIN_DELTA_BIC = 10.0


def predicted_commands(vehicle: VehicleConfig) -> np.ndarray:
    """(4,) trim command in unaccelerated level flight, PX4 rotor order."""
    return trim_commands(vehicle, np.array([vehicle.mass_kg * G_M_S2]))[0]


@dataclass
class TermResult:
    name: str
    params: dict[str, float]
    fit_rms_cmd: float
    holdout_rms_cmd: float
    bic: float
    vehicle: VehicleConfig = field(repr=False)

    def to_dict(self) -> dict:
        return {
            "term": self.name,
            "params": {k: round(v, 6) for k, v in self.params.items()},
            "fit_rms_cmd": round(self.fit_rms_cmd, 1),
            "holdout_rms_cmd": round(self.holdout_rms_cmd, 1),
            "bic": round(self.bic, 2),
        }


def _rms(vehicle: VehicleConfig, measured: np.ndarray) -> float:
    return float(np.sqrt(np.mean((measured - predicted_commands(vehicle)) ** 2))) if len(measured) else float("nan")


def _bic(rms: float, n: int, k: int) -> float:
    return n * math.log(max(rms, 1e-9) ** 2) + k * math.log(n)


def fit_terms(nominal: VehicleConfig, terms: list[Term], fit_cmd: np.ndarray) -> VehicleConfig:
    """Least squares of the trim commands to the per-flight mean commands (F, 4)."""
    x0 = stacked(nominal, terms, "get")
    scale = stacked(nominal, terms, "scale")
    lo, hi = stacked(nominal, terms, "lower"), stacked(nominal, terms, "upper")

    def resid(z: np.ndarray) -> np.ndarray:
        v = apply_terms(nominal, terms, x0 + z * scale)
        return (fit_cmd - predicted_commands(v)).ravel() / 1000.0

    sol = least_squares(resid, np.zeros_like(x0), bounds=((lo - x0) / scale, (hi - x0) / scale), x_scale=1.0)
    return apply_terms(nominal, terms, x0 + sol.x * scale)


def param_dict(vehicle: VehicleConfig, terms: list[Term]) -> dict[str, float]:
    values = stacked(vehicle, terms, "get")
    names = [p for t in terms for p in t.params]
    return dict(zip(names, map(float, values)))


@dataclass
class SteadyCalibration:
    airframe: str
    nominal: VehicleConfig
    calibrated: VehicleConfig
    cause: str | None
    ranking: list[TermResult]
    nominal_fit_rms_cmd: float
    nominal_holdout_rms_cmd: float
    calibrated_holdout_rms_cmd: float
    fit_files: list[str]
    holdout_files: list[str]

    def to_dict(self) -> dict:
        return {
            "airframe": self.airframe,
            "cause": self.cause,
            "why": TERMS[self.cause].why if self.cause else "no term beats the nominal model",
            "ranking": [r.to_dict() for r in self.ranking],
            "nominal_fit_rms_cmd": round(self.nominal_fit_rms_cmd, 1),
            "holdout_rms_cmd": {
                "nominal": round(self.nominal_holdout_rms_cmd, 1),
                "calibrated": round(self.calibrated_holdout_rms_cmd, 1),
            },
            "calibrated_terms": {
                "motor_efficiency": list(self.calibrated.motor_efficiency),
                "cg_offset_frd_m": list(self.calibrated.cg_offset_frd_m),
                "mass_kg": self.calibrated.mass_kg,
            },
            "fit_files": self.fit_files,
            "holdout_files": self.holdout_files,
        }


def calibrate_steady(
    airframe: str,
    nominal: VehicleConfig,
    fit_cmd: np.ndarray,
    holdout_cmd: np.ndarray,
    fit_files: list[str],
    holdout_files: list[str],
    candidates=CANDIDATES,
) -> SteadyCalibration:
    """Fit each candidate on ``fit_cmd`` (F, 4 mean commands, PX4 order), rank, keep the cause.

    The calibrated vehicle carries the cause; a second term is added when it
    lowers the fit BIC by ``MIN_DELTA_BIC`` again (greedy, as ``offline.calibrate.fit``).
    """
    n = fit_cmd.size
    base_rms = _rms(nominal, fit_cmd)
    base_bic = _bic(base_rms, n, 0)
    ranking = []
    for name in candidates:
        v = fit_terms(nominal, [TERMS[name]], fit_cmd)
        k = len(TERMS[name].params)
        ranking.append(
            TermResult(
                name, param_dict(v, [TERMS[name]]), _rms(v, fit_cmd), _rms(v, holdout_cmd), _bic(_rms(v, fit_cmd), n, k), v
            )
        )
    ranking.sort(key=lambda r: r.bic)
    chosen: list[str] = []
    best_bic, calibrated = base_bic, nominal
    for r in ranking:
        terms = [TERMS[t] for t in chosen + [r.name]]
        v = fit_terms(nominal, terms, fit_cmd)
        b = _bic(_rms(v, fit_cmd), n, sum(len(t.params) for t in terms))
        if b < best_bic - MIN_DELTA_BIC:
            chosen.append(r.name)
            best_bic, calibrated = b, v
    return SteadyCalibration(
        airframe,
        nominal,
        calibrated,
        chosen[0] if chosen else None,
        ranking,
        base_rms,
        _rms(nominal, holdout_cmd),
        _rms(calibrated, holdout_cmd),
        fit_files,
        holdout_files,
    )


def equivalent_speed_ratios(calibrated: VehicleConfig, fault_cmd: np.ndarray) -> np.ndarray:
    """(4,) per-rotor speed scale, relative to the calibrated airframe, that reproduces ``fault_cmd``.

    ``fault_cmd`` (F, 4) are the mean commands of flights of one condition; the
    common part (extra mass, battery) is divided out (geometric mean 1), so a
    value below 1 is a rotor that lost thrust: thrust factor = ratio**2.
    """
    v = fit_terms(calibrated, [TERMS["motor_efficiency"]], fault_cmd)
    r = np.asarray(v.motor_efficiency) / np.asarray(calibrated.motor_efficiency)
    return r / np.exp(np.mean(np.log(r)))
