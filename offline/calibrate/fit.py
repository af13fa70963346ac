"""Fit candidate terms by weighted least squares and pick them by held-out BIC.

Held-out data: every segment is cut into alternating blocks of ``BLOCK_S``
seconds; even blocks fit the parameters, odd blocks score them. Alternating
blocks (rather than first half / second half) keep both sets spanning the same
flight phases, so one short log still gives a fair held-out score.

Score: a Gaussian likelihood per residual signal with its variance profiled
out, ``BIC = sum_s n_s/c_s * log(RSS_s/n_s) + k * log(n_fit/c)``, on held-out
residuals. ``c_s`` is the integrated autocorrelation time of signal s in the
nominal model's residuals: the filters (and any slow model error) make
neighbouring samples far from independent, and counting them as independent
would let a term win on noise.
Selection is greedy forward: every remaining term is fitted on top of the chosen ones and judged by
the gates (``gate_checks``: identifiable, held-out BIC gain above ``gain_threshold``, no signal
fitted worse); the one named is the lowest held-out BIC among those passing every gate; selection
stops when none passes. Every candidate's verdict is kept with the gate that decided it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from monitor.vehicle import VehicleConfig
from offline.calibrate.physics import G_M_S2, SpeedScale, angular_accel, residuals, rotor_forces, trim_commands
from offline.calibrate.prepare import Segment
from offline.calibrate.terms import TERMS, Term, apply_terms, stacked

BLOCK_S = 5.0
MAX_LAG = 40  # samples (2 s at 20 Hz) for the autocorrelation time
REWEIGHT_PASSES = 2
LATER_ROUND_CANDIDATES = 4
# The held-out BIC gain a term must exceed to be named. Set on OUR simulator's nominal flights (the register
# drawn, every library term at nominal, the rotors' spin-up reaction among them: ``python -m
# offline.calibrate.derive_gates --pairs 40 --duration-s 40 --seed 11``): at 80, 1 of 40 pairs of 2 x 40 s flights
# passes a term (2.5 %, the target: a motor_time_constant of gain 93.5, which the telemetry-delay rival then takes,
# so no pair names a cause); at 60, 6 of 40 (five lags of 62-80 on a 20 ms vehicle, mass 68); at 10 (Kass-Raftery
# "very strong") 31 of 40 (battery sag and the ESC's voltage dependence look like a heavier vehicle). The pooled
# held-out RMS cut is reported beside the gain, not gated: a floor of 1 or 2 % changes no pair's verdict on those
# flights at any BIC threshold, and it can veto a real effect whose residual sits in few of the signals.
MIN_DELTA_BIC = 80.0
# The gain gate per length of log. MIN_DELTA_BIC was set on pairs of 40-s flights, half of each held out: 40 s of
# held-out log (GATE_HELDOUT_S). What the nominal flights make a term pass is an effect they really carry and the
# vehicle file lacks (quadratic drag read as linear drag, the attitude log's delay read as a motor lag, battery sag
# read as mass), and its held-out gain grows with the log's length, where the BIC penalty grows only as its log:
# the derivation's 40 pairs flown for 80 s instead of 40 give each term 1.8-2.3 times its 40-s gain (median ratio
# per term, gains above 20 at 40 s), and 22 of the 40 pairs pass a term at 80 against 1 of 40 (``python -m
# offline.calibrate.derive_gates --pairs 40 --duration-s 80 --seed 11`` against ``--duration-s 40``). So the gate
# is a gain per held-out second: MIN_DELTA_BIC per GATE_HELDOUT_S, never below MIN_DELTA_BIC (``gain_threshold``);
# on logs up to 2 x 40 s it is MIN_DELTA_BIC. On fresh 2 x 80 s nominal pairs (``python -m bench.gate_length own
# --pairs 40 --seed 12 --duration-s 80``) the fixed gate names a term in 26 of 40, this one in 10 of 40 (each the
# attitude log delay read as a motor lag: the 20 Hz ceiling, docs/CALIBRATION.md).
GATE_HELDOUT_S = 40.0
# The steady-state view's BIC is on per-flight mean commands (a handful of numbers): Kass-Raftery "very strong".
STEADY_MIN_DELTA_BIC = 10.0
# Consistency: a real vehicle effect improves the equations it enters and leaves the others
# alone. A term that buys a better fit of one channel with a worse fit of another is fitting an
# artefact of the log (e.g. the translation channel's streams resampled 0-10 ms stale in a
# .tlog made a motor lag "improve" velocity while worsening every moment equation).
# Worse means worse beyond what nominal flights show: the held-out RMS of that signal rises by more than
# MAX_SIGNAL_WORSENING (3 %, the smallest rise that matters) and its mean square by more than WORSENING_SE standard
# errors of the paired difference (effective samples = n / correlation time). WORSENING_SE is the largest such rise
# any identifiable candidate shows on OUR simulator's nominal flights (``python -m offline.calibrate.derive_gates
# --pairs 40 --duration-s 40 --seed 11``, ``consistency_on_nominal``: 3.55, cg_offset on one pair's pitch, RMS x1.11;
# 95 % of those candidates stay below 2.4): a term fitting noise worsens a signal that much, so only beyond it does a
# worse signal say the term is wrong. (A low-bandwidth channel has few independent samples: on the evaluation
# simulator's hidden motor-lag airframe the true lags raise the vertical channel's RMS by 4 % at 0.7 standard
# errors, ~39 independent held-out samples.)
MAX_SIGNAL_WORSENING = 1.03
WORSENING_SE = 3.55
# An outside-library rival (``offline.calibrate.unexplained.delay_probe``: the estimator's signals stamped later
# than the motor outputs) competes with the terms in every round: where its held-out BIC is lower than that of the
# round's best passing term by more than RIVAL_MARGIN_BIC, nothing is named and the residual is reported as
# unexplained. 10 is Kass-Raftery "very strong", not fitted: on OUR simulator no lag term passes the gates on
# 2 x 40 s or 2 x 80 s flights with 35-90 ms hidden, so no named lag exists there to set it on; where a term is
# named on its nominal flights the rival trails it by 80 or more (``python -m bench.evalsim_calibration --out
# out/rival80 --duration-s 80 --effects lag_all_rotors lag_one_rotor --own-seeds 2 --seeds 0 --nominal 0
# --outside-seeds 0 --own-nominal 4``: rival_minus_best, rival_minus_lag); the full matrix measures both
# simulators (docs/CALIBRATION.md).
RIVAL_MARGIN_BIC = 10.0
# At 20 Hz the logged command is a snapshot of a signal that moves at the controller's rate, so the predicted
# moments carry noise the measured motion does not, and a least-squares gain (inertia) shrinks by about rho^2
# (errors-in-variables, ``_gain_bias``): inertia is not identifiable where that bias exceeds INERTIA_MAX_BIAS.
INERTIA_MAX_BIAS = 0.05


@dataclass
class Data:
    """Segments plus their fit / held-out masks."""

    segments: list[Segment]
    fit_masks: list[np.ndarray]
    held_masks: list[np.ndarray]
    corr_time: dict[str, float] = field(default_factory=dict)  # samples per independent sample, per signal

    @classmethod
    def split(cls, segments: list[Segment]) -> Data:
        fit, held = [], []
        for s in segments:
            block = np.floor(s.time_s / BLOCK_S).astype(int) % 2
            fit.append(s.valid & (block == 0))
            held.append(s.valid & (block == 1))
        return cls(segments, fit, held)

    @property
    def n_fit(self) -> int:
        return int(sum(m.sum() for m in self.fit_masks))

    @property
    def heldout_s(self) -> float:
        """Seconds of log in the held-out blocks (valid samples only)."""
        return float(sum(m.sum() * s.dt_s for s, m in zip(self.segments, self.held_masks)))

    def residuals(self, vehicle: VehicleConfig, speed_scale: SpeedScale = None) -> list[dict[str, np.ndarray]]:
        return [residuals(s, vehicle, speed_scale) for s in self.segments]


def _pooled(res: list[dict[str, np.ndarray]], masks: list[np.ndarray]) -> dict[str, np.ndarray]:
    out: dict[str, list[np.ndarray]] = {}
    for r, m in zip(res, masks):
        for name, v in r.items():
            out.setdefault(name, []).append(v[m])
    return {k: np.concatenate(v) for k, v in out.items()}


def rms_by_signal(res: list[dict[str, np.ndarray]], masks: list[np.ndarray]) -> dict[str, float]:
    return {k: float(np.sqrt(np.mean(v**2))) if len(v) else float("nan") for k, v in _pooled(res, masks).items()}


def noise_floor(signal: str) -> float:
    """Sensor-level resolution of a residual signal; keeps a noiseless simulated channel from dominating."""
    if signal.endswith("_rad_s2"):
        return 0.01
    if signal.endswith("_m_s2"):
        return 0.01
    return 0.0005


def correlation_time(res: list[dict[str, np.ndarray]], masks: list[np.ndarray]) -> dict[str, float]:
    """Integrated autocorrelation time per signal (1 = white), summed until the correlation first drops below 0."""
    out = {}
    for name in res[0]:
        num = np.zeros(MAX_LAG + 1)
        cnt = np.zeros(MAX_LAG + 1)
        for r, m in zip(res, masks):
            v = np.where(m, r[name], np.nan)
            v = v - np.nanmean(v) if np.any(m) else v
            for lag in range(MAX_LAG + 1):
                prod = v[lag:] * v[: len(v) - lag]
                ok = np.isfinite(prod)
                num[lag] += prod[ok].sum()
                cnt[lag] += ok.sum()
        if num[0] <= 0:
            out[name] = 1.0
            continue
        rho = (num / np.maximum(cnt, 1)) / (num[0] / max(cnt[0], 1))
        stop = np.flatnonzero(rho[1:] <= 0)
        last = int(stop[0]) + 1 if len(stop) else MAX_LAG + 1
        out[name] = float(max(1.0, 1.0 + 2.0 * rho[1:last].sum()))
    return out


def bic(res: list[dict[str, np.ndarray]], masks: list[np.ndarray], k: int, n_fit: int, corr_time: dict[str, float]) -> float:
    total = 0.0
    for name, v in _pooled(res, masks).items():
        n = len(v)
        if n:
            total += n / corr_time.get(name, 1.0) * np.log(float(np.mean(v**2)) + noise_floor(name) ** 2)
    c = float(np.median(list(corr_time.values()))) if corr_time else 1.0
    return float(total + k * np.log(max(n_fit / c, 2.0)))


def gain_threshold(data: Data) -> float:
    """The held-out BIC gain a term (or an outside-library probe) must exceed on ``data``: MIN_DELTA_BIC per
    GATE_HELDOUT_S of held-out log, never below MIN_DELTA_BIC."""
    return MIN_DELTA_BIC * max(1.0, data.heldout_s / GATE_HELDOUT_S)


def relative_rms(rms: dict[str, float], base: dict[str, float]) -> float:
    """Held-out RMS of a model relative to a base model, pooled over signals (each floored at its noise level)."""
    ratios = [(rms[s] ** 2 + noise_floor(s) ** 2) / (base[s] ** 2 + noise_floor(s) ** 2) for s in base if s in rms]
    return float(np.sqrt(np.mean(ratios)))


def worst_signal(rms: dict[str, float], base: dict[str, float]) -> float:
    """Largest held-out RMS ratio over signals (each floored at its noise level)."""
    return float(
        max(np.sqrt((rms[s] ** 2 + noise_floor(s) ** 2) / (base[s] ** 2 + noise_floor(s) ** 2)) for s in base if s in rms)
    )


def signal_worsening(
    base: list[dict[str, np.ndarray]], new: list[dict[str, np.ndarray]], masks: list[np.ndarray], corr_time: dict[str, float]
) -> dict[str, tuple[float, float]]:
    """Per signal, how much worse ``new`` fits it than ``base`` on the held-out blocks: (held-out RMS ratio, each
    floored at the signal's noise level; the mean-square rise in paired standard errors, with the effective sample
    count n / correlation time)."""
    a_all, b_all = _pooled(base, masks), _pooled(new, masks)
    out = {}
    for s, a in a_all.items():
        b, f2 = b_all[s], noise_floor(s) ** 2
        if len(a) < 2:
            continue
        d = b**2 - a**2
        se = np.std(d) / np.sqrt(len(d) / corr_time.get(s, 1.0))
        out[s] = (float(np.sqrt((np.mean(b**2) + f2) / (np.mean(a**2) + f2))), float(np.mean(d) / se) if se > 0 else 0.0)
    return out


def worsened_signals(worsening: dict[str, tuple[float, float]]) -> list[str]:
    """Signals fitted worse beyond what nominal flights show: RMS ratio above MAX_SIGNAL_WORSENING and the
    mean-square rise beyond WORSENING_SE paired standard errors (``signal_worsening``), worst first."""
    worse = [s for s, (ratio, z) in worsening.items() if ratio > MAX_SIGNAL_WORSENING and z > WORSENING_SE]
    return sorted(worse, key=lambda s: -worsening[s][1])


def combined_rms(rms: dict[str, float], sigma: dict[str, float]) -> float:
    """One number per model: RMS of the residuals in units of the nominal model's per-signal RMS."""
    return float(np.sqrt(np.mean([(rms[s] / sigma[s]) ** 2 for s in sigma if s in rms])))


