"""The shared decision rule replayed over a log, as the ``decision`` object of ``diagnose --json``.

One body for both ways ``diagnose`` feeds the rule: with the classifier's windows (``engine.replay_decision``) and
with physics alone, every window's network evidence NaN (``physics_first.physics_replay``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from monitor.decision.config import DecisionConfig
from monitor.decision.replay import FlightSteps, replay
from monitor.decision.rule import Decision, WindowEvidence
from monitor.decision.thresholds import file_sha256
from monitor.flight import FlightTable
from monitor.resample import US_PER_S


def replay_record(
    table: FlightTable, model_path, window: int, evidence: Mapping[int, WindowEvidence], cfg: DecisionConfig | None = None
) -> dict:
    """``{"alerts", "final"[, "in_flight_fault"]}``: the rule's announcements over the log (boot-clock times), its
    state at the end, and, where it reached fault level, the first and last fault and the sets it named last."""
    cfg = cfg or DecisionConfig()
    dec = Decision(cfg, table.rate_hz, window, model_sha256=file_sha256(model_path) if model_path else None)
    t_s = np.asarray(table.timestamp_us) / US_PER_S
    fault = None  # the last window at fault level: {"t_boot_s", "hypothesis_sets"} (a landing later resets the levels)

    def after_window(j: int, t: float) -> None:
        nonlocal fault
        if "fault" in dec.level or dec.pair_level == "fault":
            sets = [list(s) for s in dec.hypothesis_sets("fault") if s]
            if sets:
                fault = {"t_boot_s": round(t, 2), "hypothesis_sets": sets}

    alerts = [
        {
            "t_boot_s": round(a.t_s, 2),
            "level": a.level,
            "propellers": list(a.propellers),
            "text": a.text,
            "hypothesis_sets": [list(s) for s in a.sets],
        }
        for a in replay(dec, FlightSteps.of_table(table), t_s, evidence, after_window)
    ]
    out = {"alerts": alerts, "final": dec.verdict()}
    first = next((a for a in alerts if a["level"] == "fault"), None)
    if fault is not None and first is not None:
        out["in_flight_fault"] = {
            "first_fault_boot_s": first["t_boot_s"],
            "last_fault_boot_s": fault["t_boot_s"],
            "hypothesis_sets": fault["hypothesis_sets"],
        }
    return out
