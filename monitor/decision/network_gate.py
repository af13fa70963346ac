"""Does the fault classifier know this airframe? Where it does not, it is silent: its windows are no evidence.

The network learnt one airframe's motor outputs and attitude. Its RPM features' training statistics (the model's
``normalization``) say what that airframe's RPM looks like in flight; a vehicle whose airborne RPM sits outside the
warning bounds below flies unlike it (another size, propeller, mass or ESC), and the network's answer there is a
guess. ``propwatch diagnose`` judges the whole flight's airborne RPM (``monitor.diagnose.engine.rpm_envelope``); the
daemon (``NetworkGate``) judges the mean of each flight's airborne RPM so far (frozen after ``GATE_S``). Both use
these bounds.
"""

from __future__ import annotations

import numpy as np

# Airborne RPM against what the model saw in training (its normaliser's mean and std per RPM feature): the typical
# |z| of each rotor's RPM over the flight, and the ratio of means. Beyond WARN the network is silent; beyond REFUSE
# it would be guessing outright. Chosen, not measured: 96 randomised healthy flights of our simulator (seed 100,
# `python -m bench.decision_constants`) read rpm_z 0.07-2.21 and rpm_ratio 0.87-1.18; 1 of them passes a WARN
# bound, none a REFUSE one.
RPM_Z_WARN, RPM_Z_REFUSE = 2.0, 3.0
RPM_RATIO_WARN = (0.85, 1.15)
# How ``propwatch diagnose`` begins its reason where nothing declared the log's airframe to be the network's
# (``monitor.diagnose.engine.undeclared``); the rendering recognises it by this start.
UNDECLARED_START = "the network knows one airframe"
RPM_RATIO_REFUSE = (0.6, 1.6)
RPM_FEATURES = ("rpm_1", "rpm_2", "rpm_3", "rpm_4", "rpm_mean")
MIN_S = 2.0  # airborne seconds of RPM before the daemon may silence the network in a flight (chosen)
GATE_S = 10.0  # airborne seconds after which the flight's mean RPM is frozen (the rule's own baseline span)


def trained_mean_rpm(metadata: dict, features) -> float | None:
    """The mean RPM of the model's training flights (its normaliser's RPM features), None where it has none."""
    norm = metadata.get("normalization", {})
    idx = [i for i, f in enumerate(features) if f in RPM_FEATURES]
    if not idx or "mean" not in norm:
        return None
    m = float(np.mean([norm["mean"][i] for i in idx]))
    return m if m > 0 else None  # a model normalised about zero says nothing of its airframe's RPM


def ratio_known(ratio: float) -> bool:
    return RPM_RATIO_WARN[0] <= ratio <= RPM_RATIO_WARN[1]


class NetworkGate:
    """Per flight: on a vehicle ``declared`` to be the model's airframe, the network speaks until the mean of the four
    rotors' RPM over at least ``MIN_S`` airborne says the airframe is not its training airframe (outside
    ``RPM_RATIO_WARN`` of the training mean); the mean is frozen after ``GATE_S``. On the model's own airframe it
    never holds anything, so the daemon and ``diagnose`` feed the rule the same windows there. Undeclared, it never
    speaks (``diagnose`` without ``--model``/``--vehicle`` alike)."""

    def __init__(self, trained_rpm: float | None, rate_hz: float, declared: bool = True) -> None:
        self.declared = declared
        self.trained_rpm = trained_rpm
        self.min_steps = max(int(round(MIN_S * rate_hz)), 1)
        self.gate_steps = max(int(round(GATE_S * rate_hz)), self.min_steps)
        self.reset()

    def reset(self) -> None:
        self._sum, self._n = 0.0, 0

    def step(self, rpm, airborne: bool) -> None:
        if not airborne:
            if self._n:
                self.reset()
            return
        if self.trained_rpm is None or self._n >= self.gate_steps or rpm is None:
            return
        m = float(np.mean(rpm))
        if np.isfinite(m):
            self._sum += m
            self._n += 1

    @property
    def ratio(self) -> float | None:
        if self.trained_rpm is None or self._n < self.min_steps:
            return None
        return self._sum / self._n / self.trained_rpm

    @property
    def speaks(self) -> bool:
        """Whether the network's windows are evidence now."""
        if not self.declared:
            return False
        r = self.ratio
        return r is None or ratio_known(r)
