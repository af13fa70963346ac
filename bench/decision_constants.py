"""The decision layer's constants that describe our simulator's healthy flights, measured beside their shipped values.

    nice -n 10 python -m bench.decision_constants                # 96 + 48 healthy flights of 80 s, about 2 min on 2 cores
    python -m bench.decision_constants --flights 16 --nominal-flights 8 --json out/decision-constants.json

Two sets of healthy flights of OUR simulator (never the evaluation-only ``offline/evalsim``), deterministic by seed:

- ``randomised``: ``FlightSet("healthy", --flights, seed=--seed, physics="randomised", pickup_fraction=0.25)``, the
  flights ``python -m bench.alerts_flights --set ours-healthy --seed 100 --flights 96`` classifies (seed 100 is the
  calibration seed of ``propwatch tune alerts``): every term of the assumption register drawn, the airframe's too,
  telemetry degraded; a quarter pick up or drop a payload mid-flight.
- ``nominal``: the register with the airframe's own terms at their nominal values
  (``offline.sim.assumptions.nominal_airframe``): the vehicle as its file says, what ``Priors()`` assumes.

Each row prints the constant, its shipped value, what this run measures and how. Nothing here changes a constant.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from types import SimpleNamespace

import numpy as np

from monitor.decision.config import DecisionConfig
from monitor.decision.effectiveness import (
    OWN_BASELINE_STD_FLOOR,
    PLAUSIBLE_EFFECTIVENESS,
    Evidence,
    HypothesisBank,
    Priors,
    RotorGeometry,
)
from monitor.decision.network_gate import RPM_RATIO_WARN, RPM_Z_WARN
from monitor.decision.regime import COLLECTIVE_MEDIAN_S, heading_velocity
from monitor.decision.replay import FlightSteps, replay
from monitor.decision.rotor_share import (
    _AXES,
    _U,
    DRAG_SLOPE_PRIOR_SD,
    FLAP_SLOPE_PRIOR_SD,
    SHARE_AVERAGE_S,
    SHARE_SIGMA,
    YAW_FREE_GAP,
    YAW_FREE_RISE,
    YAW_SIGMA,
    RotorShare,
)
from monitor.decision.rule import Decision, WindowEvidence
from monitor.diagnose.engine import LARGE_ATTITUDE_MAX_FRACTION, rpm_envelope
from monitor.model import Classifier
from monitor.vehicle import REPO_ROOT, load_vehicle

AXES = ("roll", "pitch", "yaw")


def randomised_set(vehicle, n: int, seed: int):
    """Per flight: (name, degraded signals, FlightLog, index in the log, payload step (fraction of the mass) or None)."""
    from offline.alerts.flights import FlightSet, randomised_chunks
    from offline.dataset.generate import degraded_signals

    out = []
    for ch in randomised_chunks(vehicle, FlightSet("healthy", n, seed=seed, physics="randomised", pickup_fraction=0.25)):
        sig = degraded_signals(ch.flog, ch.phys)
        for b, name in enumerate(ch.names):
            step = float(name.split("pickup")[1].split("@")[0]) if "pickup" in name else None
            out.append((name, {k: v[b] for k, v in sig.items()}, ch.flog, b, step))
        print(f"randomised: {len(out)}/{n} flights", file=sys.stderr)
    return out


def nominal_set(vehicle, n: int, seed: int, chunk: int = 8):
    """Per flight: degraded signals of a healthy flight of the nominal airframe."""
    from offline.dataset.generate import DatasetSpec, routes, simulate_randomised
    from offline.sim.assumptions import nominal_airframe

    spec = DatasetSpec(
        "decision-constants-nominal", waypoints=("random",), propellers="quadratic", physics="randomised", seed=seed
    )
    payload = np.random.default_rng([seed, 17]).uniform(0.0, 0.6, n)  # FlightSet's default payload range
    wps = routes(spec, n, seed=seed)[0]
    register = nominal_airframe()
    out = []
    for c0 in range(0, n, chunk):
        idx = np.arange(c0, min(n, c0 + chunk))
        sig = simulate_randomised(spec, vehicle, idx, np.zeros((len(idx), 4), np.int8), payload[idx], wps[idx], register)
        out += [{k: np.asarray(v[b], np.float64) for k, v in sig.items()} for b in range(len(idx))]
        print(f"nominal: {len(out)}/{n} flights", file=sys.stderr)
    return out


def balances(signals: list[dict], geometry: RotorGeometry) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Each flight's finite (z, H, std) of its non-overlapping 5 s windows after the first 5 s (as ``propwatch tune
    noise`` and ``propwatch tune sets`` read them)."""
    from offline.tune.noise import flight_balances

    ds = SimpleNamespace(
        signals={k: np.stack([s[k] for s in signals]) for k in signals[0]}, n_flights=len(signals), sample_rate_hz=20.0
    )
    out = []
    for z, h, std in flight_balances(ds, geometry):
        ok = np.isfinite(z).all(axis=1) & np.isfinite(h).all(axis=(1, 2)) & np.isfinite(std).all(axis=1)
        out.append((z[ok], h[ok], std[ok]))
    return out


