"""The verdict that needs no network: a motor that stopped, a change in the air, then the first flight's shares.

Every quad-X log with motor outputs and attitude in flight gets one. In order, the first that speaks is the verdict:

1. **motor output** (``monitor.decision.motor_output``): one output pinned at an end of its range while the others
   fly. At the bottom: the motor or its ESC cut out, named as such, never as a propeller. At the top: that corner is
   at its limit (a failing motor, a damaged propeller, or a load off centre towards it), not sure which.
2. **in-flight change**: the shared decision rule (``monitor.decision``) replayed over the log with no network
   evidence; its physics statistics (each rotor's share against the flight's own first seconds, and the yaw
   balance) reached fault level. Its thresholds were calibrated on healthy flights of our simulator to a
   false-alarm rate per flight-hour (``models/decision-calibration.json``); the network's statistics add nothing here.
3. **first flight** (``monitor.diagnose.shares``): one rotor's level share stands above every other's by more than
   healthy airframes show: that rotor is named, as a damaged propeller or this airframe's balance (a first flight
   cannot tell them apart); otherwise "no damage seen", never a confident "healthy".

Where the network knows the airframe its verdict stands, but what it alone names (physics says nothing of it) is a
note, not a propeller to inspect (``network_as_note``).
"""

from __future__ import annotations

import numpy as np

from monitor.decision.config import DecisionConfig
from monitor.decision.motor_output import scan
from monitor.decision.rule import WindowEvidence
from monitor.diagnose.replayed import replay_record
from monitor.diagnose.shares import ShareEvidence
from monitor.flight import FlightTable
from monitor.labels import LABEL_TABLE, label_for
from monitor.resample import US_PER_S

FIRST_FLIGHT = "first flight"
MOTOR_OUTPUT = "motor output"
IN_FLIGHT = "in-flight change"


def boot_s(table: FlightTable) -> np.ndarray:
    return np.asarray(table.timestamp_us) / US_PER_S


def motor_output_alarms(table: FlightTable, esc) -> list:
    """Stopped or saturated motors over the flight (the ESC curve's command range gives the ends), [] without RPM."""
    rpm = np.asarray(table.motor_rpm, dtype=np.float64)
    if esc is None or not np.any(np.isfinite(rpm).all(axis=1) & table.airborne):
        return []
    lo, hi = float(esc.cmd_to_rpm(esc.cmd_min)), float(esc.cmd_to_rpm(esc.cmd_max))
    return scan(boot_s(table), rpm, table.airborne, table.rate_hz, lo, hi)


def airborne_ends(table: FlightTable, window: int, hop: int) -> np.ndarray:
    """Steps ending ``window`` airborne steps, one every ``hop``: where the rule is fed a window (no network)."""
    air = np.concatenate([[0], np.cumsum(np.asarray(table.airborne, dtype=np.int64))])
    ends = np.arange(window - 1, len(table), hop)
    return ends[air[ends + 1] - air[ends + 1 - window] == window]


def physics_replay(table: FlightTable, model_path, window: int, hop: int, cfg: DecisionConfig | None = None) -> dict:
    """The decision rule replayed with physics alone (every window's network evidence NaN): ``decision`` as the
    engine's ``replay_decision`` gives it, with ``network: false``."""
    none = WindowEvidence(np.full(4, np.nan))
    evidence = {int(e): none for e in airborne_ends(table, window, hop)}
    return replay_record(table, model_path, window, evidence, cfg) | {"network": False}


def propellers_for(label: int, confidence: str, names, suspect=()) -> list[dict]:
    bad = LABEL_TABLE[label]
    return [
        {
            "propeller": i + 1,
            "px4_rotor": i + 1,
            "name": names[i],
            "fault_probability": None,
            "faulty": (i + 1) in bad and confidence == "confident",
            "suspect": ((i + 1) in bad and confidence != "confident") or (i + 1) in suspect,
        }
        for i in range(4)
    ]