@dataclass
class TermFit:
    terms: list[Term]
    x: np.ndarray
    std: np.ndarray
    vehicle: VehicleConfig
    residuals: list[dict[str, np.ndarray]]
    bic: float
    held_rms: dict[str, float]
    identifiable: dict[str, bool] = field(default_factory=dict)
    reasons: dict[str, str] = field(default_factory=dict)

    def params(self, term: Term) -> dict[str, float]:
        i = self._offset(term)
        return {p: float(self.x[i + j]) for j, p in enumerate(term.params)}

    def stds(self, term: Term) -> dict[str, float]:
        i = self._offset(term)
        return {p: float(self.std[i + j]) for j, p in enumerate(term.params)}

    def _offset(self, term: Term) -> int:
        i = 0
        for t in self.terms:
            if t.name == term.name:
                return i
            i += len(t.params)
        raise KeyError(term.name)


def fit_terms(data: Data, nominal: VehicleConfig, terms: list[Term], x0: np.ndarray, sigma: dict[str, float]) -> TermFit:
    """Jointly fit ``terms`` on the fit blocks; score on the held-out blocks."""
    scale = stacked(nominal, terms, "scale")
    lo, hi = stacked(nominal, terms, "lower"), stacked(nominal, terms, "upper")
    x0 = np.clip(x0, lo + 1e-9 * scale, hi - 1e-9 * scale)
    names = list(sigma)

    def vec(x: np.ndarray, w: dict[str, float]) -> np.ndarray:
        res = data.residuals(apply_terms(nominal, terms, x))
        parts = [r[s][m] / w[s] for r, m in zip(res, data.fit_masks) for s in names if s in r]
        return np.concatenate(parts)

    # Iteratively reweighted: each signal weighted by the RMS the current fit leaves in it (the
    # profile likelihood's weights). Weights from the nominal residual alone would let a signal the
    # nominal model got badly wrong count for little once it is fixed, and bias the joint fit.
    w = dict(sigma)
    for _ in range(REWEIGHT_PASSES):
        sol = least_squares(
            lambda z, w=w, x0=x0: vec(x0 + z * scale, w),
            np.zeros(len(x0)),
            bounds=((lo - x0) / scale, (hi - x0) / scale),
            method="trf",
            x_scale=1.0,
            max_nfev=60 * max(len(x0), 1),
            diff_step=1e-3,
        )
        x0 = np.clip(x0 + sol.x * scale, lo + 1e-9 * scale, hi - 1e-9 * scale)
        res = data.residuals(apply_terms(nominal, terms, x0))
        w = {k: max(v, noise_floor(k)) for k, v in rms_by_signal(res, data.fit_masks).items()}
    x = x0
    # Standard errors from our own central differences at the solution (a tenth of each
    # parameter's resolution), not the solver's last Jacobian, which can be stale or zero
    # when it stops on its first step.
    f0 = vec(x, w)
    J = np.empty((len(f0), len(x)))
    for j in range(len(x)):
        h = np.zeros(len(x))
        h[j] = 0.1 * scale[j]
        J[:, j] = (vec(np.clip(x + h, lo, hi), w) - vec(np.clip(x - h, lo, hi), w)) / 2.0 / 0.1
    dof = max(len(f0) - len(x), 1)
    s2 = float(f0 @ f0) / dof
    try:
        cov_z = np.linalg.inv(J.T @ J) * s2 * float(np.median(list(data.corr_time.values()) or [1.0]))
        std = np.sqrt(np.maximum(np.diag(cov_z), 0.0)) * scale
    except np.linalg.LinAlgError:
        std = np.full(len(x), np.inf)
    vehicle = apply_terms(nominal, terms, x)
    res = data.residuals(vehicle)
    fit = TermFit(
        terms,
        x,
        std,
        vehicle,
        res,
        bic(res, data.held_masks, len(x), data.n_fit, data.corr_time),
        rms_by_signal(res, data.held_masks),
    )
    eiv = _gain_bias(data, vehicle) if any(t.name == "inertia" for t in terms) else None
    for t in terms:
        if t.name == "inertia" and eiv is not None and np.any(eiv > INERTIA_MAX_BIAS):
            fit.identifiable[t.name] = False
            fit.reasons[t.name] = (
                "not identifiable: the predicted angular acceleration is too noisy at this log rate "
                f"(errors-in-variables would bias the inertia by about {', '.join(f'{100 * b:.0f} %' for b in eiv)} "
                "on roll, pitch, yaw); log the motor outputs faster or fly more aggressively"
            )
            continue
        s, sc = fit.stds(t), t.scale(nominal)
        bad = [p for j, p in enumerate(t.params) if p not in t.nuisance and (not np.isfinite(s[p]) or s[p] > sc[j])]
        fit.identifiable[t.name] = not bad
        if bad:
            fit.reasons[t.name] = (
                "not identifiable: standard error of "
                + ", ".join(f"{p} {s[p]:.3g} > resolution {sc[t.params.index(p)]:.3g}" for p in bad)
                + " (too short or too little excitation for this term)"
            )
    return fit


