"""ESC command <-> propeller speed, the one place this conversion happens.

The paper's load-cell fit (Tong et al., Sec. IV) maps ESC PWM in microseconds to
RPM as ``RPM = a*PWM**2 + b*PWM + c`` with a = -0.0062, b = 29.37, c = -22992.
Other vehicles (the Crazyflie's 0..65535 PWM) use the same quadratic form with
their own coefficients and command range, carried by ``EscCurve``.

Both the simulator (offline) and the monitor (onboard) import this module, so
training and inference convert identically.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from monitor.errors import ConfigError

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
RAD_S_PER_RPM = 2.0 * math.pi / 60.0


@dataclass(frozen=True)
class EscCurve:
    """``rpm = a*cmd**2 + b*cmd + c`` on ``cmd`` in [cmd_min, cmd_max].

    ``cmd_unit`` is ``"us"`` for PWM pulse width in microseconds, or ``"cf16"``
    for the Crazyflie's 16-bit motor PWM (0..65535).
    """

    a_rpm_per_cmd2: float
    b_rpm_per_cmd: float
    c_rpm: float
    cmd_min: float
    cmd_max: float
    cmd_unit: str = "us"

    def __post_init__(self) -> None:
        if not self.cmd_max > self.cmd_min:
            raise ConfigError("esc.cmd_max: must be greater than esc.cmd_min")
        if self.cmd_unit not in ("us", "cf16"):
            raise ConfigError(f"esc.cmd_unit: must be 'us' or 'cf16', got {self.cmd_unit!r}")
        slope_lo = 2 * self.a_rpm_per_cmd2 * self.cmd_min + self.b_rpm_per_cmd
        slope_hi = 2 * self.a_rpm_per_cmd2 * self.cmd_max + self.b_rpm_per_cmd
        if slope_lo <= 0 or slope_hi <= 0:
            raise ConfigError("esc: the RPM curve must increase over [cmd_min, cmd_max] to be invertible")

    def cmd_to_rpm(self, cmd: np.ndarray | float) -> np.ndarray:
        """Commanded (target) RPM for an ESC command; clipped to the command range."""
        c = np.clip(np.asarray(cmd, dtype=np.float64), self.cmd_min, self.cmd_max)
        return (self.a_rpm_per_cmd2 * c + self.b_rpm_per_cmd) * c + self.c_rpm

    def rpm_to_cmd(self, rpm: np.ndarray | float) -> np.ndarray:
        """Inverse on the increasing branch; RPM outside the curve's range saturates."""
        rpm = np.asarray(rpm, dtype=np.float64)
        lo, hi = self.cmd_to_rpm(self.cmd_min), self.cmd_to_rpm(self.cmd_max)
        r = np.clip(rpm, lo, hi)
        a, b, c = self.a_rpm_per_cmd2, self.b_rpm_per_cmd, self.c_rpm - r
        if a == 0.0:
            return -c / b
        disc = np.maximum(b * b - 4.0 * a * c, 0.0)
        # Numerically stable root of the increasing branch (citardauq form).
        return (2.0 * c) / (-b - np.sqrt(disc))

    def cmd_to_omega_rad_s(self, cmd: np.ndarray | float) -> np.ndarray:
        return self.cmd_to_rpm(cmd) * RAD_S_PER_RPM

    def omega_rad_s_to_cmd(self, omega_rad_s: np.ndarray | float) -> np.ndarray:
        return self.rpm_to_cmd(np.asarray(omega_rad_s) * RPM_PER_RAD_S)


# The paper's fit, PWM in microseconds (Tong et al., Sec. IV "RPM_i = ...").
PAPER_ESC = EscCurve(a_rpm_per_cmd2=-0.0062, b_rpm_per_cmd=29.37, c_rpm=-22992.0, cmd_min=1000.0, cmd_max=2000.0)


def pwm_us_to_rpm(pwm_us: np.ndarray | float, curve: EscCurve = PAPER_ESC) -> np.ndarray:
    return curve.cmd_to_rpm(pwm_us)


def rpm_to_pwm_us(rpm: np.ndarray | float, curve: EscCurve = PAPER_ESC) -> np.ndarray:
    return curve.rpm_to_cmd(rpm)
