"""Calibration end to end: measured flights + nominal vehicle -> named causes, calibrated vehicle, gain.

1. ``prepare`` cuts the flights into airborne segments and fixes the filters;
2. the nominal model's residuals (equation error) and steady-state command
   errors show what the simulation gets wrong, per signal and flight phase;
3. ``fit.select_terms`` fits every candidate term and keeps those the
   held-out data supports (greedy, BIC); the first one kept is the cause;
4. the chosen terms are written onto the vehicle (``writer``);
5. the gain is the held-out residual RMS before and after, and the steady-state
   command error before and after.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from monitor.flight import FlightTable
from monitor.vehicle import VehicleConfig
from offline.calibrate.fit import Data, Selection, TermFit, combined_rms, fit_terms, rms_by_signal, select_terms
from offline.calibrate.prepare import Segment, prepare
from offline.calibrate.steady import steady_state
from offline.calibrate.terms import TERMS, Term
from offline.calibrate.unbalance import unbalance_ratio
from offline.calibrate.unexplained import delay_probe, one_rotor_reading, unexplained_residual

PHASES = ("hover", "cruise", "climb", "manoeuvre")
LAG_TERMS = ("motor_time_constant", "rotor_time_constant")
# The resolution of the lag terms on 20 Hz telemetry, so a report that names no lag says how large a lag could still
# hide. Measured at the gates in force (held-out gain 80, consistency 3.55 standard errors, the spin-up reaction in
# the lag terms) with ``python -m bench.evalsim_lag --out out/lagres --duration-s 40 --lags-ms 45 60 90 --pattern
# common one --jitter-ms 4 --seeds 0 1`` (2 x 40 s): all four rotors at 60 and 90 ms named 2 of 2 (45 ms: 1 of 2);
# one rotor at 90 ms named 2 of 2 (held-out gains 217 and 323), at 60 ms 0 of 2 (gains 59.8 and 59.0, under the
# gate) and at 45 ms 0 of 2. At the previous gates (held-out gain 60) one rotor at 60 ms was named 2 of 2 with
# gains of 64-65. The hidden-effect matrix's flights (5 other seeds, docs/CALIBRATION.md) name one rotor at 60 and
# 90 ms 5 of 5 and at 45 ms 0 of 5: 60 ms is named in 5 of 7 runs in all, 90 ms in 7 of 7. On 2 x 80 s flights: ``python -m bench.yaw_spinup evalsim`` (docs/CALIBRATION.md, "Yaw under a
# motor lag").
LAG_RESOLUTION_NOTE = (
    "no motor lag named. Resolution measured at 20 Hz (bench/evalsim_lag.py: evaluation simulator, 2 x 40 s "
    "flights, 4 ms telemetry jitter, nominal lag 20 ms): one slow rotor is named from about {one} ms, all four "
    "rotors slower from about {common} ms; a smaller lag can be present unnamed"
)
LAG_RESOLUTION_MS = {"one": 90, "common": 60}
# A named motor_efficiency that singles out one rotor: its thrust efficiency off the other three's mean by at least
# INSPECT_MIN_DEVIATION and by INSPECT_OUTLIER_RATIO times the others' own half-range. Four efficiencies span every
# static thrust and moment pattern, so a damaged propeller (thrust lost, torque per thrust changed) on that rotor
# fits as a weak motor plus a small spread in the yaw pattern: the logs cannot tell them apart. 5 % is below the
# smallest propeller damage the hidden-effect matrix draws (8 % thrust loss at hover, bench/evalsim_calibration.py)
# and above the +-1 % spread of the evaluation simulator's healthy airframes; the ratio keeps a four-way spread
# (each rotor off by a similar amount; the matrix's pattern +-s, +-s/2 gives 1.8) from singling one out. How often
# it appears on damaged, weak and spread runs: ``python -m bench.evalsim_calibration`` (column inspect_rotor) and
# ``python -m bench.evalsim_inspect`` (with the one-rotor reading); docs/CALIBRATION.md.
INSPECT_MIN_DEVIATION = 0.05
INSPECT_OUTLIER_RATIO = 2.0


@dataclass
class CalibrationResult:
    sources: list[str]
    nominal: VehicleConfig
    calibrated: VehicleConfig
    selection: Selection
    segments: list[Segment]
    data: Data
    cause: str | None
    confidence: float
    findings: list[dict]
    candidates: dict[str, dict]
    residuals: dict[str, dict]
    steady: dict[str, dict]
    unbalance: dict
    gain: dict
    notes: list[str] = field(default_factory=list)
    unexplained: dict = field(default_factory=dict)
    inspect_rotor: dict | None = None

    def to_json(self) -> dict:
        return {
            "cause": self.cause,
            "confidence": self.confidence,
            "findings": self.findings,
            "gain": self.gain,
            "candidates": self.candidates,
            "residuals_by_phase": self.residuals,
            "steady_state": self.steady,
            "unbalance_ratio": self.unbalance,
            "logs": self.sources,
            "notes": self.notes,
            "unexplained_residual": self.unexplained,
            "inspect_rotor": self.inspect_rotor,
            "selection_rounds": [
                {"chosen": step.chosen, "verdicts": {n: v.to_dict() for n, v in step.verdicts.items()}}
                for step in self.selection.steps
            ],
        }


def residuals_by_phase(segments: list[Segment], res: list[dict[str, np.ndarray]]) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for phase in ("all",) + PHASES:
        masks = [s.valid & ((s.phase == phase) if phase != "all" else True) for s in segments]
        if sum(int(m.sum()) for m in masks) < 10:
            continue
        out[phase] = rms_by_signal(res, masks)
    return out


def _round(d: dict[str, float], nd: int = 6) -> dict[str, float]:
    return {k: float(f"{v:.{nd}g}") for k, v in d.items()}


def _evidence(
    term: Term,
    before: dict[str, float],
    after: TermFit,
    sigma: dict[str, float],
    runner_up: tuple[str, float] | None,
    delta_bic: float,
) -> list[str]:
    drops = sorted(before, key=lambda s: (after.held_rms[s] - before[s]) / sigma[s])
    lines = [f"{s}: held-out RMS {before[s]:.4g} -> {after.held_rms[s]:.4g}" for s in drops[:3] if after.held_rms[s] < before[s]]
    lines.append(f"held-out BIC improves by {delta_bic:.1f} over the model without it")
    if runner_up:
        lines.append(f"next best alternative {runner_up[0]} is {runner_up[1]:.1f} BIC worse")
    lines.append(term.why)
    return lines


def vetoed_leader_notes(sel: Selection) -> list[str]:
    """One line per round in which a gate, not a better candidate, kept out the term with the largest held-out gain."""
    out = []
    for k, step in enumerate(sel.steps):
        v = step.vetoed_leader()
        if v is None:
            continue
        named = f"; {step.chosen} is named instead" if step.chosen else "; nothing is named in this round"
        out.append(
            f"round {k + 1}: {v.term} has the largest held-out BIC gain ({v.gain:.1f}) but the {v.gate} gate rejects it: "
            f"{v.why}{named}"
        )
    return out


def inspect_rotor(efficiency: list[float]) -> dict | None:
    """The rotor a named ``motor_efficiency`` singles out, and why it should be inspected; None when none stands out."""
    e2 = np.asarray(efficiency, dtype=np.float64) ** 2  # thrust efficiencies
    dev = np.array([e2[k] / np.delete(e2, k).mean() - 1.0 for k in range(4)])
    k = int(np.argmax(np.abs(dev)))
    others = np.delete(e2, k)
    half_range = float((others.max() - others.min()) / 2.0 / others.mean())
    if abs(dev[k]) < INSPECT_MIN_DEVIATION or abs(dev[k]) < INSPECT_OUTLIER_RATIO * half_range:
        return None
    return {
        "rotor": k + 1,
        "thrust_vs_others_pct": round(float(100 * dev[k]), 1),
        "others_half_range_pct": round(100 * half_range, 1),
        "why": (
            f"motor_efficiency singles out rotor {k + 1} ({100 * dev[k]:+.1f} % thrust against the other three, which "
            f"agree within {100 * half_range:.1f} %): a damaged propeller on rotor {k + 1} (thrust lost, its torque per "
            "thrust changed) would look the same in these logs, as a weak motor plus a small yaw-pattern spread. "
            f"Inspect rotor {k + 1}'s propeller before trusting this calibration: a damaged propeller calibrated into "
            "the vehicle's normal hides it from the monitor"
        ),
    }


def calibrate_vehicle(
    tables: list[FlightTable], nominal: VehicleConfig, candidates: list[str] | None = None
) -> CalibrationResult:
    segments = prepare(tables, nominal)
    data = Data.split(segments)
    terms = [TERMS[n] for n in (candidates or list(TERMS))]
    sel = select_terms(data, nominal, terms, rival=delay_probe)
    final = sel.final
    calibrated = final.vehicle if final else nominal
    sigma = sel.sigma
    nominal_held = rms_by_signal(sel.nominal_residuals, data.held_masks)

    findings, before = [], nominal_held
    for step in sel.steps:
        if not step.chosen:
            break
        fit = step.trials[step.chosen]
        term = TERMS[step.chosen]
        others = sorted((f.bic - fit.bic, n) for n, f in step.trials.items() if n != step.chosen and all(f.identifiable.values()))
        findings.append(
            {
                "effect": step.chosen,
                "params": _round(fit.params(term)),
                "std": _round(fit.stds(term), 3),
                "residual_rms_before": round(combined_rms(before, sigma), 6),
                "residual_rms_after": round(combined_rms(fit.held_rms, sigma), 6),
                "score": round(step.base_bic - fit.bic, 3),
                "confidence": round(step.confidence, 4),
                "residual_rms_by_signal_before": _round(before),
                "residual_rms_by_signal_after": _round(fit.held_rms),
                "evidence": _evidence(
                    term, before, fit, sigma, (others[0][1], others[0][0]) if others else None, step.base_bic - fit.bic
                ),
            }
        )
        before = fit.held_rms
    if final is not None:  # joint refit values replace the step-wise ones
        for f in findings:
            f["params"] = _round(final.params(TERMS[f["effect"]]))
            f["std"] = _round(final.stds(TERMS[f["effect"]]), 3)

    candidates_out = {}
    first = sel.steps[0]
    for name, fit in first.trials.items():
        term = TERMS[name]
        ident = all(fit.identifiable.values())
        candidates_out[name] = {
            "identifiable": ident,
            "score": round(first.base_bic - fit.bic, 3) if ident else None,
            "params": _round(fit.params(term)) if ident else None,
            "std": _round(fit.stds(term), 3) if ident else None,
            "residual_rms_after": round(combined_rms(fit.held_rms, sigma), 6) if ident else None,
            "reason": fit.reasons.get(name, ""),
            "verdict": first.verdicts[name].to_dict(),
        }

    # The paper's unbalance ratio against the fitted motor_efficiency, same held-out data.
    ur = unbalance_ratio(segments, data.fit_masks, nominal)
    ur_res = data.residuals(nominal, ur.speed_scale)
    eff_fit = first.trials.get("motor_efficiency") or fit_terms(
        data, nominal, [TERMS["motor_efficiency"]], TERMS["motor_efficiency"].get(nominal), sigma
    )
    unbalance = {
        "ratio": _round(ur.params()),
        "residual_rms_nominal": round(combined_rms(nominal_held, sigma), 6),
        "residual_rms_unbalance_ratio": round(combined_rms(rms_by_signal(ur_res, data.held_masks), sigma), 6),
        "residual_rms_fitted_motor_efficiency": round(combined_rms(eff_fit.held_rms, sigma), 6),
        "steady_state_unbalance_ratio": steady_state(segments, nominal, data.held_masks, ur.speed_scale),
    }

    nominal_res = residuals_by_phase(segments, sel.nominal_residuals)
    calib_res = residuals_by_phase(segments, final.residuals) if final else nominal_res
    steady_nom = steady_state(segments, nominal, data.held_masks)
    steady_cal = steady_state(segments, calibrated, data.held_masks)
    after_held = final.held_rms if final else nominal_held
    gain = {
        "heldout_residual_rms_before": round(combined_rms(nominal_held, sigma), 6),
        "heldout_residual_rms_after": round(combined_rms(after_held, sigma), 6),
        "heldout_residual_rms_by_signal_before": _round(nominal_held),
        "heldout_residual_rms_by_signal_after": _round(after_held),
        "steady_state_cmd_error_rms_before": {p: round(v["error_rms"], 4) for p, v in steady_nom.items()},
        "steady_state_cmd_error_rms_after": {p: round(v["error_rms"], 4) for p, v in steady_cal.items()},
        "classifier": {
            "done": False,
            "reason": "the measured logs carry no fault labels, so no classifier is scored on them; the gain "
            "measured is the held-out residual before and after (docs/CALIBRATION.md)",
        },
    }
    gain["heldout_residual_reduction_pct"] = round(
        100.0 * (1.0 - gain["heldout_residual_rms_after"] / gain["heldout_residual_rms_before"]), 3
    )
    notes = vetoed_leader_notes(sel)
    if not {f["effect"] for f in findings} & set(LAG_TERMS) and set(LAG_TERMS) & set(candidates_out):
        note = LAG_RESOLUTION_NOTE.format(**LAG_RESOLUTION_MS)
        rate_hz = 1.0 / segments[0].dt_s
        if abs(rate_hz - 20.0) > 0.5:
            note += f" (these logs are {rate_hz:.0f} Hz: not measured at that rate)"
        for name in LAG_TERMS:
            c = candidates_out.get(name)
            if c and c["identifiable"]:
                fitted = ", ".join(f"{1000 * v:.0f}" for k, v in c["params"].items() if k.endswith("_s"))
                v = first.verdicts[name]
                note += f"; {name} alone fits {fitted} ms, held-out BIC gain {c['score']:.1f}, not named: {v.why}"
        notes.append(note)
    inspect = None
    if "motor_efficiency" in {f["effect"] for f in findings}:
        inspect = inspect_rotor(list(calibrated.motor_efficiency))
        if inspect:
            # The other three at their common level (with mass or the ESC named beside, that level carries part of
            # the collective), rotor k free.
            level = float(np.mean(np.delete(np.asarray(calibrated.motor_efficiency), inspect["rotor"] - 1)))
            base = dataclasses.replace(calibrated, motor_efficiency=(level,) * 4)
            one = one_rotor_reading(data, base, inspect["rotor"] - 1, sigma)
            inspect["if_only_this_rotor"] = one
            inspect["why"] += (
                f". Read as rotor {inspect['rotor']} alone (the other three equal): thrust "
                f"{one['thrust_pct']:+.1f} %, torque per thrust {one['torque_per_thrust_pct']:+.1f} % (held-out BIC "
                f"{one['torque_heldout_bic_gain']:.1f} for that torque change); a motor or ESC moves thrust and torque "
                "alike, a damaged propeller changes its torque per thrust, but a +-2 % spread of the other three moves "
                "this reading by as much as a damaged propeller does (python -m bench.evalsim_inspect): a hint for the "
                "inspection, not a verdict"
            )
            notes.append(inspect["why"])
    unexplained = unexplained_residual(data, calibrated, final.residuals if final else sel.nominal_residuals)
    if unexplained["found"]:
        notes.append(f"unexplained residual (no term of the library can express it): {unexplained['summary']}")
    return CalibrationResult(
        sources=[t.source or f"flight {i}" for i, t in enumerate(tables)],
        nominal=nominal,
        calibrated=calibrated,
        selection=sel,
        segments=segments,
        data=data,
        cause=findings[0]["effect"] if findings else None,
        confidence=findings[0]["confidence"] if findings else 0.0,
        findings=findings,
        candidates=candidates_out,
        residuals={"nominal": nominal_res, "calibrated": calib_res},
        steady={"nominal": steady_nom, "calibrated": steady_cal},
        unbalance=unbalance,
        gain=gain,
        notes=notes,
        unexplained=unexplained,
        inspect_rotor=inspect,
    )