def _gain_bias(data: Data, vehicle: VehicleConfig) -> np.ndarray:
    """Per axis, the relative bias a least-squares gain (inertia) fit would carry: 1 - rho^2.

    The measured side (gyro) is nearly noise-free; the predicted side carries
    the command-snapshot noise, so the fitted gain shrinks by about rho^2.
    """
    meas, pred = [], []
    for s, m in zip(data.segments, data.fit_masks):
        f, tau = rotor_forces(s, vehicle)
        a, b = angular_accel(s, vehicle, f, tau)
        meas.append(a[m])
        pred.append(b[m])
    a, b = np.concatenate(meas), np.concatenate(pred)
    rho2 = np.array([np.corrcoef(a[:, i], b[:, i])[0, 1] ** 2 if np.std(b[:, i]) > 0 else 0.0 for i in range(3)])
    return 1.0 - rho2


@dataclass(frozen=True)
class GateCheck:
    """One selection gate applied to one candidate: did it pass, on which numbers."""

    gate: str
    passed: bool
    numbers: dict[str, float]
    why: str


def gate_checks(
    trial: TermFit, base_bic: float, base_rms: dict[str, float], base_res: list[dict[str, np.ndarray]], data: Data
) -> list[GateCheck]:
    """Every gate a candidate must pass to be named, in order, each with the numbers that decided it."""
    gain = base_bic - trial.bic
    threshold = gain_threshold(data)
    cut = 1.0 - relative_rms(trial.held_rms, base_rms)  # reported beside the gain, not a gate
    worsening = signal_worsening(base_res, trial.residuals, data.held_masks, data.corr_time)
    worse = worsened_signals(worsening)
    # The signal closest to the veto: the largest paired rise among those whose RMS rose by MAX_SIGNAL_WORSENING.
    risen = {s: w for s, w in worsening.items() if w[0] > MAX_SIGNAL_WORSENING}
    worst = max(risen, key=lambda s: risen[s][1]) if risen else None
    figures = ", ".join(
        f"{s} held-out RMS x{worsening[s][0]:.3f}, mean square +{worsening[s][1]:.1f} paired standard errors" for s in worse
    )
    ident = all(trial.identifiable.values())
    return [
        GateCheck(
            "identifiable",
            ident,
            {},
            "standard errors within each parameter's resolution" if ident else "; ".join(trial.reasons.values()),
        ),
        GateCheck(
            "heldout_bic_gain",
            gain > threshold,
            {
                "gain": round(gain, 1),
                "threshold": round(threshold, 1),
                "heldout_s": round(data.heldout_s, 1),
                "pooled_rms_cut_pct": round(100 * cut, 2),
            },
            f"held-out BIC gain {gain:.1f} {'>' if gain > threshold else '<='} {threshold:.4g}"
            + (f" ({MIN_DELTA_BIC:g} per {GATE_HELDOUT_S:g} s of held-out log)" if threshold > MIN_DELTA_BIC else ""),
        ),
        GateCheck(
            "consistency",
            not worse,
            {
                "worsened_signals": len(worse),
                "worst_signal": worst,
                "worst_rms_ratio": round(worsening[worst][0], 4) if worst else None,
                "worst_se_rise": round(worsening[worst][1], 2) if worst else None,
            },
            "no signal fitted worse beyond what nominal flights show"
            if not worse
            else f"fits {figures} (gate: RMS ratio > {MAX_SIGNAL_WORSENING:g} and > {WORSENING_SE:g} paired standard "
            "errors, the most nominal flights show)",
        ),
    ]


