"""A virtual load cell that reproduces the paper's propeller experiment (Tong et al., Sec. V-A).

The experiment: one propeller on a stand at constant voltage, ESC command
ramped between 1000 and 2000 µs, RPM, thrust and torque sampled every 25 ms
for about 5 minutes, once per condition (normal, bent, cracked).

What is simulated, at ``internal_rate_hz`` (2 kHz, well above the 1P
frequency of up to 183 Hz):
- the command: full-range triangle ramps, each leg lasting a random
  ``leg_min_s``..``leg_max_s``, so the test 20 % sees ramp rates the training
  part also saw but not the same sequence;
- the motor: target speed from the vehicle's ESC curve (``monitor.esc``),
  followed with the vehicle's first-order motor time constant. The same curve
  serves every condition: the LSTM maps *measured* RPM to forces, so what a
  heavier-loaded damaged blade does to the ESC->RPM map never enters it (in
  flight the speed controller closes that loop);
- the propeller: ``kF·ω²`` and ``kτ·ω²`` of the vehicle (the normal propeller is
  the vehicle's), times the condition's mean signature, times its 1P ripple
  (blade angle integrated from ω) and flutter (Ornstein-Uhlenbeck noise);
  see ``offline.sim.faults`` for the physical argument;
- the stand: each 25 ms sample is the average over its period (the stand's
  ADC averages; this is what keeps a 100-180 Hz 1P ripple from aliasing into
  full-size errors), plus white sensor noise. RPM is an optical count over the
  period (the mean speed) with its own noise.

Noise defaults: thrust 0.01 N (1 gf) and torque 0.3 mN·m standard deviation;
RPM 5 RPM. A real RCbenchmark 1580 ramp sampled every 23.5 ms
(../shared/data/thrust_rcbench1580_dantonio, StepsTest20230615) reads
0.0038 N and 0.078 mN·m at rest (``thrust_stand.noise_at_rest``); the defaults
are 2.5x and 4x that, for the vibration a 10-inch propeller adds at speed
(a test keeps them at or above the real floor).

Everything is relative to the vehicle, so ``normalised()`` gives the speed as
a fraction of ``omega_max`` and forces as fractions of ``kF·omega_max²``,
``kτ·omega_max²`` -- the units the LSTMs learn in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

from monitor.errors import ConfigError
from monitor.esc import RAD_S_PER_RPM, RPM_PER_RAD_S
from monitor.vehicle import VehicleConfig
from offline.propellers.thrust_stand import GRAVITY_M_S2
from offline.sim.faults import CONDITIONS, SIGNATURES, FaultSignature


@dataclass(frozen=True)
class LoadCellConfig:
    duration_s: float = 300.0  # paper: "approximately 5 minutes"
    sample_period_s: float = 0.025  # paper: 25 ms
    internal_rate_hz: float = 2000.0
    esc_min_us: float = 1000.0  # paper: ESC 1000..2000, the operating limits
    esc_max_us: float = 2000.0
    leg_min_s: float = 3.0
    leg_max_s: float = 10.0
    thrust_noise_n: float = 0.01
    torque_noise_nm: float = 0.0003
    rpm_noise_rpm: float = 5.0
    seed: int = 0
    signatures: dict[str, FaultSignature] = field(default_factory=lambda: dict(SIGNATURES))

    def __post_init__(self) -> None:
        steps = self.sample_period_s * self.internal_rate_hz
        if abs(steps - round(steps)) > 1e-9 or round(steps) < 1:
            raise ConfigError("internal_rate_hz: must be a whole multiple of 1/sample_period_s")
        if not 0 < self.leg_min_s <= self.leg_max_s:
            raise ConfigError("leg_min_s: must be positive and <= leg_max_s")
        if not self.esc_min_us < self.esc_max_us:
            raise ConfigError("esc_min_us: must be below esc_max_us")
        if self.duration_s < 10 * self.sample_period_s:
            raise ConfigError("duration_s: too short for a sweep")

    @property
    def steps_per_sample(self) -> int:
        return int(round(self.sample_period_s * self.internal_rate_hz))


@dataclass(frozen=True)
class LoadCellRun:
    """One condition's sweep, one row per 25 ms sample, SI units."""

    condition: str
    time_s: np.ndarray
    esc_us: np.ndarray
    rpm: np.ndarray
    thrust_n: np.ndarray
    torque_nm: np.ndarray

    @property
    def omega_rad_s(self) -> np.ndarray:
        return self.rpm * RAD_S_PER_RPM

    def normalised(self, vehicle: VehicleConfig) -> tuple[np.ndarray, np.ndarray]:
        """(s (T,), y (T, 2)): speed / omega_max and [thrust / (kF·omega_max²), torque / (kτ·omega_max²)]."""
        w_max2 = vehicle.omega_max_rad_s**2
        s = self.omega_rad_s / vehicle.omega_max_rad_s
        y = np.stack(
            [self.thrust_n / (vehicle.kf_n_per_rad_s2 * w_max2), self.torque_nm / (vehicle.ktau_nm_per_rad_s2 * w_max2)], axis=-1
        )
        return s, y