def q(x, p) -> float:
    return round(float(np.quantile(np.asarray(x), p)), 4)


def per_axis(x: np.ndarray) -> str:
    return " / ".join(f"{v:.4f}" for v in x)


def readings(bal, geometry: RotorGeometry, p: Priors) -> np.ndarray:
    """(flights, 4) diagnose's effectiveness reading of each whole flight (``monitor.diagnose.physics.physics_evidence``:
    the thrust fraction under ``for_measurement`` priors, of the set most probable under ``p``)."""
    bank, measure = HypothesisBank(p, geometry), HypothesisBank(p.for_measurement(), geometry)
    out = []
    for z, h, s in bal:
        ev = Evidence()
        ev.add(z, h, s, p)
        out.append(measure.posterior(ev).thrust_fraction[bank.posterior(ev).best])
    return np.array(out)


def outside(eta: np.ndarray) -> int:
    lo, hi = PLAUSIBLE_EFFECTIVENESS
    return int(np.sum(((eta < lo) | (eta > hi)).any(axis=1)))


def balance_rows(nominal_bal, randomised_bal, geometry: RotorGeometry, vehicle) -> list[dict]:
    p = Priors()
    win_std = np.concatenate([s for _, _, s in nominal_bal])  # (windows, 3): each window's sub-block noise
    scatter = np.array([z.std(axis=0, ddof=1) for z, _, _ in nominal_bal if len(z) >= 2])  # (flights, 3)
    means = np.array([z.mean(axis=0) for z, _, _ in nominal_bal if len(z)])  # (flights, 3)
    from offline.sim.assumptions import REGISTER

    spread = REGISTER["healthy_torque_per_thrust_spread_frac"]
    eta_nominal, eta = readings(nominal_bal, geometry, p), readings(randomised_bal, geometry, p)
    lo, hi = PLAUSIBLE_EFFECTIVENESS
    return [
        {
            "constant": "effectiveness.Priors.noise_floor",
            "shipped": p.noise_floor,
            "measured": {
                "window_noise_p10_roll_pitch_yaw": np.quantile(win_std, 0.1, axis=0).round(4).tolist(),
                "window_noise_p50_roll_pitch_yaw": np.quantile(win_std, 0.5, axis=0).round(4).tolist(),
                "within_flight_scatter_p50_roll_pitch_yaw": np.median(scatter, axis=0).round(4).tolist(),
                "windows_floored_roll_pitch_yaw": np.mean(win_std < p.noise_floor, axis=0).round(3).tolist(),
            },
            "how": f"nominal airframe, {len(win_std)} windows of 5 s at 20 Hz: each window's sub-block noise "
            f"(p10 {per_axis(np.quantile(win_std, 0.1, axis=0))}, p50 {per_axis(np.quantile(win_std, 0.5, axis=0))}) and "
            f"the std of a flight's windows (median over flights {per_axis(np.median(scatter, axis=0))}); windows whose "
            f"noise the floor raises: {per_axis(np.mean(win_std < p.noise_floor, axis=0))}",
        },
        {
            "constant": "effectiveness.OWN_BASELINE_STD_FLOOR",
            "shipped": OWN_BASELINE_STD_FLOOR,
            "measured": {"within_flight_scatter_p10_roll_pitch_yaw": np.quantile(scatter, 0.1, axis=0).round(4).tolist()},
            "how": f"std of a nominal flight's 5-s balances, p10 over {len(scatter)} flights: "
            f"{per_axis(np.quantile(scatter, 0.1, axis=0))}",
        },
        {
            "constant": "effectiveness.Priors.yaw_trim_std",
            "shipped": p.yaw_trim_std,
            "measured": {"flight_mean_std_roll_pitch_yaw": means.std(axis=0, ddof=1).round(4).tolist()},
            "how": f"flight-to-flight std of the flight-mean balance, nominal airframe ({len(means)} flights): "
            f"{per_axis(means.std(axis=0, ddof=1))} (roll/pitch prior 4 cg_offset_std_m / L = "
            f"{4 * p.cg_offset_std_m / geometry.arm_m:.4f})",
        },
        {
            "constant": "effectiveness.Priors.healthy_torque_spread_std",
            "shipped": p.healthy_torque_spread_std,
            "measured": {"register_uniform_std": round((spread.high - spread.low) / math.sqrt(12.0), 4)},
            "how": f"the register's healthy_torque_per_thrust_spread_frac, uniform {spread.low:+g}..{spread.high:+g}: std "
            f"{(spread.high - spread.low) / math.sqrt(12.0):.4f} (a range, not a measurement: see its reason)",
        },
        {
            "constant": "effectiveness.PLAUSIBLE_EFFECTIVENESS",
            "shipped": list(PLAUSIBLE_EFFECTIVENESS),
            "measured": {
                "nominal_eta_min_max": [round(float(eta_nominal.min()), 4), round(float(eta_nominal.max()), 4)],
                "randomised_eta_min_max": [round(float(eta.min()), 4), round(float(eta.max()), 4)],
                "randomised_flights_outside": outside(eta),
            },
            "how": f"diagnose's effectiveness reading, whole flight: nominal airframe {eta_nominal.min():.3f}.."
            f"{eta_nominal.max():.3f} ({outside(eta_nominal)} of {len(eta_nominal)} flights outside {lo}-{hi}); drawn "
            f"airframes {eta.min():.3f}..{eta.max():.3f} ({outside(eta)} of {len(eta)} outside)",
        },
    ]