@dataclass
class Verdict:
    """What selection decided about one candidate in one round, and which gate decided it."""

    term: str
    named: bool
    gate: str  # the first gate it failed; "best" when it passed them all ("named" or outranked by a better one)
    why: str
    gain: float  # held-out BIC gain over the round's base model
    checks: list[GateCheck]

    def to_dict(self) -> dict:
        return {
            "named": self.named,
            "decided_by": self.gate,
            "why": self.why,
            "heldout_bic_gain": round(self.gain, 1),
            "gates": {c.gate: {"passed": c.passed, **c.numbers} for c in self.checks},
        }


@dataclass
class Step:
    """One round of forward selection: every remaining candidate tried on top of ``base``."""

    base_bic: float
    trials: dict[str, TermFit]
    chosen: str | None
    confidence: float
    verdicts: dict[str, Verdict] = field(default_factory=dict)
    rival: dict | None = None  # the outside-library rival's fit on this round's base: name, value, bic, ...
    threshold: float = MIN_DELTA_BIC  # the round's gain gate (``gain_threshold``)

    def vetoed_leader(self) -> Verdict | None:
        """The candidate with the largest held-out gain when a gate, not a better candidate, kept it out."""
        if not self.verdicts:
            return None
        top = max(self.verdicts.values(), key=lambda v: v.gain)
        return None if top.named or top.gate == "best" or top.gain <= self.threshold else top