def esc_ramp_us(cfg: LoadCellConfig, t_s: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Full-range triangle ramps with random leg durations, starting at the bottom."""
    knots_t, knots_v, t, up = [0.0], [cfg.esc_min_us], 0.0, True
    while t < t_s[-1]:
        t += rng.uniform(cfg.leg_min_s, cfg.leg_max_s)
        knots_t.append(t)
        knots_v.append(cfg.esc_max_us if up else cfg.esc_min_us)
        up = not up
    return np.interp(t_s, knots_t, knots_v)


def _first_order(x: np.ndarray, x0: float, dt_s: float, tau_s: float) -> np.ndarray:
    """Exact discretisation of tau·y' = x - y (x held over each step), started at y = x0."""
    a = math.exp(-dt_s / tau_s)
    y, _ = lfilter([1.0 - a], [1.0, -a], x, zi=[a * x0])
    return y


def _flutter(n: int, dt_s: float, tau_s: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance Ornstein-Uhlenbeck noise (correlation time tau_s)."""
    a = math.exp(-dt_s / tau_s)
    y, _ = lfilter([math.sqrt(1.0 - a * a)], [1.0, -a], rng.standard_normal(n), zi=[a * rng.standard_normal()])
    return y


def run_load_cell(vehicle: VehicleConfig, condition: str, cfg: LoadCellConfig = LoadCellConfig()) -> LoadCellRun:
    """Simulate one condition's sweep. Seeded by ``cfg.seed`` and the condition, so conditions differ."""
    if condition not in CONDITIONS:
        raise ConfigError(f"condition: must be one of {', '.join(CONDITIONS)}, got {condition!r}")
    sig = cfg.signatures[condition]
    rng = np.random.default_rng([cfg.seed, CONDITIONS.index(condition)])
    k = cfg.steps_per_sample
    n_samples = int(cfg.duration_s / cfg.sample_period_s)
    dt = 1.0 / cfg.internal_rate_hz
    t_fine = np.arange(n_samples * k) * dt

    esc = esc_ramp_us(cfg, t_fine, rng)
    omega_target = vehicle.esc.cmd_to_omega_rad_s(esc)
    omega = np.maximum(_first_order(omega_target, float(omega_target[0]), dt, vehicle.motor_time_constant_s), 0.0)

    w2 = omega**2
    s = omega / vehicle.omega_max_rad_s
    angle = np.cumsum(omega) * dt + rng.uniform(0.0, 2.0 * math.pi)
    ripple = np.sin(angle)
    flutter_t = _flutter(t_fine.size, dt, sig.flutter_time_constant_s, rng)
    flutter_q = _flutter(t_fine.size, dt, sig.flutter_time_constant_s, rng)
    thrust = (
        vehicle.kf_n_per_rad_s2
        * w2
        * sig.thrust_factor(s)
        * (1.0 + sig.ripple_1p_thrust * ripple + sig.flutter_thrust_std * s**2 * flutter_t)
    )
    torque = (
        vehicle.ktau_nm_per_rad_s2
        * w2
        * sig.torque_factor(s)
        * (1.0 + sig.ripple_1p_torque * ripple + sig.flutter_torque_std * s**2 * flutter_q)
    )

    def sample(x: np.ndarray) -> np.ndarray:  # the stand's average over each sample period
        return x.reshape(n_samples, k).mean(axis=1)

    return LoadCellRun(
        condition=condition,
        time_s=np.arange(n_samples) * cfg.sample_period_s,
        esc_us=esc[::k].copy(),
        rpm=np.maximum(sample(omega) * RPM_PER_RAD_S + cfg.rpm_noise_rpm * rng.standard_normal(n_samples), 0.0),
        thrust_n=sample(thrust) + cfg.thrust_noise_n * rng.standard_normal(n_samples),
        torque_nm=sample(torque) + cfg.torque_noise_nm * rng.standard_normal(n_samples),
    )


def write_tyto_csv(run: LoadCellRun, path: str | Path) -> Path:
    """Write a run as an RCbenchmark/Tyto-style export (gf, N·m, UTF-8 with BOM), readable by ``thrust_stand``."""
    path = Path(path)
    lines = ["\ufeffTime (s),ESC signal (µs),Torque (N·m),Thrust (gf),Motor Optical Speed (RPM),App message,"]
    for row in zip(run.time_s, run.esc_us, run.torque_nm, run.thrust_n / GRAVITY_M_S2 * 1000.0, run.rpm):
        lines.append(",".join(repr(float(v)) for v in row) + ",,")
    path.write_text("\r\n".join(lines) + "\r\n", encoding="utf-8", newline="")
    return path
