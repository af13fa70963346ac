"""Another checkout's decision rule (``propwatch evaluate alerts --compare-with CHECKOUT``), replayed as it ships.

The rule is reached through its named entry points in a Python of its own, never mixed with this tree's
modules: a child interpreter started with only ``CHECKOUT`` on its path imports ``DecisionConfig``,
``Decision`` and ``WindowEvidence``, ``load_calibration`` and ``replay`` / ``FlightSteps`` from the
checkout's ``monitor.decision`` package, and reads ``CHECKOUT/models/decision-calibration.json``. Each flight
goes to it as data (its window outputs and steps, plain arrays, pickled over stdin); its alerts come back the
same way, as ``offline.alerts.rules.decision_rule`` gives them (``(t_s, level, propellers, sets)``).
"""

from __future__ import annotations

import dataclasses
import os
import pickle
import subprocess
import sys
import weakref
from pathlib import Path

from offline.alerts.flights import AlertFlight

# Run by the child with CHECKOUT as sys.argv[1] and first on its path: one pickled flight in, its alerts out.
CHILD = """
import pickle, sys
from pathlib import Path
import numpy as np
from monitor.decision.config import DecisionConfig
from monitor.decision.replay import FlightSteps, replay
from monitor.decision.rule import Decision, WindowEvidence
from monitor.decision.thresholds import load_calibration

cfg = DecisionConfig()  # its own defaults: the rule as that checkout ships it
cal = load_calibration(Path(sys.argv[1]) / "models" / "decision-calibration.json")
src, dst = sys.stdin.buffer, sys.stdout.buffer
while True:
    try:
        f = pickle.load(src)
    except EOFError:
        break
    d = Decision(cfg, f["rate_hz"], f["window"], calibration=cal, use_stored_calibration=False)
    t_s = (np.arange(len(f["steps"]["airborne"])) + 1) / f["rate_hz"]
    ev = {k + f["window"] - 1: WindowEvidence(p) for k, p in enumerate(f["fault_probability"])}
    out = [(a.t_s, a.level, a.propellers, tuple(getattr(a, "sets", ())) or (a.propellers,))
           for a in replay(d, FlightSteps(**f["steps"]), t_s, ev)]
    pickle.dump(out, dst)
    dst.flush()
"""


def flight_data(f: AlertFlight) -> dict:
    """What the child reads of a flight: plain numbers and arrays, no class of this tree."""
    return {
        "rate_hz": f.rate_hz,
        "window": f.window,
        "fault_probability": f.fault_probability,
        "steps": dataclasses.asdict(f.steps()),
    }


class PreviousRule:
    """``rule(flight)`` -> the other checkout's alerts; its child interpreter starts at the first flight."""

    def __init__(self, checkout: str | Path):
        self.checkout = Path(checkout).resolve()
        self._child: subprocess.Popen | None = None

    def _start(self) -> subprocess.Popen:
        env = {**os.environ, "PYTHONPATH": str(self.checkout)}
        child = subprocess.Popen(
            [sys.executable, "-I", "-c", f"import sys; sys.path.insert(0, {str(self.checkout)!r})\n" + CHILD, str(self.checkout)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            cwd=self.checkout,
            env=env,
        )
        weakref.finalize(self, _close, child)
        return child

    def __call__(self, f: AlertFlight) -> list[tuple]:
        if self._child is None:
            self._child = self._start()
        pickle.dump(flight_data(f), self._child.stdin)
        self._child.stdin.flush()
        try:
            return pickle.load(self._child.stdout)
        except EOFError:
            raise RuntimeError(f"{self.checkout}: its decision rule stopped (exit {self._child.wait()})") from None


def _close(child: subprocess.Popen) -> None:
    child.stdin.close()
    child.wait()


def previous_rule(checkout: str | Path) -> PreviousRule:
    return PreviousRule(checkout)