@dataclass
class Selection:
    nominal_residuals: list[dict[str, np.ndarray]]
    nominal_bic: float
    sigma: dict[str, float]
    steps: list[Step]
    final: TermFit | None

    @property
    def chosen(self) -> list[str]:
        return [s.chosen for s in self.steps if s.chosen]


def judge(
    trials: dict[str, TermFit], base_bic: float, base_rms: dict[str, float], base_res: list[dict[str, np.ndarray]], data: Data
) -> tuple[str | None, dict[str, Verdict]]:
    """Gate every trial; the one named is the lowest held-out BIC among those passing every gate."""
    checks = {n: gate_checks(f, base_bic, base_rms, base_res, data) for n, f in trials.items()}
    passing = [n for n, c in checks.items() if all(g.passed for g in c)]
    best = min(passing, key=lambda n: trials[n].bic) if passing else None
    verdicts = {}
    for n, c in checks.items():
        failed = next((g for g in c if not g.passed), None)
        gain = base_bic - trials[n].bic
        if failed is not None:
            v = Verdict(n, False, failed.gate, failed.why, gain, c)
        elif n == best:
            v = Verdict(n, True, "best", f"passes every gate with the largest held-out BIC gain ({gain:.1f})", gain, c)
        else:
            d = trials[n].bic - trials[best].bic
            v = Verdict(n, False, "best", f"passes every gate but {best} explains the same data better by {d:.1f} BIC", gain, c)
        verdicts[n] = v
    return best, verdicts


