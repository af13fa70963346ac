"""Per-rotor response gain at a log's native rate: the angular acceleration each rotor's command change buys.

Physics ("CG offset or damage?"): a damaged propeller lowers its rotor's thrust per command, so
the body's angular acceleration per change of that rotor's command drops; a mass near a rotor moves the
trim (a constant moment) and leaves the per-command gains (nearly) alone. Per flight, over each airborne
stretch, this fits

    alpha(t) = sum_i beta_i * u_i(t - lag) + c

(both sides through the same [1/4, 1/2, 1/4] smoother first: a linear filter on both sides of a linear model
keeps its coefficients, and it removes the Nyquist-rate alternation of the logged Crazyflie commands, an alias
of the 500 Hz controller) where ``alpha`` is one body axis's angular acceleration (differentiated gyro rate, or the twice-differentiated
Euler angle where no rate is logged), ``u_i`` rotor i's command minus its moving mean over ``highpass_s``
(so the trim, and with it a CG offset's constant moment, drops out), ``alpha`` high-passed alike, ``c`` a
moment bias. ``lag`` is the motor's time constant: a command moves thrust that much later.

Caveat, measured (``offline/crazypad/README.md``): in closed loop the commands answer the gyro (a rate
controller's D term makes ``u`` follow ``-alpha`` within a sample), so this open-loop fit is biased. On our
simulator's flights (white gyro noise, PX4-like D term) it does not even recover the healthy sign pattern; on
real CrazyPAD flights it does, with R^2 0.4-0.6, but its per-flight noise (25-60 % of each gain) hides the
5-15 % losses of the cut propellers. Reported as evidence, never used to clear or convict a rotor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.errors import ModelError
from monitor.features import NATIVE_MIN_RATE_HZ
from monitor.flight import true_runs


@dataclass(frozen=True)
class ResponseGain:
    beta: np.ndarray  # (4,) angular acceleration per unit command change, (rad/s^2) per command unit, rotor order of u
    r2: float  # share of the high-passed acceleration's variance the fit explains
    samples: int  # samples used

    def relative(self, signs: np.ndarray) -> np.ndarray:
        """(4,) each rotor's gain in its expected direction over the mean of the four (1 = equal rotors).

        ``signs`` (4,): the sign of each rotor's moment about this axis for more thrust (geometry)."""
        g = np.asarray(signs, dtype=np.float64) * self.beta
        mean = float(np.mean(g))
        if not mean > 0:
            return np.full(4, np.nan)
        return g / mean


def _moving_mean(x: np.ndarray, n: int) -> np.ndarray:
    return _filter(x, np.ones(n) / n)


SMOOTHER = np.array([0.25, 0.5, 0.25])  # zero gain at the Nyquist rate


def _filter(x: np.ndarray, k: np.ndarray) -> np.ndarray:
    if x.ndim == 1:
        return np.convolve(x, k, mode="same")
    return np.stack([np.convolve(x[:, j], k, mode="same") for j in range(x.shape[1])], axis=1)


def angular_acceleration(rate_rad_s: np.ndarray | None, angle_rad: np.ndarray | None, rate_hz: float) -> np.ndarray:
    """(T,) rad/s^2 from a body rate (one difference) or, where none is logged, an Euler angle (two)."""
    if rate_rad_s is not None and np.isfinite(rate_rad_s).any():
        return np.gradient(np.asarray(rate_rad_s, dtype=np.float64)) * rate_hz
    if angle_rad is not None and np.isfinite(angle_rad).any():
        a = np.unwrap(np.asarray(angle_rad, dtype=np.float64))
        return np.gradient(np.gradient(a)) * rate_hz * rate_hz
    raise ModelError("response gain: neither a body rate nor an angle of this axis is logged")


def fit_response_gain(
    motor_cmd: np.ndarray,
    accel_rad_s2: np.ndarray,
    rate_hz: float,
    mask: np.ndarray,
    lag_s: float,
    highpass_s: float = 0.5,
    min_stretch_s: float = 1.5,
) -> ResponseGain:
    """Fit ``beta`` (see the module doc) over the stretches where ``mask`` holds, each at least ``min_stretch_s``.

    ``motor_cmd`` (T, 4) in any command unit; ``accel_rad_s2`` (T,). Each stretch loses ``highpass_s`` at
    both ends (the moving mean is not centred there). Raises ``ModelError`` with too little data."""
    if not (np.isfinite(rate_hz) and rate_hz >= NATIVE_MIN_RATE_HZ):
        raise ModelError(f"fit_response_gain: needs a stream at >= {NATIVE_MIN_RATE_HZ:g} Hz, got {rate_hz!r} Hz")
    cmd = np.asarray(motor_cmd, dtype=np.float64)
    acc = np.asarray(accel_rad_s2, dtype=np.float64)
    if cmd.ndim != 2 or cmd.shape[1] != 4 or acc.shape != (cmd.shape[0],) or np.shape(mask) != acc.shape:
        raise ModelError(f"fit_response_gain: need (T, 4) commands, (T,) acceleration and mask; got {cmd.shape}, {acc.shape}")
    if not (lag_s >= 0 and highpass_s > 0):
        raise ModelError(f"fit_response_gain: lag_s must be >= 0 and highpass_s > 0, got {lag_s}, {highpass_s}")
    lag = int(round(lag_s * rate_hz))
    w = max(2, int(round(highpass_s * rate_hz)))
    xs, ys = [], []
    for a, b in true_runs(np.asarray(mask, dtype=bool)):
        if b - a < max(min_stretch_s * rate_hz, 2 * w + lag + 10):
            continue
        u, y = _filter(cmd[a:b], SMOOTHER), _filter(acc[a:b], SMOOTHER)
        u = (u - _moving_mean(u, w))[w:-w]
        y = (y - _moving_mean(y, w))[w:-w]
        if lag:
            u, y = u[:-lag], y[lag:]
        ok = np.isfinite(u).all(axis=1) & np.isfinite(y)
        xs.append(u[ok])
        ys.append(y[ok])
    n = sum(len(y) for y in ys)
    if n < 5 * rate_hz:
        raise ModelError(f"fit_response_gain: {n} usable samples, need {5 * rate_hz:g} (5 s of steady flight)")
    x, y = np.concatenate(xs), np.concatenate(ys)
    scale = float(np.std(x)) or 1.0  # conditioning only; beta is returned in the command's own unit
    design = np.column_stack([x / scale, np.ones(len(y))])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    resid = y - design @ coef
    r2 = 1.0 - float(np.var(resid)) / float(np.var(y)) if np.var(y) > 0 else float("nan")
    return ResponseGain(beta=coef[:4] / scale, r2=r2, samples=int(n))