def share_rows(flights: list) -> list[dict]:
    from bench.alerts_flights import share_spread

    sp = share_spread([SimpleNamespace(motor_rpm=np.asarray(s["motor_rpm"], np.float64), rate_hz=20.0) for _, s, *_ in flights])
    x, y, r = sp["quantiles_abs"], sp["yaw_balance"]["quantiles_abs"], sp["largest_yaw_free_rise_10s"]
    return [
        {
            "constant": "rotor_share.SHARE_SIGMA",
            "shipped": SHARE_SIGMA,
            "measured": {"rms": sp["std"], "q99": x[0.99], "q999": x[0.999], "q99_half": round(x[0.99] / 2, 4)},
            "how": f"yaw-free share (mean over {SHARE_AVERAGE_S:g} s) less the flight's first 10 s: rms {sp['std']}, "
            f"99 % within {x[0.99]}, 99.9 % within {x[0.999]}; sigma = 99 % / 2 = {x[0.99] / 2:.4f}",
        },
        {
            "constant": "rotor_share.YAW_SIGMA",
            "shipped": YAW_SIGMA,
            "measured": {"rms": sp["yaw_balance"]["std"], "q99": y[0.99], "q99_half": round(y[0.99] / 2, 4)},
            "how": f"yaw balance (mean over 10 s) less the flight's first 10 s: rms {sp['yaw_balance']['std']}, "
            f"99 % within {y[0.99]}; sigma = 99 % / 2 = {y[0.99] / 2:.4f}",
        },
        {
            "constant": "rotor_share.YAW_FREE_RISE",
            "shipped": YAW_FREE_RISE,
            "measured": {"q99": r[0.99], "q999": r[0.999]},
            "how": f"largest rotor's yaw-free rise over 10 s against the first 10 s: 99 % {r[0.99]}, 99.9 % {r[0.999]}",
        },
    ]