def rival_verdict(best: str, trial: TermFit, rival: dict, base_bic: float) -> Verdict | None:
    """The best passing term's verdict when ``rival`` explains the held-out data better by RIVAL_MARGIN_BIC."""
    lead = trial.bic - rival["bic"]
    if lead <= RIVAL_MARGIN_BIC:
        return None
    gain = base_bic - trial.bic
    check = GateCheck(
        "outside_library",
        False,
        {"rival_heldout_bic_gain": round(base_bic - rival["bic"], 1), "lead": round(lead, 1), "margin": RIVAL_MARGIN_BIC},
        "",
    )
    why = (
        f"{rival['name']} ({rival['describe']}, outside the library) explains the held-out data better by {lead:.1f} "
        f"BIC (> {RIVAL_MARGIN_BIC:g}): an unexplained residual, not {best}"
    )
    return Verdict(best, False, "outside_library", why, gain, [dataclasses.replace(check, why=why)])


def select_terms(
    data: Data, nominal: VehicleConfig, candidates: list[Term], rival: Callable[[Data, VehicleConfig, int], dict] | None = None
) -> Selection:
    """Greedy forward selection. ``rival(data, base_vehicle, k_base)`` (an outside-library probe returning at least
    ``name``, ``describe`` and its held-out ``bic``) competes in every round: see RIVAL_MARGIN_BIC."""
    res0 = data.residuals(nominal)
    data.corr_time = correlation_time(res0, data.fit_masks)
    sigma = {k: max(v, noise_floor(k)) for k, v in rms_by_signal(res0, data.fit_masks).items()}
    nominal_sigma = dict(sigma)
    base_bic = bic(res0, data.held_masks, 0, data.n_fit, data.corr_time)
    base_rms = rms_by_signal(res0, data.held_masks)
    base_res = res0
    nominal_bic = base_bic
    chosen: list[Term] = []
    x_cur = np.zeros(0)
    current: TermFit | None = None
    steps: list[Step] = []
    remaining = list(candidates)
    while remaining:
        trials = {
            t.name: fit_terms(data, nominal, chosen + [t], np.concatenate([x_cur, t.get(nominal)]), sigma) for t in remaining
        }
        best, verdicts = judge(trials, base_bic, base_rms, base_res, data)
        rival_fit = None
        if rival is not None and best is not None:
            rival_fit = rival(data, current.vehicle if current else nominal, len(x_cur))
            rival_fit |= {"versus": best, "lead": trials[best].bic - rival_fit["bic"]}
            lost = rival_verdict(best, trials[best], rival_fit, base_bic)
            if lost is not None:
                verdicts[best] = dataclasses.replace(lost, checks=verdicts[best].checks + lost.checks)
                best = None
        conf = 0.0
        if best is not None:
            ok = {n: f for n, f in trials.items() if all(f.identifiable.values())}
            scores = np.array([base_bic] + [f.bic for f in ok.values()])
            w = np.exp(-(scores - scores.min()) / 2.0)
            conf = float(np.exp(-(trials[best].bic - scores.min()) / 2.0) / w.sum())
        steps.append(Step(base_bic, trials, best, conf, verdicts, rival_fit, gain_threshold(data)))
        if best is None:
            break
        current = trials[best]
        chosen.append(next(t for t in remaining if t.name == best))
        # Later rounds try only the terms the first round found identifiable and promising: a term
        # that neither the data can pin down nor helps alone rarely helps jointly, and each try is a fit.
        if len(steps) == 1:
            ok = [n for n, f in trials.items() if all(f.identifiable.values())]
            promising = sorted(ok, key=lambda n: trials[n].bic)[: LATER_ROUND_CANDIDATES + 1]
            remaining = [t for t in remaining if t.name in promising]
        remaining = [t for t in remaining if t.name != best]
        x_cur = current.x
        base_bic, base_rms, base_res = current.bic, current.held_rms, current.residuals
        # Reweight by what is left: the next term competes against the current model's residual.
        sigma = {k: max(v, noise_floor(k)) for k, v in rms_by_signal(current.residuals, data.fit_masks).items()}
    return Selection(res0, nominal_bic, nominal_sigma, steps, current)


