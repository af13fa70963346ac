"""Classifier features: the one numpy module used by training and by the monitor.

Input is a mapping of canonical signals, each with any leading axes (flights)
and time on the last axis (plus a trailing axis of 4 for ``motor_rpm``):

| signal             | shape      | unit  | meaning |
| motor_rpm          | (..., T, 4)| RPM   | target RPM per rotor, PX4 order, from the ESC fit (monitor.esc) or ESC telemetry |
| roll_rad, pitch_rad, yaw_rad | (..., T) | rad | attitude, Euler ZYX |
| roll_rate_rad_s, pitch_rate_rad_s, yaw_rate_rad_s | (..., T) | rad/s | body rates (FRD) |

A feature is named; a model stores its ordered list of names and the monitor
computes exactly those. ``PAPER_FEATURES`` are the paper's ten signals.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from monitor.errors import ModelError

SAMPLE_RATE_HZ = 20.0
WINDOW_STEPS = 100

SIGNALS = (
    "motor_rpm",
    "roll_rad",
    "pitch_rad",
    "yaw_rad",
    "roll_rate_rad_s",
    "pitch_rate_rad_s",
    "yaw_rate_rad_s",
)

Signals = Mapping[str, np.ndarray]


def _rpm(i: int) -> Callable[[Signals], np.ndarray]:
    return lambda s: s["motor_rpm"][..., i]


def _rpm_rel(i: int) -> Callable[[Signals], np.ndarray]:
    # Each rotor's share of the mean: invariant to payload and to the ESC fit's scale.
    def f(s: Signals) -> np.ndarray:
        rpm = s["motor_rpm"]
        mean = np.mean(rpm, axis=-1)
        return rpm[..., i] / np.where(np.abs(mean) > 1.0, mean, 1.0) - 1.0

    return f


# Body moments each rotor's speed asks for, PX4 quad-X (1 front-right CCW, 2 rear-left CCW,
# 3 front-left CW, 4 rear-right CW): thrust ~ rpm^2, roll = -y*T, pitch = x*T, yaw = spin drag.
# In (kRPM)^2, not normalised: the angular acceleration they produce is what reveals a weak
# propeller independently of payload (payload changes the mass, not the rotor's leverage).
_MOMENT_SIGNS = {
    "roll": (-1.0, 1.0, 1.0, -1.0),
    "pitch": (1.0, -1.0, 1.0, -1.0),
    "yaw": (1.0, 1.0, -1.0, -1.0),
}


def _moment(axis: str) -> Callable[[Signals], np.ndarray]:
    signs = np.array(_MOMENT_SIGNS[axis])

    def f(s: Signals) -> np.ndarray:
        return _krpm_squared(s) @ signs

    return f


def _krpm_squared(s: Signals) -> np.ndarray:
    """(..., T, 4) each rotor's (kRPM)^2, what its thrust and drag torque scale with."""
    k = np.asarray(s["motor_rpm"], dtype=np.float64) / 1000.0
    return k * k


def _collective(s: Signals) -> np.ndarray:
    # Sum of the four rotors' (kRPM)^2: what the collective thrust and drag torque scale with.
    return np.sum(_krpm_squared(s), axis=-1)


def _plain(name: str) -> Callable[[Signals], np.ndarray]:
    return lambda s: s[name]


FEATURES: dict[str, Callable[[Signals], np.ndarray]] = {
    **{f"rpm_{i + 1}": _rpm(i) for i in range(4)},
    **{f"rpm_rel_{i + 1}": _rpm_rel(i) for i in range(4)},
    **{n: _plain(n) for n in SIGNALS[1:]},
    "rpm_mean": lambda s: np.mean(s["motor_rpm"], axis=-1),
    "yaw_sin": lambda s: np.sin(s["yaw_rad"]),
    "yaw_cos": lambda s: np.cos(s["yaw_rad"]),
    **{f"{a}_moment_krpm2": _moment(a) for a in _MOMENT_SIGNS},
    "collective_krpm2": _collective,
}

PAPER_FEATURES: tuple[str, ...] = (
    "rpm_1",
    "rpm_2",
    "rpm_3",
    "rpm_4",
    "roll_rad",
    "pitch_rad",
    "yaw_rad",
    "roll_rate_rad_s",
    "pitch_rate_rad_s",
    "yaw_rate_rad_s",
)


def check_feature_names(names: Sequence[str]) -> None:
    unknown = [n for n in names if n not in FEATURES]
    if unknown:
        raise ModelError(f"unknown feature(s) {unknown}; known: {sorted(FEATURES)}")


def compute_features(signals: Signals, names: Sequence[str] = PAPER_FEATURES) -> np.ndarray:
    """Stack the named features on a last axis: (..., T, F) float32. NaN in, NaN out."""
    check_feature_names(names)
    missing = [s for s in SIGNALS if s not in signals and any(_needs(n, s) for n in names)]
    if missing:
        raise ModelError(f"signals missing for features: {missing}")
    return feature_function(names)(signals)