class _ShareProbe(RotorShare):
    """The decision's ``RotorShare``, recording what each tested window's evidence is formed from (read-only)."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.residual, self.yaw_dev, self.rises = [], [], []

    def llr(self, dt_s: float = 0.0, quiet: bool = False, yaw_quiet: bool | None = None):
        if self.baseline is not None and self._n >= self.window:
            trims = _AXES @ (self._ring.sum(axis=0) / self.window)
            pred, _ = self.line(self._mean_regressors(self._vring))
            self.residual.append(_U @ (trims - pred))  # each rotor's yaw-free share less the plane
            if self._yn >= self.yaw_window:
                self.yaw_dev.append(float(self._yring.sum() / self.yaw_window) - self.yaw_baseline)
            rise = self.yaw_free_rise()
            if rise is not None:
                self.rises.append(rise)
        return super().llr(dt_s, quiet, yaw_quiet)


def decision_rows(flights: list, window: int) -> list[dict]:
    """The shares' evidence as the decision forms it: each flight replayed through ``Decision`` (regime holds, the
    plane, the yaw baseline), the network's evidence a constant 0 (it does not move the shares' path)."""
    cfg = DecisionConfig()
    res, dev, rises = [], [], []
    for _, s, flog, b, *_ in flights:
        rpm = np.asarray(s["motor_rpm"], np.float64)
        rates = np.stack([s[k] for k in ("roll_rate_rad_s", "pitch_rate_rad_s", "yaw_rate_rad_s")], 1)
        steps = FlightSteps(
            airborne=np.ones(len(rpm), dtype=bool),
            motor_rpm=rpm,
            tilt_rad=np.maximum(np.abs(s["roll_rad"]), np.abs(s["pitch_rad"])),
            rate_rad_s=np.abs(rates).max(axis=1),
            battery_v=flog.battery_v[b].astype(np.float64),
            vel_heading_m_s=heading_velocity(flog.vel_ned_m_s[b], s["yaw_rad"]),
            accel_xy_frd_m_s2=flog.accel_frd_m_s2[b][:, :2].astype(np.float64),
        )
        d = Decision(cfg, 20.0, window)
        d.share = probe = _ShareProbe(window, 20.0, cfg.min_thrust_loss, average_s=SHARE_AVERAGE_S)
        none = WindowEvidence(np.zeros(4))
        replay(d, steps, (np.arange(len(rpm)) + 1) / 20.0, {j: none for j in range(window - 1, len(rpm))})
        res += probe.residual
        dev += probe.yaw_dev
        rises += probe.rises
    e, y, r = np.abs(np.array(res)).ravel(), np.abs(np.array(dev)), np.array(rises)
    top = r.max(axis=1)
    adjacent = np.abs(r[:, [0, 0, 1, 1]] - r[:, [2, 3, 2, 3]]).max(axis=1)  # rotors sharing a side: 1-3, 1-4, 2-3, 2-4
    at_rise = float(np.mean(top <= YAW_FREE_RISE))
    return [
        {
            "constant": "rotor_share.SHARE_SIGMA (as the decision forms it)",
            "shipped": SHARE_SIGMA,
            "measured": {"rms": round(float(np.sqrt(np.mean(e**2))), 4), "q99": q(e, 0.99), "q999": q(e, 0.999)},
            "how": f"each rotor's 2-s yaw-free share less the decision's plane, {len(res)} tested windows: rms "
            f"{np.sqrt(np.mean(e**2)):.4f}, 99 % within {q(e, 0.99)}, 99.9 % within {q(e, 0.999)}; sigma = 99 % / 2 = "
            f"{q(e, 0.99) / 2:.4f}",
        },
        {
            "constant": "rotor_share.YAW_SIGMA (as the decision forms it)",
            "shipped": YAW_SIGMA,
            "measured": {"rms": round(float(np.sqrt(np.mean(y**2))), 4), "q99": q(y, 0.99)},
            "how": f"10-s yaw balance less the decision's yaw baseline, {len(y)} windows: rms {np.sqrt(np.mean(y**2)):.4f}, "
            f"99 % within {q(y, 0.99)}; sigma = 99 % / 2 = {q(y, 0.99) / 2:.4f}",
        },
        {
            "constant": "rotor_share.YAW_FREE_RISE (as the decision forms it)",
            "shipped": YAW_FREE_RISE,
            "measured": {"q99": q(top, 0.99), "q999": q(top, 0.999), "quantile_of_shipped": round(at_rise, 4)},
            "how": f"largest rotor's rise (yaw_free_rise) at every tested window: 99 % {q(top, 0.99)}, 99.9 % "
            f"{q(top, 0.999)}; {YAW_FREE_RISE} is the {100 * at_rise:.1f} % quantile",
        },
        {
            "constant": "rotor_share.YAW_FREE_GAP (as the decision forms it)",
            "shipped": YAW_FREE_GAP,
            "measured": {"q99": q(adjacent, 0.99), "q999": q(adjacent, 0.999)},
            "how": f"largest rise difference of two rotors sharing a side at every tested window: 99 % {q(adjacent, 0.99)}, "
            f"99.9 % {q(adjacent, 0.999)}",
        },
    ]


def slope_rows(flights: list) -> list[dict]:
    """Each flight's least-squares plane of its 2-s mean (pitch, roll) trims in (heading velocity, specific force)."""
    n = int(round(SHARE_AVERAGE_S * 20.0))
    kv, ka = [], []
    for _, s, flog, b, *_ in flights:
        w2 = np.asarray(s["motor_rpm"], np.float64) ** 2
        trims = (w2 / w2.mean(axis=1, keepdims=True)) @ _AXES.T  # (T, 2) pitch, roll
        vel = heading_velocity(flog.vel_ned_m_s[b], s["yaw_rad"])  # (T, 2) forward, right
        acc = flog.accel_frd_m_s2[b][:, :2]  # (T, 2) x, y
        m = len(trims) // n
        t, v, f = (np.nanmean(a[: m * n].reshape(m, n, -1), axis=1) for a in (trims, vel, acc))
        for a in range(2):
            x = np.column_stack([np.ones(m), v[:, a], f[:, a]])
            ok = np.isfinite(x).all(axis=1) & np.isfinite(t[:, a])
            coef = np.linalg.lstsq(x[ok], t[ok, a], rcond=None)[0]
            kv.append(coef[1])
            ka.append(coef[2])
    return [
        slope_row("rotor_share.FLAP_SLOPE_PRIOR_SD", FLAP_SLOPE_PRIOR_SD, np.array(kv), "velocity", "m/s"),
        slope_row("rotor_share.DRAG_SLOPE_PRIOR_SD", DRAG_SLOPE_PRIOR_SD, np.array(ka), "specific-force", "m/s^2"),
    ]