# ---------------------------------------------------------------------------
# Steady-state view.
#
# For logs without body rates or full attitude (CrazyPAD's motor logs: no pitch, no rates), the
# equation-error view above cannot run; what such logs do carry is the per-motor command the
# controller settles at in steady flight. Data: per flight, the mean command of each motor over
# its steady phases. Model: the trim commands of the vehicle with the term applied
# (``offline.calibrate.physics.trim_commands``). The same term library (``TERMS``) is fitted by
# least squares, ranked by BIC on the fit flights (k parameters, n = 4 x flights means) and
# chosen greedily while it lowers BIC by ``STEADY_MIN_DELTA_BIC``. What no term explains is reported
# as an unexplained residual, in commands and in units of the flights' own flight-to-flight
# spread, rather than forced onto a term.


STEADY_CANDIDATES = ("motor_efficiency", "cg_offset", "mass", "esc_curve")
# What per-motor mean commands cannot tell apart, and what they cannot see at all (said in every steady result).
STEADY_CANNOT_SEPARATE = (
    ("cg_offset", "motor_efficiency"),  # both move thrust between motors at trim; motor_efficiency absorbs any static pattern
    ("mass", "esc_curve"),  # both scale every motor's command alike
)
STEADY_NOT_OBSERVABLE = ("inertia", "motor_time_constant", "rotor_time_constant", "rotor_inertia", "drag", "gyro_bias")


def predicted_commands(vehicle: VehicleConfig) -> np.ndarray:
    """(4,) trim command in unaccelerated level flight, PX4 rotor order."""
    return trim_commands(vehicle, np.array([vehicle.mass_kg * G_M_S2]))[0]


@dataclass
class SteadyTermResult:
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
            "fit_rms_cmd": _finite_or_none(round(self.fit_rms_cmd, 1)),
            "holdout_rms_cmd": _finite_or_none(round(self.holdout_rms_cmd, 1)),
            "bic": round(self.bic, 2),
        }


def _finite_or_none(v: float) -> float | None:
    """A figure for JSON: None where it is undefined (NaN or infinite), never NaN."""
    v = float(v)
    return v if math.isfinite(v) else None


def _steady_rms(vehicle: VehicleConfig, measured: np.ndarray) -> float:
    return float(np.sqrt(np.mean((measured - predicted_commands(vehicle)) ** 2))) if len(measured) else float("nan")


def _steady_bic(rms: float, n: int, k: int) -> float:
    return n * math.log(max(rms, 1e-9) ** 2) + k * math.log(n)


def fit_steady_terms(nominal: VehicleConfig, terms: list[Term], fit_cmd: np.ndarray) -> VehicleConfig:
    """Least squares of the trim commands to the per-flight mean commands (F, 4)."""
    x0 = stacked(nominal, terms, "get")
    scale = stacked(nominal, terms, "scale")
    lo, hi = stacked(nominal, terms, "lower"), stacked(nominal, terms, "upper")

    def resid(z: np.ndarray) -> np.ndarray:
        v = apply_terms(nominal, terms, x0 + z * scale)
        return (fit_cmd - predicted_commands(v)).ravel() / 1000.0

    sol = least_squares(resid, np.zeros_like(x0), bounds=((lo - x0) / scale, (hi - x0) / scale), x_scale=1.0)
    return apply_terms(nominal, terms, x0 + sol.x * scale)


def steady_param_dict(vehicle: VehicleConfig, terms: list[Term]) -> dict[str, float]:
    values = stacked(vehicle, terms, "get")
    names = [p for t in terms for p in t.params]
    return dict(zip(names, map(float, values)))


