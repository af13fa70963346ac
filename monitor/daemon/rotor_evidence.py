"""Rotor effectiveness in flight (issue 12, point 3): what each rotor delivers, from the moment balance.

The daemon keeps the last ``window`` consecutive valid grid steps (5 s at 20 Hz) of commanded RPM and body
rates; when it raises an alert it reads them as ``propwatch diagnose`` reads a log
(``monitor.diagnose.physics``, ``monitor.effectiveness``): the window's roll, pitch and yaw balance of the
commanded ω² against the measured rates gives each rotor's fraction of nominal thrust under the balance's
most probable set, with its standard deviation (the balance's own least-squares reading,
``Priors.for_measurement``). It is the 5 s before the alert, so a fault that began mid-flight is read as it
is now, not averaged with the healthy minutes before it. A reading outside ``PLAUSIBLE_EFFECTIVENESS`` means
the balance does not close for this vehicle (another airframe, a wrong ESC curve): none is reported. It
raises nothing by itself. Cost: a copy per step; one balance and two 16-set window posteriors
(``HypothesisBank.window_posterior``, ~0.2 ms) per alert.
"""

from __future__ import annotations

import numpy as np

from monitor.diagnose.physics import PLAUSIBLE_EFFECTIVENESS
from monitor.effectiveness import HypothesisBank, Priors, RotorGeometry, window_balance


class RecentEffectiveness:
    def __init__(self, vehicle, window: int, rate_hz: float, priors: Priors | None = None):
        self.geometry = RotorGeometry.from_vehicle(vehicle)
        self.priors = priors or Priors()
        self.window = int(window)
        self.rate_hz = float(rate_hz)
        self._sets = HypothesisBank(self.priors, self.geometry)
        self._measure = HypothesisBank(self.priors.for_measurement(), self.geometry)
        # Stored twice so the last ``window`` steps are one contiguous slice (as the pipeline's feature ring).
        self._rpm = np.zeros((2 * self.window, 4))
        self._rates = np.zeros((2 * self.window, 3))
        self.reset()

    def reset(self) -> None:
        self._head = 0
        self._count = 0

    def push(self, motor_rpm, rates_rad_s, valid: bool) -> None:
        """One grid step: commanded RPM (4,), body rates FRD (3,); an invalid step breaks the run."""
        if not valid or motor_rpm is None or rates_rad_s is None:
            self._count = 0
            return
        rpm, rates = np.asarray(motor_rpm, dtype=np.float64), np.asarray(rates_rad_s, dtype=np.float64)
        if rpm.shape != (4,) or rates.shape != (3,) or not (np.isfinite(rpm).all() and np.isfinite(rates).all()):
            self._count = 0
            return
        w, h = self.window, self._head
        self._rpm[h] = self._rpm[h + w] = rpm
        self._rates[h] = self._rates[h + w] = rates
        self._head = (h + 1) % w
        self._count = min(self._count + 1, w)

    def reading(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(fraction of nominal thrust (4,), its std (4,)) over the last window; None before one is full."""
        if self._count < self.window:
            return None
        s = slice(self._head, self._head + self.window)  # oldest first
        z, h, std = window_balance(self._rpm[None, s], self._rates[None, s], self.geometry, self.rate_hz)
        best = self._sets.window_posterior(z, h, std).best  # = posterior of one window's Evidence, to rounding
        m = self._measure.window_posterior(z, h, std)
        eta, sd = m.thrust_fraction[best], m.thrust_fraction_std[best]
        lo, hi = PLAUSIBLE_EFFECTIVENESS
        return (eta, sd) if np.all((eta >= lo) & (eta <= hi)) else None

    def event_fields(self) -> dict:
        """``rotor_effectiveness`` and ``rotor_effectiveness_std`` (PX4 order) for an event; null without a reading."""
        r = self.reading()
        if r is None:
            return {"rotor_effectiveness": None, "rotor_effectiveness_std": None}
        return {
            "rotor_effectiveness": [round(float(x), 4) for x in r[0]],
            "rotor_effectiveness_std": [round(float(x), 4) for x in r[1]],
        }