def physics_verdict(
    table: FlightTable, shares: ShareEvidence | None, decision: dict | None, alarms: list, unfit: list[str]
) -> tuple[dict | None, list[dict] | None, str | None]:
    """(verdict, hypotheses, reason) from physics alone: motor output, then in-flight change, then first flight.

    ``unfit``: why the in-flight rule's answer may not be the verdict on this log (a flip, a crash)."""
    names = table.motor_names
    if alarms:
        a = alarms[0]
        label = label_for([a.rotor])
        v = {
            "label": label,
            "faulty_propellers": [a.rotor],
            "faulty_names": [names[a.rotor - 1]],
            # a motor whose output sat at the bottom while the others flew cut out; one at full is at its limit: a
            # failing motor or ESC, a damaged propeller, or a load off centre towards it (CrazyPAD's weights)
            "confidence": "confident" if a.kind == "stopped" else "ambiguous",
            "source": MOTOR_OUTPUT,
            "motor_output": [x.to_json() for x in alarms],
            "change_boot_s": a.since_s,
        }
        return v, [{"faulty_propellers": [a.rotor], "evidence": f"motor {a.rotor} {a.kind}"}], None
    change = (decision or {}).get("in_flight_fault")
    if change and not unfit:
        sets = change["hypothesis_sets"]
        conf = "confident" if len(sets) == 1 else "ambiguous"
        label = label_for(sets[0])
        v = {
            "label": label,
            "faulty_propellers": list(LABEL_TABLE[label]),
            "faulty_names": [names[i - 1] for i in LABEL_TABLE[label]],
            "confidence": conf,
            "source": IN_FLIGHT,
            "change_boot_s": change["first_fault_boot_s"],
        }
        hyps = [{"faulty_propellers": list(s), "evidence": "in-flight change (shares and yaw balance)"} for s in sets]
        return v, hyps, None
    if shares is None or not shares.judged:
        secs = 0.0 if shares is None else shares.seconds
        return None, None, (f"too little level flight to judge: {secs:.1f} s of airborne outputs past take-off, {5.0:g} s needed")
    k = shares.named_rotor
    label = label_for([k] if k else [])
    v = {
        "label": label,
        "faulty_propellers": list(LABEL_TABLE[label]),
        "faulty_names": [names[i - 1] for i in LABEL_TABLE[label]],
        "confidence": "suspect" if k else "uncertain",
        "source": FIRST_FLIGHT,
    }
    if k:
        hyps = [
            {"faulty_propellers": [k], "cause": f"a damaged propeller {names[k - 1]}"},
            {"faulty_propellers": [], "cause": f"this airframe's balance (a CG or motor towards {names[k - 1]})"},
        ]
    else:
        hyps = [{"faulty_propellers": [], "cause": "no rotor stands out beyond healthy airframes"}]
    return v, hyps, None


def network_alone(verdict: dict, hypotheses, shares: ShareEvidence | None, physics_sets) -> bool:
    """Whether the verdict's propellers rest on the network alone, so that it may only be a note.

    Physics names none of them (the share check names no rotor among them), and either the moment balance calls the
    flight healthy (its most probable set is "no damage": ``physics_sets`` from a balance on the vehicle file's
    airframe) or there is no balance: however sure the network is, its flags alone are a note. Measured on every
    CrazyPAD flight without history (`python -m bench.crazypad_first_flight`, the Crazyflie's own model): where its
    flags at or above its FAULTY level still stood alone, 2 of 20 healthy flights were asked for M3+M4 (0 now);
    propeller-cut flights asked for M3 fell from 91 to 71 of 180 (another propeller 28 -> 9), none confidently wrong
    either way."""
    sets = [tuple(h["faulty_propellers"]) for h in (hypotheses or []) if "faulty_propellers" in h] or [
        tuple(verdict.get("faulty_propellers") or ())
    ]
    named = {i for s in sets for i in s}
    if not named:
        return False
    if shares is not None and shares.named_rotor in named:
        return False
    return not physics_sets[0] if physics_sets else True