def slope_row(constant: str, shipped: float, k: np.ndarray, what: str, unit: str) -> dict:
    p5, p50, p95, rms = q(k, 0.05), q(k, 0.5), q(k, 0.95), round(float(np.sqrt(np.mean(k**2))), 4)
    return {
        "constant": constant,
        "shipped": shipped,
        "measured": {"p5_p50_p95": [p5, p50, p95], "rms": rms},
        "how": f"per flight and axis, the 2-s trims' plane in (velocity, specific force): {what} slope p5/p50/p95 "
        f"{p5} / {p50} / {p95} per {unit}, rms {rms}",
    }


def regime_rows(flights: list, cfg: DecisionConfig) -> list[dict]:
    """Collective steps (the 10-s median mean RPM against the 10 s before it, every step), tilt and body rate."""
    n = int(round(COLLECTIVE_MEDIAN_S * 20.0))
    calm, steps, tilt, rate = [], [], [], []
    for _, s, _, _, step in flights:
        rpm = np.asarray(s["motor_rpm"], np.float64).mean(axis=1)
        win = np.lib.stride_tricks.sliding_window_view(rpm, n)
        med = np.nanmedian(win, axis=1)  # med[k]: the 10 s starting at step k
        change = np.abs(med[n:] - med[:-n]) / med[:-n]
        if step is None:
            calm.append(np.nanmax(change))
        elif abs(step) >= 0.2:
            steps.append(np.nanmax(change))
        tilt.append(np.maximum(np.abs(s["roll_rad"]), np.abs(s["pitch_rad"])))
        rate.append(np.abs(np.stack([s[k] for k in ("roll_rate_rad_s", "pitch_rate_rad_s", "yaw_rate_rad_s")], 1)).max(axis=1))
    calm, tilt_deg, rate_deg = np.array(calm), np.degrees(np.concatenate(tilt)), np.degrees(np.concatenate(rate))
    beyond = np.nanmean((tilt_deg > cfg.aggressive_tilt_deg) | (rate_deg > cfg.aggressive_rate_deg_s))
    return [
        {
            "constant": "DecisionConfig.collective_step_fraction",
            "shipped": cfg.collective_step_fraction,
            "measured": {
                "no_payload_step_max": round(float(calm.max()), 4),
                "no_payload_step_p99_of_flights": q(calm, 0.99),
                "payload_step_ge_20pc_min": round(float(min(steps)), 4) if steps else None,
            },
            "how": f"largest change of the 10-s median mean RPM against the 10 s before: {len(calm)} flights without a "
            f"payload step max {calm.max():.4f} (p99 of flights {q(calm, 0.99)}); {len(steps)} with a step of >= 20 % of "
            f"the mass min {min(steps) if steps else float('nan'):.4f}",
        },
        {
            "constant": "DecisionConfig.aggressive_tilt_deg / aggressive_rate_deg_s",
            "shipped": [cfg.aggressive_tilt_deg, cfg.aggressive_rate_deg_s],
            "measured": {
                "tilt_deg_p999_max": [q(tilt_deg[np.isfinite(tilt_deg)], 0.999), round(float(np.nanmax(tilt_deg)), 2)],
                "rate_deg_s_p999_max": [q(rate_deg[np.isfinite(rate_deg)], 0.999), round(float(np.nanmax(rate_deg)), 2)],
                "fraction_beyond": round(float(beyond), 6),
            },
            "how": f"healthy steps: tilt p99.9 {q(tilt_deg[np.isfinite(tilt_deg)], 0.999)} deg (max {np.nanmax(tilt_deg):.1f}), "
            f"body rate p99.9 {q(rate_deg[np.isfinite(rate_deg)], 0.999)} deg/s (max {np.nanmax(rate_deg):.1f}); "
            f"beyond either: {100 * beyond:.4f} % of steps",
        },
    ]


