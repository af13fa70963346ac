"""Diagnosis of one flight table: windows -> classifier -> verdict, timeline, warnings.

The features and windows are the daemon's (``monitor.features``,
``monitor.model``); what is added here is the choice of windows (only ones
lying wholly inside an airborne segment, with every value measured), the
aggregation into a verdict, and the checks that the log fits the model:
missing signals, rates, and whether the vehicle flies inside the model's
envelope (its mean RPM against the RPM the model was trained on).

Verdict: the label with the highest mean probability over the windows used;
``faulty_propellers`` are that label's propellers; ``fault_probability[i]``
is the mean over windows of the model's P(propeller i faulty). With a
conformal rule beside the model (``monitor.decision.hypotheses``), the verdict is the
most probable set of the rule's score, and ``fault_probability[i]`` is that
same score's marginal (the summed probability of every set holding propeller i),
so the verdict and its probabilities never disagree; the network's own mean
stays in ``network_fault_probability``.

Confidence, in words (``verdict.confidence``): ``confident`` when that label's
mean probability reaches ``DecisionConfig.faulty_probability`` (0.9); else
``suspect`` when at least half the windows agree on it, else ``uncertain``.
Only a confident verdict marks propellers FAULTY (``propellers[].faulty``); a
suspect one marks them ``suspect``. ``label_probability_of_verdict`` and
``agreeing_windows`` (the share of windows whose most likely label is the
verdict's) say how sure it is. The in-flight decision is the daemon's own rule
(``monitor.decision``), replayed over the log step by step: ``decision`` holds
its suspect / fault announcements and final state. Where it reached fault level
(and the log is like its calibration flights), the verdict is its answer and the
moment balance reads the windows after the change against the flight's own start
(``apply_in_flight_fault``, ``after_change_physics``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from monitor.decision.config import DecisionConfig
from monitor.decision.effectiveness import PRE_CHANGE_MARGIN_S
from monitor.decision.hypotheses import SetRule, flight_score, hypothesis_set, load_rule
from monitor.decision.network_gate import (
    RPM_FEATURES,
    RPM_RATIO_REFUSE,
    RPM_RATIO_WARN,
    RPM_Z_REFUSE,
    RPM_Z_WARN,
    UNDECLARED_START,
)
from monitor.decision.rule import WindowEvidence
from monitor.diagnose.physics import SET_PRIOR, PhysicsEvidence, own_baseline, physics_evidence
from monitor.diagnose.physics_first import (
    motor_output_alarms,
    network_alone,
    physics_replay,
    physics_verdict,
    propellers_for,
)
from monitor.diagnose.replayed import replay_record
from monitor.diagnose.shares import ShareEvidence, has_outputs, share_evidence
from monitor.errors import ModelError
from monitor.esc import EscCurve
from monitor.features import compute_features, signals_needed, sliding_windows, valid_windows
from monitor.flight import FlightTable
from monitor.labels import LABEL_TABLE, fault_probability_from_label_probs, label_for
from monitor.logs import RawFlight, read_raw, to_flight_table
from monitor.logs.guards import DEFAULT_MAX_SECONDS, check_size, check_time_advances
from monitor.model import Classifier
from monitor.resample import US_PER_S
from monitor.resources import shipped

DEFAULT_MODEL = shipped("classifier.onnx")
# Windows per classifier call. onnxruntime's outputs for a window change in their last bits with the window's place
# in its call unless every call holds a multiple of 4 windows: then they equal those of one call of them all (bit for
# bit at 4, 8, 12, 16, 32, 64, 100 and 4096 windows a call; not at 1-3, 5-7, 9-11, 13-15, 17). Smaller calls keep the
# runtime's buffers small: on a 30-min log (1794 windows at the 1 s hop) the network stage of `python -m
# bench.bench_diagnose --model models/classifier.onnx --stages` took 0.66 s of CPU in one call, 0.46 s in calls of 32
# (the difference mostly page faults; 16-128 a call within 0.02 s of each other).
PREDICT_BATCH_WINDOWS = 32


def default_model(vehicle_yaml: str | None) -> Path:
    """The classifier shipped for a vehicle: ``models/NAME-classifier.onnx`` beside ``NAME.yaml``.

    A vehicle with its own shipped model (the Crazyflie) gets it without
    ``--model``; any other vehicle gets the paper quad's classifier, whose
    envelope checks then say whether the log fits it.
    """
    if vehicle_yaml:
        own = shipped(f"{Path(vehicle_yaml).stem}-classifier.onnx")
        if own.is_file():
            return own
    return DEFAULT_MODEL


# The paper's flights are gentle; beyond this attitude the model has not been trained.
LARGE_ATTITUDE_RAD = np.deg2rad(45.0)
# Of the airborne time: beyond it, a warning (and no in-flight verdict). Chosen, not measured; no healthy flight of
# our simulator passes 45 deg (`python -m bench.decision_constants`: largest fraction 0).
LARGE_ATTITUDE_MAX_FRACTION = 0.01
QUADROTOR = "MAV_TYPE_QUADROTOR"  # the one vehicle type the models are for (pymavlink's MAV_TYPE name)


@dataclass
class Diagnosis:
    source: str
    verdict: dict | None  # {"label", "faulty_propellers", "fault_probability"} or None
    windows: int
    warnings: list[str]
    reason: str | None = None  # why there is no verdict
    propellers: list[dict] = field(default_factory=list)
    label_probability: list[float] | None = None
    segments: list[dict] = field(default_factory=list)
    timeline: dict = field(default_factory=dict)
    hop_steps: int = 1
    envelope: dict = field(default_factory=dict)  # the figures behind the envelope checks
    decision: dict | None = None  # the shared in-flight rule replayed: {"alerts": [...], "final": {...}}
    physics: PhysicsEvidence | None = None  # rotor effectiveness and the sets the moment balance allows
    hypotheses: list[dict] | None = None  # the model's conformal set (monitor.decision.hypotheses), when it has a rule
    hypothesis_rule: dict | None = None  # that rule: score, threshold, coverage, calibration flights
    physics_basis: str | None = None  # which windows the physics evidence read, when not the whole flight's
    shares: ShareEvidence | None = None  # the flight's own balance from its rotors' shares (no network, no airframe file)
    network: dict = field(default_factory=dict)  # {"used": bool, "why_not": str | None}: whether the classifier spoke

    def to_json(self) -> dict:
        """The ``--json`` object (every key documented in docs/diagnose-json.md).

        One numbering everywhere: propellers, labels and probability columns are in PX4
        rotor order; each propeller's ``name`` is the vehicle's own (``FlightTable.motor_names``,
        e.g. CrazyPAD's M3 for PX4 rotor 2) and stands beside its PX4 number.
        """
        return {
            "log": self.source,
            "verdict": self.verdict,
            "windows": self.windows,
            "warnings": list(self.warnings),
            "reason": self.reason,
            "propellers": self.propellers,
            "label_probability": self.label_probability,
            "airborne_segments": self.segments,
            "timeline": self.timeline,
            "hop_steps": self.hop_steps,
            "envelope": self.envelope,
            "decision": self.decision,
            "hypotheses": self.hypotheses if self.hypotheses is not None else (self.physics.hypotheses if self.physics else None),
            "hypothesis_rule": self.hypothesis_rule,
            "rotor_effectiveness": self.physics.rotor_effectiveness if self.physics else None,
            "rotor_effectiveness_std": self.physics.rotor_effectiveness_std if self.physics else None,
            **({"rotor_effectiveness_basis": self.physics_basis} if self.physics_basis else {}),
            "shares": self.shares.to_json() if self.shares is not None else None,
            "network": self.network or None,
        }


def rotor_name(name: str, px4_rotor: int) -> str:
    """A rotor as people should read it: the vehicle's name with the PX4 number beside it."""
    return f"propeller {px4_rotor}" if name == str(px4_rotor) else f"{name} (PX4 rotor {px4_rotor})"


def describe_label(label: int, names, confidence: str = "confident") -> str:
    """``label 3: M3 (PX4 rotor 2) faulty``; labels are PX4 rotor sets (monitor.labels).

    Only a ``confident`` verdict calls propellers faulty: a ``suspect`` or ``uncertain`` one says so
    instead (``label 3: M3 (PX4 rotor 2) suspect``).
    """
    faulty = LABEL_TABLE[label]
    if not faulty:
        return f"label {label}: no faulty propeller" + ("" if confidence == "confident" else f" ({confidence})")
    if all(names[i - 1] == str(i) for i in faulty):  # the vehicle numbers its rotors as PX4 does
        what = ("propeller " if len(faulty) == 1 else "propellers ") + ", ".join(map(str, faulty))
    else:
        what = ", ".join(rotor_name(names[i - 1], i) for i in faulty)
    return f"label {label}: {what} {'faulty' if confidence == 'confident' else confidence}"


def round_floats(obj, digits: int = 6):
    """``obj`` with every float rounded (JSON readers get 239.7, not 239.70000000000002)."""
    if isinstance(obj, float):
        return round(obj, digits)
    if isinstance(obj, dict):
        return {k: round_floats(v, digits) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [round_floats(v, digits) for v in obj]
    return obj


def window_ends(table: FlightTable, feats: np.ndarray, window: int, hop: int) -> np.ndarray:
    """Indices of the last step of each usable window: all airborne, all finite."""
    wins = sliding_windows(feats, window, hop)
    if len(wins) == 0:
        return np.empty(0, dtype=np.int64)
    ends = np.arange(len(wins)) * hop + window - 1
    air = np.concatenate([[0], np.cumsum(table.airborne.astype(np.int64))])
    all_air = air[ends + 1] - air[ends + 1 - window] == window
    return ends[all_air & valid_windows(wins)]


def _t_s(table: FlightTable, i) -> np.ndarray:
    """Seconds on the autopilot's boot clock (the times its own tools show)."""
    return np.asarray(table.timestamp_us)[i] / US_PER_S


def large_attitude_fraction(table: FlightTable) -> float:
    """The share of airborne steps with roll or pitch beyond ``LARGE_ATTITUDE_RAD`` (an unknown angle reads level)."""
    air = table.airborne
    tilt = np.maximum(np.abs(table.roll_rad[air]), np.abs(table.pitch_rad[air]))
    return float(np.mean(np.nan_to_num(tilt) > LARGE_ATTITUDE_RAD))


def log_refusal(table: FlightTable) -> str | None:
    """Why this log gets no verdict at all (None: it gets one): not a quad-X, never airborne, or no motor outputs in
    flight. Everything else is judged, by physics at least (an unknown tilt reads as level: ``monitor.memory``)."""
    vehicle_type = table.extras.get("vehicle_type", "")
    if vehicle_type and not vehicle_type.startswith(QUADROTOR + " "):
        return f"not a quad-X multicopter: the log says {vehicle_type}; propwatch knows four rotors in PX4 quad-X order"
    air = table.airborne
    if not air.any():
        return "no airborne flight found (armed, throttle above idle, off the ground)"
    if not has_outputs(table):
        return "motor outputs unknown during flight: the shares of the four rotors need them"
    return None


def envelope_checks(
    table: FlightTable, clf: Classifier, esc: EscCurve | None = None, figures: dict | None = None
) -> tuple[list[str], str | None]:
    """(warnings, why the classifier is silent on this log or None) -- ``figures`` gets the numbers.

    The classifier speaks only on the airframe it was trained on: same command unit, every signal it reads, and the
    airborne RPM inside its training envelope's warning bounds. (The response to differential thrust does not tell
    airframes apart at 20 Hz: on the model's own airframe in our simulator it spans x0.04-0.60 of the file's,
    `python -m bench.airframe_response`.)"""
    warnings: list[str] = []
    figures = {} if figures is None else figures
    unit = table.extras.get("esc_cmd_unit", table.extras.get("motor_cmd_unit"))  # the unit the ESCs received
    if esc is not None and unit is not None and unit != esc.cmd_unit:
        from monitor.resources import display_path
        from monitor.vehicle import vehicles_for_cmd_unit

        fits = [f"--vehicle {display_path(p)}" for p in vehicles_for_cmd_unit(unit)]
        return warnings, (
            f"vehicle outside the model's envelope: its motor commands are in '{unit}' but the model's "
            f"ESC curve takes '{esc.cmd_unit}' (another class of vehicle); use a model trained for it"
            + (f": try {' or '.join(fits)}" if fits else "")
        )
    air = table.airborne
    sig = table.signals()
    for f in clf.info.features:
        for name in signals_needed(f):
            if not np.isfinite(sig[name][air]).any():
                what = (
                    "motor RPM (commands not logged or in another unit than the model's ESC curve)"
                    if name == "motor_rpm"
                    else name
                )
                return warnings, f"{what} unknown during flight: the model needs it for feature {f}"
    warn, refusal = rpm_envelope(table, clf, figures)
    if refusal or warn:
        return warnings, refusal or warn.split(": the verdict is")[0]
    big = large_attitude_fraction(table)
    figures["large_attitude_fraction"] = round(big, 4)
    if big > LARGE_ATTITUDE_MAX_FRACTION:
        warnings.append(
            f"{100 * big:.1f} % of the airborne time has roll or pitch beyond 45 deg "
            "(aggressive flight, flip or crash): outside the model's training"
        )
    return warnings, None


def rpm_envelope(table: FlightTable, clf: Classifier, figures: dict) -> tuple[str | None, str | None]:
    """(warning, refusal) from the airborne RPM features against the model's training statistics."""
    norm = clf.info.metadata.get("normalization", {})
    idx = [i for i, f in enumerate(clf.info.features) if f in RPM_FEATURES]
    if not idx or "mean" not in norm or "std" not in norm:
        return None, None
    names = [clf.info.features[i] for i in idx]
    feats = compute_features(table.signals(), names)[table.airborne].astype(np.float64)
    feats = feats[np.isfinite(feats).all(axis=1)]
    if len(feats) == 0:
        return None, None
    mean = np.array([norm["mean"][i] for i in idx])
    std = np.array([norm["std"][i] for i in idx])
    z = float(np.max(np.median(np.abs(feats - mean) / std, axis=0)))
    flown, trained = float(np.median(feats.mean(axis=1))), float(mean.mean())
    ratio = flown / trained if trained > 0 else float("inf")
    figures.update(
        airborne_mean_rpm=round(flown, 1), trained_mean_rpm=round(trained, 1), rpm_ratio=round(ratio, 4), rpm_z=round(z, 3)
    )
    msg = (
        f"vehicle outside the model's envelope: median airborne RPM {flown:.0f} vs {trained:.0f} in the model's "
        f"training data (x{ratio:.2f}; a rotor's typical RPM is {z:.1f} training std away)"
    )
    if z > RPM_Z_REFUSE or not RPM_RATIO_REFUSE[0] <= ratio <= RPM_RATIO_REFUSE[1]:
        return None, msg
    if z > RPM_Z_WARN or not RPM_RATIO_WARN[0] <= ratio <= RPM_RATIO_WARN[1]:
        return msg + ": the verdict is an extrapolation", None
    return None, None


def diagnose_table(
    table: FlightTable,
    clf: Classifier,
    hop: int = 1,
    batch: int = PREDICT_BATCH_WINDOWS,
    esc: EscCurve | None = None,
    vehicle=None,
    airframe_declared: bool = True,
) -> Diagnosis:
    """Classify every usable window of ``table`` (one every ``hop`` steps) and aggregate.

    ``esc``: the curve the table's RPM came from, to refuse a log of another vehicle class.
    ``vehicle``: its geometry, inertia and kF/kτ give the moment-balance evidence (``physics``).
    ``airframe_declared``: whoever asks says the log is of ``vehicle``'s airframe (``--vehicle``); where not, the
    network is silent (``undeclared``) and physics judges alone.
    """
    if hop < 1:
        raise ValueError("hop must be >= 1")
    info = clf.info
    if abs(table.rate_hz - info.sample_rate_hz) > 1e-9:
        raise ModelError(f"{table.source}: table at {table.rate_hz} Hz but the model expects {info.sample_rate_hz} Hz")
    warnings = list(table.warnings)
    figures: dict = {}
    refusal = log_refusal(table)
    segs = [
        {
            "start_boot_s": float(_t_s(table, a)),
            "stop_boot_s": float(_t_s(table, b - 1)) + 1.0 / table.rate_hz,
            "steps": int(b - a),
        }
        for a, b in table.airborne_segments()
    ]
    d = Diagnosis(table.source, None, 0, warnings, refusal, segments=segs, hop_steps=hop, envelope=figures)
    if refusal:
        return d
    d.shares = share_evidence(table)
    alarms = motor_output_alarms(table, esc)
    env_warn, silent = envelope_checks(table, clf, esc, figures)
    warnings += env_warn
    feats = compute_features(table.signals(), info.features) if silent is None else None
    ends = window_ends(table, feats, info.window, hop) if silent is None else np.empty(0, dtype=np.int64)
    if silent is None and len(ends) == 0:
        longest = max((s["steps"] for s in segs), default=0)
        silent = (
            f"no usable window: {info.window} consecutive airborne steps with every signal measured are needed "
            f"({info.window / table.rate_hz:g} s); longest airborne segment has {longest} steps"
        )
    physics_why_not = None
    rule = load_rule(clf.path)
    if silent is None and not airframe_declared:
        silent = undeclared(clf)
    if silent is None and vehicle is not None:
        d.physics, physics_why_not = physics_evidence(table, vehicle, window=info.window)
        silent = balance_unlike_model(d.physics, rule)
    d.network = {"used": silent is None, "why_not": silent}
    if silent is not None:
        physics_only(d, table, clf, info.window, hop, alarms)
        return d
    labels, faults = predict_at(clf, feats, ends, info.window, batch)
    mean_labels = labels.mean(axis=0)
    label = int(np.argmax(mean_labels)) + 1
    p = faults.mean(axis=0)
    d.windows = len(ends)
    cfg = DecisionConfig()
    network_p = None
    if rule is not None:
        label, scores = apply_rule(d, rule, mean_labels)
        network_p, p = p, fault_probability_from_label_probs(scores)
        agree = float(np.mean(np.argmax(labels, axis=1) + 1 == label))
        confidence = "confident" if len(d.hypotheses) == 1 else "ambiguous"
    else:
        confidence, agree = verdict_confidence(labels, label, cfg)
    d.verdict = {
        "label": label,
        "faulty_propellers": list(LABEL_TABLE[label]),
        "faulty_names": [table.motor_names[i - 1] for i in LABEL_TABLE[label]],
        "fault_probability": [float(x) for x in p],
        "confidence": confidence,
        "label_probability_of_verdict": round(float(mean_labels[label - 1]), 4),
        "agreeing_windows": round(agree, 4),
        "faulty_probability_required": cfg.faulty_probability,
    }
    if network_p is not None:
        d.verdict["network_fault_probability"] = [float(x) for x in network_p]
    d.label_probability = [float(x) for x in mean_labels]
    d.propellers = [
        {
            "propeller": i + 1,
            "px4_rotor": i + 1,
            "name": table.motor_names[i],
            "fault_probability": float(p[i]),
            "faulty": (i + 1) in LABEL_TABLE[label] and confidence == "confident",
            "suspect": (i + 1) in LABEL_TABLE[label] and confidence in ("suspect", "ambiguous"),
        }
        for i in range(4)
    ]
    d.decision = replay_decision(table, clf, cfg, ends, labels, faults)
    d.timeline = {
        "t_boot_s": [float(x) for x in _t_s(table, ends)],
        "fault_probability": np.round(faults, 5).tolist(),
        "label": (np.argmax(labels, axis=1) + 1).tolist(),
    }
    apply_in_flight_fault(d, table.motor_names, in_flight_unfit(table, d.envelope))
    if d.verdict.get("source") == "in-flight change":
        if vehicle is not None:
            after_change_physics(d, table, vehicle, info.window)
        weigh_in_flight_sets(d, table.motor_names)
    elif physics_why_not:
        d.warnings.append(physics_why_not)
    network_as_note(d, table)
    first_flight_confidence(d, table)
    apply_motor_output(d, table, alarms)
    return d


def first_flight_confidence(d: Diagnosis, table: FlightTable) -> None:
    """A whole-flight verdict (no in-flight change, no stopped motor, no history) is confident only where the shares
    name its one rotor beyond what healthy airframes show (``shares.STANDOUT_SHARE``). Without history a CG offset or
    a motor spread hides a propeller damaged before take-off, or mimics one (the CG-vs-damage ceiling, measured in
    ``python -m bench.first_flight``: on our simulator's register airframes the damaged rotor's share was the highest
    on half the flights at 6-15 % loss), whatever the network and the vehicle file's balance say. Otherwise a
    propeller answer keeps its sets, not sure (``ambiguous`` with a conformal rule, else ``suspect``), and a healthy
    answer becomes physics' first-flight verdict ("no damage seen"), what the network said kept in
    ``verdict.network``. (CrazyPAD, no history: 27 confident verdicts wrong at 84adda2, 14 of them "healthy" on a cut
    propeller; `python -m bench.crazypad_first_flight`.)"""
    v = d.verdict
    if v is None or v.get("source"):
        return
    named = list(v["faulty_propellers"])
    if named:
        if v.get("confidence") == "confident" and not (
            len(named) == 1 and d.shares is not None and d.shares.named_rotor == named[0]
        ):
            name_verdict(d, v["label"], "ambiguous" if d.hypothesis_rule is not None else "suspect", table.motor_names)
        return
    if not physics_in_place_of_network(d, table, v.get("fault_probability")):
        v["confidence"] = "uncertain"


def physics_in_place_of_network(d: Diagnosis, table: FlightTable, probabilities) -> bool:
    """Replace the network's whole-flight verdict by physics' first-flight verdict, what the network said kept in
    ``verdict.network`` and its probabilities (``probabilities`` per propeller) beside it; False where the shares
    cannot judge the flight (the network's verdict then stays)."""
    v = d.verdict
    pv, ph, _ = physics_verdict(table, d.shares, None, [], [])
    if pv is None:
        return False
    pv["network"] = {k: v[k] for k in ("label", "faulty_propellers", "confidence") if k in v}
    pv["fault_probability"] = v.get("fault_probability")
    if v.get("network_fault_probability"):
        pv["network_fault_probability"] = v["network_fault_probability"]
    d.verdict, d.hypotheses = pv, ph
    d.propellers = propellers_for(pv["label"], pv["confidence"], table.motor_names)
    for prop, q in zip(d.propellers, probabilities or []):
        prop["fault_probability"] = float(q)
    return True


def undeclared(clf: Classifier) -> str:
    """Why the network is silent on a log whose airframe nobody declared. Nothing in one flight tells the network's
    airframe from another quad-X: their RPM overlaps (strangers hover at x0.64-1.32 of the nominal RPM, our own
    randomised flights at x0.87-1.18), the response to differential thrust spans x0.04-0.60 on the network's own
    airframe (`python -m bench.airframe_response`), and the balance of forces fits a damaged nominal airframe to a
    healthy stranger (`python -m bench.strangers --set strangers_healthy`: the network spoke on 35 of 100 healthy
    flights of other airframes and 27 of those read "inspect")."""
    from monitor.resources import display_path
    from monitor.vehicle import vehicle_of_model

    own = vehicle_of_model(clf.path)
    return (
        UNDECLARED_START
        + " and nothing declares this log's to be it"
        + (f": if it is, try --vehicle {display_path(own)}" if own is not None else "")
    )


def balance_unlike_model(physics: PhysicsEvidence | None, rule: SetRule | None) -> str | None:
    """Why the model's airframe is not this one, from the flight's response: the balance of forces (its moments
    against the vehicle file's mass, inertia and geometry) favours an unmeasured airframe over the file's by more
    than the model's rule allows (``airframe_log_bayes_factor_max``: at most 2 % of its calibration flights of the
    model's own airframe exceed it). None: the balance does not say so (or there is no balance or rule)."""
    if physics is None or rule is None or rule.airframe_log_bayes_factor_max is None:
        return None
    bf = physics.airframe_log_bayes_factor
    if bf is None or bf <= rule.airframe_log_bayes_factor_max:
        return None
    return (
        f"its balance of forces does not fit the model's airframe (log Bayes factor {bf:.1f} for an unmeasured "
        f"airframe, beyond {rule.airframe_log_bayes_factor_max:.1f}): another airframe, or this one far from its file "
        "(a CG offset, a motor spread; `propwatch adapt` on its healthy flights calibrates it)"
    )


def physics_only(d: Diagnosis, table: FlightTable, clf: Classifier, window: int, hop: int, alarms: list) -> None:
    """The verdict where the classifier is silent (``d.network.why_not``): physics alone
    (``monitor.diagnose.physics_first``), and a warning that says so. The balance of forces against the vehicle
    file's mass and inertia is not this airframe's, so it is dropped."""
    d.physics = None
    d.decision = physics_replay(table, clf.path, window, hop)
    big = large_attitude_fraction(table)
    d.envelope["large_attitude_fraction"] = round(big, 4)
    unfit = [f"{100 * big:.1f} % of the airborne time beyond 45 deg"] if big > LARGE_ATTITUDE_MAX_FRACTION else []
    d.verdict, d.hypotheses, reason = physics_verdict(table, d.shares, d.decision, alarms, unfit)
    why = d.network["why_not"]
    d.warnings.append(
        f"physics only: {why}"
        if why.startswith(UNDECLARED_START)
        else f"physics only: this airframe is not the one the network was trained on ({why})"
    )
    if unfit and (d.decision or {}).get("in_flight_fault"):
        d.warnings.append(unfit_warning(d, d.decision["in_flight_fault"], unfit))
    if d.verdict is None:
        d.reason = reason
        return
    d.propellers = propellers_for(d.verdict["label"], d.verdict["confidence"], table.motor_names)


def unfit_warning(d: Diagnosis, change: dict, unfit: list[str]) -> str:
    """The in-flight rule's fault on a log it does not fit (``unfit``: why), as the evidence line and the JSON tell
    it: seconds after take-off, and the sets of that first fault alert."""
    first = next((a for a in d.decision.get("alerts") or [] if a["level"] == "fault"), None)
    sets = first["hypothesis_sets"] if first else change["hypothesis_sets"]
    takeoff_s = d.segments[0]["start_boot_s"] if d.segments else 0.0
    return (
        f"the in-flight rule reached fault level at {change['first_fault_boot_s'] - takeoff_s:.0f} s after take-off "
        f"({' or '.join('+'.join(map(str, s)) for s in sets)}) but this log is not like the "
        f"flights its thresholds were calibrated on ({'; '.join(unfit)}): the verdict stays the whole flight's"
    )


def network_as_note(d: Diagnosis, table: FlightTable) -> None:
    """Where the network alone names the verdict's propellers (physics names none of them: ``network_alone``), the
    verdict is physics' and the network's answer a note."""
    v = d.verdict
    if v is None or v.get("source"):
        return
    hyps = d.hypotheses if d.hypotheses is not None else (d.physics.hypotheses if d.physics else None)
    physics_sets = [tuple(h["faulty_propellers"]) for h in d.physics.hypotheses] if d.physics is not None else None
    p = v.get("network_fault_probability") or v.get("fault_probability")
    if not network_alone(v, hyps, d.shares, physics_sets):
        return
    named = sorted({i for h in (hyps or [{"faulty_propellers": v["faulty_propellers"]}]) for i in h["faulty_propellers"]})
    if not physics_in_place_of_network(d, table, p):
        return
    names = "+".join(table.motor_names[i - 1] for i in named)
    why = "the balance of forces calls the flight healthy" if physics_sets else "physics names none of them"
    d.warnings.append(f"the fault classifier alone points at {names} ({why}): a note, not a propeller to inspect")


def apply_motor_output(d: Diagnosis, table: FlightTable, alarms: list) -> None:
    """A stopped or saturated motor is the verdict whatever the propellers show (a motor or ESC failure)."""
    if not alarms or d.verdict is None:
        return
    pv, ph, _ = physics_verdict(table, d.shares, None, alarms, [])
    pv["before"] = {k: d.verdict[k] for k in ("label", "faulty_propellers", "confidence") if k in d.verdict}
    d.verdict, d.hypotheses = pv, ph
    d.propellers = propellers_for(pv["label"], pv["confidence"], table.motor_names)


def weigh_in_flight_sets(d: Diagnosis, motor_names) -> None:
    """Each of the in-flight rule's candidate sets weighed by the moment balance after the change.

    The rule ranks its sets without weighing them; the balance of the windows after the change, against the
    flight's own start (``after_change_physics``), gives each set its marginal likelihood: with the balance's set
    prior, renormalised over the rule's sets, that is each set's probability given that one of them holds (the
    rule decided that the flight changed, the balance which of its sets explains the change best). Without a
    usable balance the sets share the probability equally (physics says nothing between them). The most probable
    set is the verdict: on 80 + 80 onset logs that raised exact sets 78.8 -> 80.0 % on ours and 87.5 -> 93.8 % on
    evalsim against the rule's own order (pairs 70 -> 72.5 %, 79.2 -> 89.6 %; singles unchanged)."""
    sets = [h["faulty_propellers"] for h in d.hypotheses]
    k = np.array([label_for(s) - 1 for s in sets])
    if d.physics is not None and d.physics.log_likelihood and d.physics_basis:
        lp = np.asarray(d.physics.log_likelihood, dtype=np.float64)[k] + np.log(SET_PRIOR[k])
        w = np.exp(lp - lp.max())
        basis = "in-flight change, weighed by the moment balance after it"
    else:
        w = np.ones(len(sets))
        basis = "in-flight change (no usable balance after it: equal weights)"
    w = w / w.sum()
    order = np.argsort(-w, kind="stable")  # most probable first; ties keep the rule's order
    d.hypotheses = [{"faulty_propellers": list(sets[i]), "probability": round(float(w[i]), 4), "evidence": basis} for i in order]
    name_verdict(d, label_for(d.hypotheses[0]["faulty_propellers"]), d.verdict["confidence"], motor_names)


def after_change_physics(d: Diagnosis, table: FlightTable, vehicle, window: int) -> None:
    """The moment balance of the windows after the in-flight change, against the flight's own balance before it.

    The balance fits one effectiveness per rotor: over a flight whose propeller changed mid-way it fits neither
    half (on evalsim's onset flights its most probable set was all four rotors, read at 2-60 % of nominal). After
    the change, with the airframe's trim, CG and motor spread at this operating point taken from the windows before
    it (``own_baseline``), it reads what the damage took."""
    change_s = float(d.verdict["change_boot_s"])
    first_s = min([a["t_boot_s"] for a in d.decision["alerts"]] + [change_s])
    base = own_baseline(table, vehicle, first_s - PRE_CHANGE_MARGIN_S, window)
    d.physics, why_not = physics_evidence(table, vehicle, baseline=base, window=window, between_boot_s=(change_s, np.inf))
    against = f"against the flight's own balance before {first_s - PRE_CHANGE_MARGIN_S:.1f} s" if base else "nominal airframe"
    d.physics_basis = f"windows after the in-flight change at {change_s:.1f} s, {against}"
    if why_not:
        d.physics_basis = None
        d.warnings.append(f"after the in-flight change: {why_not}")


def in_flight_unfit(table: FlightTable, figures: dict) -> list[str]:
    """Why the in-flight rule's answer should not be the verdict on this log (empty: it may be).

    The rule's thresholds hold a false-alarm rate on flights like its calibration flights: streams at the
    grid's rate or faster, RPM inside the model's training envelope, gentle attitudes. A log outside that
    (another vehicle's 10 Hz DataFlash, a flip) keeps the whole-flight verdict; the rule's alerts stay listed."""
    why = []
    rates = table.extras.get("stream_rates_hz") or {}
    slow = [f"{n} at {r:.1f} Hz" for n, r in rates.items() if 0 < r < 0.9 * table.rate_hz]
    if slow:
        why.append(f"streams logged below the {table.rate_hz:g} Hz grid ({', '.join(slow)})")
    z, ratio = figures.get("rpm_z"), figures.get("rpm_ratio")
    if (z is not None and z > RPM_Z_WARN) or (ratio is not None and not RPM_RATIO_WARN[0] <= ratio <= RPM_RATIO_WARN[1]):
        why.append("RPM outside the model's training envelope")
    if figures.get("large_attitude_fraction", 0.0) > LARGE_ATTITUDE_MAX_FRACTION:
        why.append(f"more than {100 * LARGE_ATTITUDE_MAX_FRACTION:g} % of the airborne time beyond 45 deg")
    return why


def apply_rule(d: Diagnosis, rule: SetRule, mean_labels: np.ndarray) -> tuple[int, np.ndarray]:
    """Set ``d.hypotheses`` from the model's conformal rule; the label of the most probable set and the (16,)
    score of every set (label order).

    The score fuses the moment balance only where the log gave one (``d.physics``); otherwise the classifier's
    probabilities alone are scored against the same threshold, and ``hypothesis_rule.score`` says so."""
    ll = np.asarray(d.physics.log_likelihood) if d.physics is not None and d.physics.log_likelihood else None
    score = rule.score if ll is not None else "classifier"
    threshold = rule.threshold_for(score)
    if threshold is None:  # an older rule file without the classifier's own threshold
        score, threshold = rule.score, rule.threshold
    bf = d.physics.airframe_log_bayes_factor if d.physics is not None else None
    airframe = "as its file says"  # an airframe the balance says is not the file's never reaches here (balance_unlike_model)
    scores = flight_score(mean_labels, ll, score, rule.sparsity_prior, rule.classifier_weight)
    d.hypotheses = hypothesis_set(scores, threshold)
    d.hypothesis_rule = {
        "score": score,
        "threshold": threshold,
        "sparsity_prior": rule.sparsity_prior,
        "classifier_weight": rule.classifier_weight,
        "airframe": airframe,
        "airframe_log_bayes_factor": bf,
        "airframe_log_bayes_factor_max": rule.airframe_log_bayes_factor_max,
        "coverage": rule.coverage,
        "calibration_flights": rule.calibration_flights,
    }
    return label_for(d.hypotheses[0]["faulty_propellers"]), scores


def verdict_confidence(labels: np.ndarray, label: int, cfg: DecisionConfig) -> tuple[str, float]:
    """('confident' | 'suspect' | 'uncertain', share of windows whose most likely label is ``label``)."""
    agree = float(np.mean(np.argmax(labels, axis=1) + 1 == label))
    if labels[:, label - 1].mean() >= cfg.faulty_probability:
        return "confident", agree
    return ("suspect" if agree >= 0.5 else "uncertain"), agree


def replay_decision(
    table: FlightTable, clf: Classifier, cfg: DecisionConfig, ends: np.ndarray, labels: np.ndarray, faults: np.ndarray
) -> dict:
    """The daemon's decision rule over the log, step by step, with the windows classified at ``ends``
    (``monitor.decision.replay``: the same replay as every offline evaluation)."""
    evidence = {int(e): WindowEvidence(faults[k], labels[k]) for k, e in enumerate(ends)}
    return replay_record(table, clf.path, clf.info.window, evidence, cfg)


def name_verdict(d: Diagnosis, label: int, confidence: str, motor_names) -> None:
    """Point ``d.verdict`` and ``d.propellers`` at ``label`` with ``confidence``: its propellers and names, the whole
    flight's probability of that label and the share of windows agreeing with it, FAULTY only when confident."""
    v = d.verdict
    v.update(
        label=label,
        faulty_propellers=list(LABEL_TABLE[label]),
        faulty_names=[motor_names[i - 1] for i in LABEL_TABLE[label]],
        confidence=confidence,
    )
    if d.label_probability is not None:
        v["label_probability_of_verdict"] = round(float(d.label_probability[label - 1]), 4)
    window_labels = d.timeline.get("label") or []
    if window_labels:
        v["agreeing_windows"] = round(sum(int(x) == label for x in window_labels) / len(window_labels), 4)
    for p in d.propellers:
        bad = p["propeller"] in LABEL_TABLE[label]
        p["faulty"], p["suspect"] = bad and confidence == "confident", bad and confidence != "confident"


def apply_in_flight_fault(d: Diagnosis, motor_names, unfit: list[str] = ()) -> None:
    """Where the in-flight rule raised a fault, the verdict is its answer, not the whole flight's.

    The whole-flight verdict weighs every window alike: a propeller damaged half-way through a flight is
    outvoted by the healthy half before it, and on an airframe unlike its vehicle file the flight's static
    imbalance looks like damage wherever it is. The in-flight rule tests the flight against its own first
    10 s of evidence (``monitor.decision``: a change, calibrated to a false-alarm rate on healthy flights of
    both simulators), so where it reached fault level its sets stand: the verdict is its most likely set,
    ``hypotheses`` its candidate sets (weighed by the balance after the change, ``weigh_in_flight_sets``), ``confident``
    only when it names one set. The whole-flight verdict and its hypotheses stay in ``verdict.whole_flight``
    (``hypothesis_rule`` is the rule that made those); ``fault_probability`` and ``label_probability`` stay the
    whole flight's.
    A flight faulty from take-off shows no change and keeps the whole-flight verdict; so does a log the rule
    does not fit (``unfit``: why, from ``in_flight_unfit``), with a warning."""
    change = (d.decision or {}).get("in_flight_fault")
    if d.verdict is None or not change:
        return
    if unfit:
        d.warnings.append(unfit_warning(d, change, unfit))
        return
    sets = change["hypothesis_sets"]
    v = d.verdict
    v["whole_flight"] = {
        "label": v["label"],
        "faulty_propellers": v["faulty_propellers"],
        "confidence": v["confidence"],
        # as ``to_json`` gives them: the conformal set, else the moment balance's credible set
        "hypotheses": d.hypotheses if d.hypotheses is not None else (d.physics.hypotheses if d.physics else None),
    }
    v.update(source="in-flight change", change_boot_s=change["first_fault_boot_s"])
    name_verdict(d, label_for(sets[0]), "confident" if len(sets) == 1 else "ambiguous", motor_names)
    d.hypotheses = [{"faulty_propellers": list(s), "evidence": "in-flight change"} for s in sets]


def predict_at(clf: Classifier, feats: np.ndarray, ends: np.ndarray, window: int, batch: int):
    """Classifier outputs for the windows ending at ``ends``, ``batch`` windows per call (to bound memory). Any
    multiple of 4 gives the outputs of one call of them all (``PREDICT_BATCH_WINDOWS``); 1, the daemon's."""
    starts = ends - window + 1
    out_l, out_f = [], []
    for i in range(0, len(ends), batch):
        idx = starts[i : i + batch, None] + np.arange(window)[None, :]
        lab, fau = clf.predict(feats[idx])
        out_l.append(lab)
        out_f.append(fau)
    return np.concatenate(out_l).astype(np.float64), np.concatenate(out_f).astype(np.float64)


def read_guarded(path: str | Path, fmt: str | None, max_seconds: float = DEFAULT_MAX_SECONDS) -> RawFlight:
    """``read_raw`` between the guards of ``monitor.logs.guards``: the file's size before reading, then that
    the streams the diagnosis reads advance in time within ``max_seconds``. Raises ``LogFormatError``."""
    check_size(path, max_seconds)
    raw = read_raw(path, fmt, extras=False)
    streams = {k: getattr(raw, k) for k in ("motor_cmd", "attitude_rad", "rates_rad_s")}
    check_time_advances(streams, path, max_seconds)
    return raw


def diagnose_raw(
    raw: RawFlight, clf: Classifier, esc: EscCurve | None, hop: int, vehicle=None, airframe_declared: bool = True
) -> tuple[FlightTable, Diagnosis]:
    """A log read by ``read_guarded`` -> (its flight table on the model's grid, its ``Diagnosis``)."""
    table = to_flight_table(raw, esc=esc, rate_hz=clf.info.sample_rate_hz)
    return table, diagnose_table(table, clf, hop=hop, esc=esc, vehicle=vehicle, airframe_declared=airframe_declared)


def diagnose_file(
    path: str | Path,
    clf: Classifier,
    esc: EscCurve | None,
    fmt: str | None,
    hop: int,
    vehicle=None,
    max_seconds: float = DEFAULT_MAX_SECONDS,
    airframe_declared: bool = True,
) -> tuple[FlightTable, Diagnosis]:
    """One log file -> (flight table, ``Diagnosis``): the one path from a log to its verdict, shared by
    ``propwatch diagnose``, ``fleet ingest`` (``fleet.worker``) and offline evaluation."""
    return diagnose_raw(read_guarded(path, fmt, max_seconds), clf, esc, hop, vehicle, airframe_declared)
