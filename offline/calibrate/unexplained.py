"""What the calibrated model still gets wrong that no term of the library can express: "unexplained residual".

After selection, small probes outside the term library are fitted to the calibrated model's residual, each a
linear regression through the same filters as the model (``physics.integrated``), fitted on the fit blocks
and scored on the held-out blocks with the selection's BIC (``fit.bic``: correlation-time corrected):

- ``rotor_torque`` (one per rotor, 1 parameter): rotor i's drag torque off its thrust by a factor, seen in the
  yaw equation alone. The library scales a rotor's thrust and torque together (``motor_efficiency``); a damaged
  or mismatched propeller changes its torque per unit thrust, which no term can;
- ``timing`` (1 parameter): the measured roll and pitch motion leads or trails the predicted moments by a common
  time, as a telemetry delay between the motor outputs and the estimator's attitude and rates would make it (a
  remaining timing error after any lag term). Roll and pitch only: on our own simulator's nominal flights the yaw
  equation leads its prediction by 50-80 ms (the rotors' inertia reacting on the body as they change speed, which
  neither the library nor this probe models), and a probe on yaw named that on 4 of 4 pairs.

A probe whose held-out BIC gain exceeds the selection's gate (``fit.MIN_DELTA_BIC``) is reported with its size
(the held-out RMS it removes, per signal) and where it sits (signal, rotor); the cause stays whatever the library
named: a probe never becomes a term of the calibrated vehicle.
"""

from __future__ import annotations

import numpy as np

from monitor.vehicle import VehicleConfig
from offline.calibrate.fit import MIN_DELTA_BIC, Data, bic, rms_by_signal
from offline.calibrate.physics import ROT_SIGNALS, angular_accel, integrated, rotor_forces

YAW = "yaw_accel_rad_s2"


def _regressors(data: Data, vehicle: VehicleConfig) -> dict[str, list[dict[str, np.ndarray]]]:
    """Per probe, per segment: the probe's unit-parameter contribution to each residual signal it enters."""
    J = np.asarray(vehicle.inertia_diag_kg_m2)
    out: dict[str, list[dict[str, np.ndarray]]] = {f"rotor_torque_{i + 1}": [] for i in range(4)}
    out["timing"] = []
    for seg in data.segments:
        f, tau = rotor_forces(seg, vehicle)
        for i in range(4):
            # Rotor i's torque 1 % high: the yaw acceleration it adds, through the model's own filter.
            x = integrated(seg, vehicle.spin_sign[i] * tau[:, i] / J[2])
            out[f"rotor_torque_{i + 1}"].append({YAW: x})
        _, pred = angular_accel(seg, vehicle, f, tau)
        d = np.gradient(pred, seg.dt_s, axis=0)  # measured = predicted a time t later: residual ~ -t d(pred)/dt
        out["timing"].append({s: -d[:, k] for k, s in enumerate(ROT_SIGNALS[:2])})
    return out


def _fit_probe(res, reg, data: Data, weights: dict[str, float]) -> float:
    """Weighted least squares of one parameter on the fit blocks."""
    num = den = 0.0
    for r, g, m in zip(res, reg, data.fit_masks):
        for s, x in g.items():
            ok = m & np.isfinite(x) & np.isfinite(r[s])
            num += float(np.sum(x[ok] * r[s][ok])) / weights[s] ** 2
            den += float(np.sum(x[ok] ** 2)) / weights[s] ** 2
    return num / den if den > 0 else 0.0


def unexplained_residual(data: Data, vehicle: VehicleConfig, res: list[dict[str, np.ndarray]]) -> dict:
    """Probes on the residual ``res`` of ``vehicle``; ``found`` when one clears the selection's gate."""
    base_bic = bic(res, data.held_masks, 0, data.n_fit, data.corr_time)
    base_rms = rms_by_signal(res, data.held_masks)
    weights = {s: max(v, 1e-9) for s, v in rms_by_signal(res, data.fit_masks).items()}
    probes = {}
    for name, reg in _regressors(data, vehicle).items():
        beta = _fit_probe(res, reg, data, weights)
        after = [{s: r[s] - beta * g[s] if s in g else r[s] for s in r} for r, g in zip(res, reg)]
        rms = rms_by_signal(after, data.held_masks)
        gain = base_bic - bic(after, data.held_masks, 1, data.n_fit, data.corr_time)
        signals = list(reg[0])
        probes[name] = {
            "heldout_bic_gain": round(gain, 1),
            "value": round(beta, 5),
            "unit": "s (measured motion later than predicted)" if name == "timing" else "fraction of the rotor's torque",
            "heldout_rms_cut": {s: round(base_rms[s] - rms[s], 6) for s in signals},
            "heldout_rms_cut_pct": {s: round(100 * (1 - rms[s] / base_rms[s]), 2) for s in signals if base_rms[s] > 0},
        }
    # One rotor at a time: keep only the best rotor's torque probe.
    rotor = max((n for n in probes if n.startswith("rotor_torque_")), key=lambda n: probes[n]["heldout_bic_gain"])
    kept = {n: p for n, p in probes.items() if n == rotor or n == "timing"}
    found = {n: p for n, p in kept.items() if p["heldout_bic_gain"] > MIN_DELTA_BIC}
    lines = []
    for n, p in sorted(found.items(), key=lambda kv: -kv[1]["heldout_bic_gain"]):
        where = max(p["heldout_rms_cut_pct"], key=p["heldout_rms_cut_pct"].get)
        at = f", rotor {n.rsplit('_', 1)[1]}" if n.startswith("rotor_torque_") else ""
        lines.append(
            f"{n} ({p['value']:+.3g} {p['unit'].split(' (')[0]}): {where}{at}, held-out RMS "
            f"{p['heldout_rms_cut_pct'][where]:.1f} % of it, held-out BIC gain {p['heldout_bic_gain']:.1f} > {MIN_DELTA_BIC:g}"
        )
    return {
        "found": bool(found),
        "summary": "; ".join(lines) if lines else "none above the gate",
        "threshold": MIN_DELTA_BIC,
        "probes": kept,
    }