def envelope_rows(flights: list, model: str) -> list[dict]:
    """diagnose's RPM envelope figures (``monitor.diagnose.engine.rpm_envelope``) on the simulator's own tables."""
    clf = Classifier(model)
    z, ratio, big = [], [], []
    for _, _, flog, b, _ in flights:
        fig: dict = {}
        table = flog.to_flight_table(b)
        rpm_envelope(table, clf, fig)
        z.append(fig["rpm_z"])
        ratio.append(fig["rpm_ratio"])
        tilt = np.maximum(np.abs(table.roll_rad), np.abs(table.pitch_rad))
        big.append(float(np.mean(tilt > np.deg2rad(45.0))))
    warned = sum(a > RPM_Z_WARN or not RPM_RATIO_WARN[0] <= r <= RPM_RATIO_WARN[1] for a, r in zip(z, ratio))
    return [
        {
            "constant": "decision.network_gate.RPM_Z_WARN / RPM_RATIO_WARN",
            "shipped": [RPM_Z_WARN, list(RPM_RATIO_WARN)],
            "measured": {
                "rpm_z_min_max": [min(z), max(z)],
                "rpm_ratio_min_max": [min(ratio), max(ratio)],
                "flights_beyond_warn": warned,
            },
            "how": f"diagnose's rpm_z on {len(z)} randomised healthy flights {min(z):.2f}..{max(z):.2f}, "
            f"rpm_ratio {min(ratio):.3f}..{max(ratio):.3f}; beyond either WARN: {warned}",
        },
        {
            "constant": "diagnose.engine.LARGE_ATTITUDE_MAX_FRACTION",
            "shipped": LARGE_ATTITUDE_MAX_FRACTION,
            "measured": {"largest_flight_fraction_beyond_45_deg": round(max(big), 5)},
            "how": f"largest fraction of one healthy flight's time beyond 45 deg: {max(big):.5f}",
        },
    ]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--flights", type=int, default=96, help="randomised healthy flights (default 96)")
    p.add_argument("--nominal-flights", type=int, default=48, help="healthy flights of the nominal airframe (default 48)")
    p.add_argument("--seed", type=int, default=100, help="seed of both sets (default 100, the alert calibration's)")
    p.add_argument("--model", default=str(REPO_ROOT / "models" / "classifier.onnx"), help="for the RPM envelope")
    p.add_argument("--json", default="", help="also write the rows here")
    args = p.parse_args(argv)
    vehicle = load_vehicle(REPO_ROOT / "models" / "vehicle.yaml")
    geometry = RotorGeometry.from_vehicle(vehicle)
    flights = randomised_set(vehicle, args.flights, args.seed)
    nominal = nominal_set(vehicle, args.nominal_flights, args.seed)
    rows = (
        balance_rows(balances(nominal, geometry), balances([s for _, s, *_ in flights], geometry), geometry, vehicle)
        + share_rows(flights)
        + slope_rows(flights)
        + regime_rows(flights, DecisionConfig())
        + decision_rows(flights, Classifier(args.model).info.window)
        + envelope_rows(flights, args.model)
    )
    print(f"our simulator, seed {args.seed}: {len(flights)} randomised healthy flights, {len(nominal)} nominal-airframe ones")
    for r in rows:
        print(f"{r['constant']}: shipped {r['shipped']}\n    {r['how']}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"seed": args.seed, "flights": len(flights), "nominal_flights": len(nominal), "rows": rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