def feature_function(names: Sequence[str]) -> Callable[[Signals], np.ndarray]:
    """``compute_features`` for these names, checked once: for a caller that computes them step by step
    (the daemon, 20 times a second) and always passes every signal. Same functions, same numbers."""
    check_feature_names(names)
    fns = [FEATURES[n] for n in names]

    def compute(signals: Signals) -> np.ndarray:
        return np.stack([np.asarray(f(signals), dtype=np.float64) for f in fns], axis=-1).astype(np.float32)

    return compute


_ATT, _REL, _MEAN, _RPM, _SIN, _COS, _COLLECTIVE, _MOMENT = range(8)  # step_feature_function's operations


def step_feature_function(names: Sequence[str]) -> Callable[[np.ndarray, np.ndarray, np.ndarray], None]:
    """The features of one grid step, written into a caller's row: ``compute(motor_rpm, attitude, out)``.

    ``motor_rpm`` (4,) float64 RPM; ``attitude`` (6,) float64 (roll, pitch, yaw rad, roll, pitch, yaw
    rate rad/s); ``out`` (F,) any float dtype (the daemon's float32 ring row). The daemon computes these 20
    times a second; ``feature_function`` on the same step (T = 1) spends ~3x as long rebuilding the same
    intermediates per feature. Bit-identical to it, by construction: every reduction, matmul and
    transcendental is the same numpy call on the same (1, ...) shapes, computed once and shared; the
    rest is the same IEEE double arithmetic on scalars; the float32 rounding is one cast of the row.
    ``tests/test_features_step.py`` compares the two on random and recorded input.
    """
    check_feature_names(names)
    plain = {name: i for i, name in enumerate(SIGNALS[1:])}  # attitude index of each plain signal
    ops: list[tuple[int, int]] = []  # (what, index) per feature, decided once
    for name in names:
        if name in plain:
            ops.append((_ATT, plain[name]))
        elif name.startswith("rpm_rel_"):
            ops.append((_REL, int(name[-1]) - 1))
        elif name == "rpm_mean":
            ops.append((_MEAN, 0))
        elif name.startswith("rpm_"):
            ops.append((_RPM, int(name[-1]) - 1))
        elif name in ("yaw_sin", "yaw_cos"):
            ops.append((_SIN if name == "yaw_sin" else _COS, 0))
        elif name == "collective_krpm2":
            ops.append((_COLLECTIVE, 0))
        else:  # {roll,pitch,yaw}_moment_krpm2
            ops.append((_MOMENT, tuple(_MOMENT_SIGNS).index(name.split("_", 1)[0])))
    what = {w for w, _ in ops}
    needs_mean = bool(what & {_REL, _MEAN})
    needs_k2 = bool(what & {_COLLECTIVE, _MOMENT})
    signs = [np.array(s) for s in _MOMENT_SIGNS.values()]
    row = np.empty(len(ops), dtype=np.float64)

    def compute(motor_rpm: np.ndarray, attitude: np.ndarray, out: np.ndarray) -> None:
        rpm = np.asarray(motor_rpm, dtype=np.float64).reshape(1, 4)
        mean = denom = 1.0
        if needs_mean:
            mean = float(np.mean(rpm, axis=-1)[0])
            denom = mean if abs(mean) > 1.0 else 1.0
        if needs_k2:
            k = rpm / 1000.0
            k2 = k * k
        for j, (w, i) in enumerate(ops):
            if w == _ATT:
                row[j] = attitude[i]
            elif w == _REL:
                row[j] = float(rpm[0, i]) / denom - 1.0
            elif w == _MEAN:
                row[j] = mean
            elif w == _RPM:
                row[j] = rpm[0, i]
            elif w == _SIN:
                row[j] = np.sin(attitude[2:3])[0]
            elif w == _COS:
                row[j] = np.cos(attitude[2:3])[0]
            elif w == _COLLECTIVE:
                row[j] = np.sum(k2, axis=-1)[0]
            else:
                row[j] = (k2 @ signs[i])[0]
        out[:] = row  # the one float64 -> out dtype rounding, as feature_function's astype

    return compute


def signals_needed(feature: str) -> tuple[str, ...]:
    """The canonical signals a named feature is computed from."""
    check_feature_names([feature])
    return tuple(s for s in SIGNALS if _needs(feature, s))


def _needs(feature: str, signal: str) -> bool:
    if signal == "motor_rpm":
        return feature.startswith("rpm") or feature.endswith("_krpm2")
    if signal == "yaw_rad":
        return feature in ("yaw_rad", "yaw_sin", "yaw_cos")
    return feature == signal


def sliding_windows(features: np.ndarray, window: int = WINDOW_STEPS, hop: int = 1) -> np.ndarray:
    """(..., T, F) -> (..., N, window, F) as a strided view (no copy); N = (T - window)//hop + 1."""
    if features.shape[-2] < window:
        shape = features.shape[:-2] + (0, window, features.shape[-1])
        return np.empty(shape, dtype=features.dtype)
    v = np.lib.stride_tricks.sliding_window_view(features, window, axis=-2)  # (..., N, F, window)
    v = np.swapaxes(v, -1, -2)
    return v[..., ::hop, :, :]