@dataclass
class SteadyCalibration:
    airframe: str
    nominal: VehicleConfig
    calibrated: VehicleConfig
    cause: str | None
    ranking: list[SteadyTermResult]
    nominal_fit_rms_cmd: float
    nominal_holdout_rms_cmd: float
    calibrated_holdout_rms_cmd: float
    fit_files: list[str]
    holdout_files: list[str]
    calibrated_bias_rms_cmd: float = float("nan")  # RMS over motors of (mean measured - model) on the fit flights
    spread_rms_cmd: float = float("nan")  # flight-to-flight std of the per-motor means (RMS over motors)

    @property
    def unexplained(self) -> dict:
        """The residual no chosen term explains, in commands and in flight-to-flight spreads.

        Beyond ~3 spreads of the mean (spread / sqrt(flights)) something outside the library is
        there. Caveat of this view: ``motor_efficiency`` has four parameters for four per-motor
        means, so whenever it is a candidate any static per-motor pattern is absorbed by it; only
        phase-dependent effects (hover vs cruise) or a library without it leave a residual here.
        """
        n = max(len(self.fit_files), 1)
        se = self.spread_rms_cmd / math.sqrt(n) if self.spread_rms_cmd > 0 else float("nan")
        # One fit flight has no flight-to-flight spread: the size in standard errors is undefined (None), not NaN.
        return {
            "rms_cmd": _finite_or_none(self.calibrated_bias_rms_cmd),
            "in_standard_errors": _finite_or_none(self.calibrated_bias_rms_cmd / se),
        }

    def to_dict(self) -> dict:
        return {
            "airframe": self.airframe,
            "view": "steady-state",
            "cannot_separate": [list(p) for p in STEADY_CANNOT_SEPARATE],
            "not_observable": list(STEADY_NOT_OBSERVABLE),
            "unexplained_residual": {k: None if v is None else round(v, 3) for k, v in self.unexplained.items()},
            "cause": self.cause,
            "why": TERMS[self.cause].why if self.cause else "no term beats the nominal model",
            "ranking": [r.to_dict() for r in self.ranking],
            "nominal_fit_rms_cmd": round(self.nominal_fit_rms_cmd, 1),
            "holdout_rms_cmd": {
                "nominal": _finite_or_none(round(self.nominal_holdout_rms_cmd, 1)),
                "calibrated": _finite_or_none(round(self.calibrated_holdout_rms_cmd, 1)),
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
    candidates=STEADY_CANDIDATES,
) -> SteadyCalibration:
    """Fit each candidate on ``fit_cmd`` (F, 4 mean commands, PX4 order), rank, keep the cause.

    The calibrated vehicle carries the cause; a second term is added when it
    lowers the fit BIC by ``STEADY_MIN_DELTA_BIC`` again (greedy, as ``offline.calibrate.fit``).
    """
    n = fit_cmd.size
    base_rms = _steady_rms(nominal, fit_cmd)
    base_bic = _steady_bic(base_rms, n, 0)
    ranking = []
    for name in candidates:
        v = fit_steady_terms(nominal, [TERMS[name]], fit_cmd)
        k = len(TERMS[name].params)
        ranking.append(
            SteadyTermResult(
                name,
                steady_param_dict(v, [TERMS[name]]),
                _steady_rms(v, fit_cmd),
                _steady_rms(v, holdout_cmd),
                _steady_bic(_steady_rms(v, fit_cmd), n, k),
                v,
            )
        )
    ranking.sort(key=lambda r: r.bic)
    chosen: list[str] = []
    best_bic, calibrated = base_bic, nominal
    for r in ranking:
        terms = [TERMS[t] for t in chosen + [r.name]]
        v = fit_steady_terms(nominal, terms, fit_cmd)
        b = _steady_bic(_steady_rms(v, fit_cmd), n, sum(len(t.params) for t in terms))
        if b < best_bic - STEADY_MIN_DELTA_BIC:
            chosen.append(r.name)
            best_bic, calibrated = b, v
    return SteadyCalibration(
        airframe,
        nominal,
        calibrated,
        chosen[0] if chosen else None,
        ranking,
        base_rms,
        _steady_rms(nominal, holdout_cmd),
        _steady_rms(calibrated, holdout_cmd),
        fit_files,
        holdout_files,
        float(np.sqrt(np.mean((np.mean(fit_cmd, axis=0) - predicted_commands(calibrated)) ** 2))),
        float(np.sqrt(np.mean(np.std(fit_cmd, axis=0, ddof=1) ** 2))) if len(fit_cmd) > 1 else float("nan"),
    )


def equivalent_speed_ratios(calibrated: VehicleConfig, fault_cmd: np.ndarray) -> np.ndarray:
    """(4,) per-rotor speed scale, relative to the calibrated airframe, that reproduces ``fault_cmd``.

    ``fault_cmd`` (F, 4) are the mean commands of flights of one condition; the
    common part (extra mass, battery) is divided out (geometric mean 1), so a
    value below 1 is a rotor that lost thrust: thrust factor = ratio**2.
    """
    v = fit_steady_terms(calibrated, [TERMS["motor_efficiency"]], fault_cmd)
    r = np.asarray(v.motor_efficiency) / np.asarray(calibrated.motor_efficiency)
    return r / np.exp(np.mean(np.log(r)))
