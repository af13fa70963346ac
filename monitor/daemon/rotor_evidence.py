"""Rotor effectiveness in flight: what each rotor delivers, from the moment balance.

The daemon keeps the last ``window`` consecutive valid grid steps (5 s at 20 Hz) of commanded RPM and body
rates; when it raises an alert it reads them as ``propwatch diagnose`` reads a log
(``monitor.diagnose.physics``, ``monitor.decision.effectiveness``): the window's roll, pitch and yaw balance of the
commanded ω² against the measured rates gives each rotor's fraction of nominal thrust under the balance's
most probable set, with its standard deviation (the balance's own least-squares reading,
``Priors.for_measurement``). It is the 5 s before the alert, so a fault that began mid-flight is read as it
is now, not averaged with the healthy minutes before it. A reading outside ``PLAUSIBLE_EFFECTIVENESS`` means
the balance does not close for this vehicle (another airframe, a wrong ESC curve): none is reported. It
raises nothing by itself.

The airframe's own trim, CG offset and motor spread move the balance as damage does, so the reading is taken
against this flight's own balance: every non-overlapping window of the flight (one balance per 5 s) joins a
baseline once it is ``PRE_CHANGE_MARGIN_S`` old, until the first alert freezes it (the onset precedes the
alert by the rule's detection delay); a landing clears it. With two windows or more it is the prior of the
disturbance (``Baseline``), as diagnose reads a log after an in-flight change
(``monitor.diagnose.engine.after_change_physics``). Cost: a copy per step, one balance per 5 s; one balance
and two 16-set window posteriors (``HypothesisBank.window_posterior``, ~0.2 ms) per alert, plus the two banks'
inversion (~1 ms) when the baseline has changed since the last alert.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from monitor.decision.effectiveness import (
    PLAUSIBLE_EFFECTIVENESS,
    PRE_CHANGE_MARGIN_S,
    Baseline,
    HypothesisBank,
    Priors,
    RotorGeometry,
    baseline_from_balances,
    window_balance,
)


class RecentEffectiveness:
    def __init__(self, vehicle, window: int, rate_hz: float, priors: Priors | None = None):
        self.geometry = RotorGeometry.from_vehicle(vehicle)
        self.priors = priors or Priors()
        self.window = int(window)
        self.rate_hz = float(rate_hz)
        self._margin_steps = int(round(PRE_CHANGE_MARGIN_S * self.rate_hz))
        self._banks: tuple[HypothesisBank, HypothesisBank] | None = None
        self._banks_for: tuple | None = None
        # Stored twice so the last ``window`` steps are one contiguous slice (as the pipeline's feature ring).
        self._rpm = np.zeros((2 * self.window, 4))
        self._rates = np.zeros((2 * self.window, 3))
        self.reset()
        self.new_flight()

    def reset(self) -> None:
        self._head = 0
        self._count = 0
        self._since_window = 0

    def new_flight(self) -> None:
        """Forget the flight's own baseline (a landing; the next flight starts its own)."""
        self._pending: deque[tuple[int, np.ndarray]] = deque()  # (step it ended at, z (3,)) not yet old enough
        self._base: list[np.ndarray] = []  # the balances (3,) of the windows in the baseline: one per 5 s of flight
        self._frozen = False
        self._step = 0

    def freeze(self) -> None:
        """An alert: the baseline keeps what it has (the windows before the onset)."""
        self._frozen = True
        self._pending.clear()

    def baseline(self) -> Baseline | None:
        """The flight's own balance so far as a ``Baseline`` (``baseline_from_balances``, as diagnose reads a log)."""
        return baseline_from_balances(np.array(self._base)) if len(self._base) >= 2 else None

    def push(self, motor_rpm, rates_rad_s, valid: bool, airborne: bool = True) -> None:
        """One grid step: commanded RPM (4,), body rates FRD (3,); an invalid step breaks the run; a step on the
        ground ends the flight's baseline."""
        if not airborne:
            if self._base or self._pending or self._frozen:
                self.new_flight()
            self.reset()
            return
        self._step += 1
        if not valid or motor_rpm is None or rates_rad_s is None:
            self.reset()
            return
        rpm, rates = np.asarray(motor_rpm, dtype=np.float64), np.asarray(rates_rad_s, dtype=np.float64)
        if rpm.shape != (4,) or rates.shape != (3,) or not (np.isfinite(rpm).all() and np.isfinite(rates).all()):
            self.reset()
            return
        w, h = self.window, self._head
        self._rpm[h] = self._rpm[h + w] = rpm
        self._rates[h] = self._rates[h + w] = rates
        self._head = (h + 1) % w
        self._count = min(self._count + 1, w)
        self._since_window += 1
        if self._frozen:
            return
        if self._since_window >= w and self._count == w:  # a new non-overlapping window: the flight's own balance
            self._since_window = 0
            z = self._balance()[0][0]
            if np.isfinite(z).all():
                self._pending.append((self._step, z))
        while self._pending and self._step - self._pending[0][0] >= self._margin_steps:
            self._base.append(self._pending.popleft()[1])

    def _balance(self):
        s = slice(self._head, self._head + self.window)  # oldest first
        return window_balance(self._rpm[None, s], self._rates[None, s], self.geometry, self.rate_hz)

    def _banks_now(self) -> tuple[HypothesisBank, HypothesisBank]:
        base = self.baseline()
        key = None if base is None else (base.disturbance_mean, base.disturbance_std)
        if self._banks is None or key != self._banks_for:
            self._banks = (
                HypothesisBank(self.priors, self.geometry, base),
                HypothesisBank(self.priors.for_measurement(), self.geometry, base),
            )
            self._banks_for = key
        return self._banks

    def reading(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(fraction of nominal thrust (4,), its std (4,)) over the last window; None before one is full."""
        if self._count < self.window:
            return None
        z, h, std = self._balance()
        sets, measure = self._banks_now()
        best = sets.window_posterior(z, h, std).best  # = posterior of one window's Evidence, to rounding
        m = measure.window_posterior(z, h, std)
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