def valid_windows(windows: np.ndarray) -> np.ndarray:
    """(..., N) mask: windows with no NaN or inf anywhere (never classify invented data)."""
    return np.isfinite(windows).all(axis=(-1, -2))


@dataclass(frozen=True)
class Normalizer:
    """Per-feature standardisation; its statistics travel inside the model's metadata."""

    mean: tuple[float, ...]
    std: tuple[float, ...]

    @classmethod
    def fit(cls, features: np.ndarray) -> Normalizer:
        flat = features.reshape(-1, features.shape[-1]).astype(np.float64)
        flat = flat[np.isfinite(flat).all(axis=1)]
        std = flat.std(axis=0)
        std = np.where(std > 1e-9, std, 1.0)
        return cls(tuple(map(float, flat.mean(axis=0))), tuple(map(float, std)))

    def to_dict(self) -> dict:
        return {"mean": list(self.mean), "std": list(self.std)}

    @classmethod
    def from_dict(cls, d: Mapping) -> Normalizer:
        return cls(tuple(map(float, d["mean"])), tuple(map(float, d["std"])))


# ---------------------------------------------------------------------------
# Native-rate evidence: computed at the log's own rate (CrazyPAD 100 Hz), not on the
# 20 Hz model grid, because what a damaged blade adds to a motor command or to the airframe's
# acceleration lives above 10 Hz and is gone after resampling. One function each, numpy only,
# so the daemon can call them when its streams are fast enough (``NATIVE_MIN_RATE_HZ``).

NATIVE_MIN_RATE_HZ = 50.0  # below this the high band (VIBRATION_BAND_HZ) is not observable
# Lower edge of the "vibration" band. Chosen, not measured: well above the flight script's manoeuvres (below 2 Hz)
# and below the Nyquist frequency of the slowest native stream (25 Hz at NATIVE_MIN_RATE_HZ).
VIBRATION_BAND_HZ = 15.0


def _check_native_rate(rate_hz: float, what: str) -> None:
    if not np.isfinite(rate_hz) or rate_hz < NATIVE_MIN_RATE_HZ:
        raise ModelError(f"{what}: needs a stream at >= {NATIVE_MIN_RATE_HZ:g} Hz, got {rate_hz!r} Hz")


def motor_command_activity(motor_cmd: np.ndarray, rate_hz: float, mask: np.ndarray | None = None) -> np.ndarray:
    """(..., T, 4) motor commands at their native rate -> (..., 4) activity per motor.

    Activity = std of the sample-to-sample change over the mean command, both over the
    samples ``mask`` keeps (airborne; a difference counts when both of its samples are kept).
    Dimensionless, so independent of the command unit and of the vehicle's weight. A motor
    whose controller keeps correcting (a damaged or unbalanced propeller) is more active.
    """
    _check_native_rate(rate_hz, "motor_command_activity")
    cmd = np.asarray(motor_cmd, dtype=np.float64)
    d = np.diff(cmd, axis=-2)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        keep = m[1:] & m[:-1]
        d = np.where(keep[:, None], d, np.nan)
        cmd = np.where(m[:, None], cmd, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.nanmean(cmd, axis=-2)
        return np.nanstd(d, axis=-2) / np.where(np.abs(mean) > 0, np.abs(mean), np.nan)


def vibration_energy(accel: np.ndarray, rate_hz: float, band_hz: float = VIBRATION_BAND_HZ) -> np.ndarray:
    """(..., T, 3) accelerations (any unit u, any frame) -> (...,) mean-square above ``band_hz`` in u².

    Parseval on the real FFT of each axis (mean removed), summed over the axes: the power
    of everything faster than the flight's manoeuvres. Rows with NaN must be cut by the
    caller (a FFT cannot skip them): a NaN anywhere gives NaN.
    """
    _check_native_rate(rate_hz, "vibration_energy")
    if not 0.0 < band_hz < rate_hz / 2.0:
        raise ModelError(f"vibration_energy: band_hz must be in (0, {rate_hz / 2:g}) Hz, got {band_hz}")
    a = np.asarray(accel, dtype=np.float64)
    n = a.shape[-2]
    if n < 4:
        return np.full(a.shape[:-2], np.nan)
    a = a - np.mean(a, axis=-2, keepdims=True)
    spec = np.fft.rfft(a, axis=-2)
    freq = np.fft.rfftfreq(n, d=1.0 / rate_hz)
    w = np.where(freq >= band_hz, 2.0, 0.0)  # one-sided spectrum: both halves of each bin
    if n % 2 == 0:
        w[-1] = np.where(freq[-1] >= band_hz, 1.0, 0.0)  # the Nyquist bin has no mirror
    power = np.sum(w[:, None] * np.abs(spec) ** 2, axis=-2) / (n * n)
    return np.sum(power, axis=-1)
