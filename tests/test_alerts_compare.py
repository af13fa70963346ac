"""``propwatch evaluate alerts --compare-with``: another checkout's decision rule, replayed as that checkout has it.

The rule lives in several modules (monitor/decision/rule.py and its parts); a comparison that loaded the other
checkout's rule but this tree's parts would replay a mix of both. The other checkout runs in its own interpreter
(``offline.alerts.previous``), so this one's modules are never touched.
"""

from __future__ import annotations

import shutil
import sys

import numpy as np

from monitor.decision.config import DecisionConfig
from monitor.vehicle import REPO_ROOT
from offline.alerts.flights import AlertFlight
from offline.alerts.previous import previous_rule
from offline.alerts.rules import decision_rule

RATE_HZ, WINDOW, HOVER_RPM = 20.0, 100, 6500.0


def onset_flight() -> AlertFlight:
    """80 s at hover; rotor 3 loses 10 % of its thrust at 30 s (share +5 %, its same-spin partner 4's -5 %)."""
    n = int(80 * RATE_HZ)
    rng = np.random.default_rng(0)
    w2 = np.ones((n, 4)) + 0.002 * rng.standard_normal((n, 4))
    w2[int(30 * RATE_HZ) :] += np.array([0.0, 0.0, 0.05, -0.05])
    rpm = HOVER_RPM * np.sqrt(w2)
    z = np.zeros(n)
    p = np.full((n - WINDOW + 1, 4), 0.01)
    return AlertFlight("f", RATE_HZ, WINDOW, p, rpm, rpm.mean(axis=1), z + 0.05, z + 0.1, z + 15.5, np.zeros((n, 3)), (3,), 30.0)


def checkout_copy(tmp_path):
    root = tmp_path / "other"
    shutil.copytree(REPO_ROOT / "monitor", root / "monitor", ignore=shutil.ignore_patterns("__pycache__"))
    (root / "models").mkdir()
    shutil.copy(REPO_ROOT / "models" / "decision-calibration.json", root / "models")
    return root


def test_this_checkout_compared_with_itself_gives_the_same_alerts_and_leaves_the_modules_alone(tmp_path):
    f = onset_flight()
    before = dict(sys.modules)
    ours = decision_rule(DecisionConfig())(f)
    theirs = previous_rule(str(checkout_copy(tmp_path)))(f)
    assert ours and [a[1:3] for a in ours][:2] == [("suspect", (3,)), ("fault", (3,))]
    assert theirs == ours
    assert all(sys.modules.get(name) is mod for name, mod in before.items())


def test_the_other_checkouts_parts_are_the_ones_replayed(tmp_path):
    # The other checkout's config asks for thrust losses of 30 % or more: its rule stays silent on a 10 % loss.
    # Loading its rule with this tree's parts would alert as this tree does.
    root = checkout_copy(tmp_path)
    cfg = root / "monitor" / "decision" / "config.py"
    text = cfg.read_text()
    assert "min_thrust_loss: float = 0.08" in text
    cfg.write_text(text.replace("min_thrust_loss: float = 0.08", "min_thrust_loss: float = 0.3"))
    f = onset_flight()
    assert decision_rule(DecisionConfig())(f)
    assert previous_rule(str(root))(f) == []
