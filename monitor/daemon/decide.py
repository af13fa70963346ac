"""The daemon's decision: one grid step in, decided and handed to the announcer, in one call.

``Decider.step`` is a step's whole way after the pipeline: which evidence and context are live, why the decision
pauses (a stream stopped while airborne, or blind; the pause journal), the judges, STATUS, blindness seen from the
step, then ``monitor.daemon.announce`` (latency, named values, the step's alerts). Blind spells the loop or the
autopilot's clock find come in through ``Decider.transition``; VIBRATION and ESC_STATUS through ``side_evidence``.

Everything that judges the flight sits behind ``DecisionStage.step``, in this order: the rotors' moment balance
(``rotor_evidence``: the effectiveness an alert's event carries), the vehicle's memory (``memory_adapter``: the
flight against the vehicle's own history), the shared rule (``monitor.decision.rule``: regime, omega^2 shares and
the network's windows, worded by ``monitor.decision.hypotheses``' set). The ``Decider`` says beforehand whether the
rule is paused and announces what comes out; nothing else reaches into the judges.

An alert is returned as an ``Alert`` (``monitor.daemon.announce``): the announcement and the fields its event carries
beside it, made when the alert is made (the rotors' baseline freezes then, and the vehicle's memory learns that the
flight raised something).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from monitor.daemon.announce import Alert, Announcer
from monitor.daemon.autopilot import MOTOR_STREAM, Autopilot
from monitor.daemon.blind import BlindTracker, Transition
from monitor.daemon.memory_adapter import VehicleMemory
from monitor.daemon.pipeline import Pipeline, StepResult
from monitor.daemon.rotor_evidence import RecentEffectiveness
from monitor.decision.hypotheses import FlightSets
from monitor.decision.motor_output import MotorOutputWatch, watch_for
from monitor.decision.network_gate import NetworkGate, trained_mean_rpm
from monitor.decision.regime import StepInputs
from monitor.decision.rotor_share import BASELINE_S
from monitor.decision.rule import Announcement, Decision, WindowEvidence
from monitor.decision.stream_evidence import EscTelemetry
from monitor.resample import US_PER_S

log = logging.getLogger("propwatch.monitor")

EVIDENCE_FRESH_S = 2.0  # a VIBRATION / ESC_STATUS stream (or the grid's velocity, IMU) silent for longer is not live
# Context for the decision (the shares' baseline follows it), not evidence of a fault: listed apart in STATUS and events.
CONTEXT = ("velocity", "imu")


@dataclass
class StepOutcome:
    alerts: list[Alert] = field(default_factory=list)
    shares_learning: str = ""  # STATUS: how far the flight's omega^2 shares have learnt their baseline ('' = learnt)
    memory_status: str = ""  # STATUS: the vehicle's memory (its baseline, or how many flights it still needs)


def stage_watches(config, pipeline: Pipeline) -> tuple[MotorOutputWatch | None, NetworkGate]:
    """The stage's watches beside the rule: a stopped or saturated motor, and whether the classifier knows the
    airframe."""
    rate_hz = config.resample.rate_hz
    info = pipeline.classifier.info
    return (
        watch_for(rate_hz, pipeline.esc, config.input.motor_source),
        NetworkGate(trained_mean_rpm(info.metadata, info.features), rate_hz, declared=config.airframe_declared),
    )


class DecisionStage:
    def __init__(
        self,
        decision: Decision,
        flight_sets: FlightSets | None,
        rotors: RecentEffectiveness | None,
        memory: VehicleMemory | None,
        motor_output: MotorOutputWatch | None = None,
        gate: NetworkGate | None = None,
    ):
        self.decision = decision
        self.motor_output = motor_output  # a motor stopped or saturated (commanded RPM only); None: not watched
        self.gate = gate  # whether the classifier knows this airframe (its RPM); None: it always speaks
        self.flight_sets = flight_sets  # the set over the last second's windows words an alert; None without a rule
        self.rotors = rotors  # None without the vehicle's geometry
        self.memory = memory  # None without a state dir
        self.esc_telemetry = EscTelemetry()
        self._airborne = False

    def pause(self, reason: str) -> None:
        """The rule pauses while ``reason`` is set (a stopped stream, blindness) and runs again when it is ''."""
        if reason != self.decision.paused_reason:
            if reason:
                self.decision.pause(reason)
            else:
                self.decision.resume()

    def step(self, step: StepResult, paused: str) -> StepOutcome:
        """One grid step, the rule paused for ``paused`` ('' = running)."""
        out = StepOutcome()
        t = step.timestamp_us / US_PER_S
        inputs = step.inputs
        rpm = inputs.motor_rpm if inputs is not None else None
        if self.rotors is not None:
            self.rotors.push(rpm, step.rates_rad_s, step.valid, airborne=bool(inputs.airborne) if inputs is not None else True)
        if self.memory is not None:
            a = self.memory.step(t, step.airborne, rpm, step.roll_rad, step.pitch_rad)
            if a is not None:
                out.alerts.append(self._raised(a, step.time_boot_ms))
        if self.motor_output is not None and rpm is not None:
            m = self.motor_output.step(t, rpm, step.airborne)
            if m is not None:
                out.alerts.append(self._raised(m.announcement(), step.time_boot_ms))
        if self._airborne and not step.airborne and self.flight_sets:
            self.flight_sets.reset()  # landed: the next flight gets a new set
        self._airborne = step.airborne
        self.decision.step(t, inputs or StepInputs.of_state(step.airborne))
        if self.gate is not None:
            self.gate.step(rpm, step.airborne)
        if step.valid:  # STATUS reads the shares' learning on a deciding step, the memory's on it or on the ground
            out.shares_learning = self._shares_learning()
        if self.memory is not None and (step.valid or not step.airborne):
            out.memory_status = self.memory.status()
        self.pause(paused)
        if not step.valid or step.fault_probability is None:
            return out
        if self.gate is not None and not self.gate.speaks:  # physics alone: the network's window is no evidence
            ev = WindowEvidence(np.full(4, np.nan))
        else:
            hyps = None  # the set is worked out only if an alert words it (RecentSet)
            if self.flight_sets and step.label_probability is not None:
                hyps = self.flight_sets.add_deferred(step.label_probability)
            ev = WindowEvidence(step.fault_probability, step.label_probability, hypotheses=hyps)
        for a in self.decision.window_evidence(t, ev):
            out.alerts.append(self._raised(a, step.time_boot_ms, step))
        return out

    def side_evidence(self, vibration, esc, airborne: bool) -> tuple[list[Alert], dict[str, float]]:
        """VIBRATION and ESC_STATUS samples: the alerts they raise, and {evidence: boot time (s)} of the usable ones
        (invalid samples are counted by their validators, never used)."""
        alerts, fresh = [], {}
        for v in vibration:
            t = v.timestamp_us / US_PER_S
            before = sum(self.decision.vibration.rejected.values())
            for a in self.decision.vibration_sample(t, v.vibration, airborne):
                alerts.append(self._raised(a, int(v.timestamp_us // 1000)))
            if sum(self.decision.vibration.rejected.values()) == before:
                fresh["vibration"] = t
        for e in esc:
            if self.esc_telemetry.observe(e.rpm) == "":
                fresh["esc_rpm"] = e.timestamp_us / US_PER_S
        return alerts, fresh

    def _shares_learning(self) -> str:
        """While the flight's omega^2 shares learn their baseline, nothing they say is tested yet: no FAULT can come
        from them (the first BASELINE_S of evidence windows after each take-off or collective step)."""
        learnt = self.decision.share.learning_s
        return "" if learnt is None else f"; shares learning baseline ({int(learnt)} of {BASELINE_S:.0f} s)"

    def _raised(self, a: Announcement, time_boot_ms: int, step: StepResult | None = None) -> Alert:
        if self.memory is not None:
            self.memory.alert_raised()  # a flight that raised anything never becomes the vehicle's history
        fields: dict = {}
        if step is not None and step.fault_probability is not None:
            fields["probabilities"] = [round(float(p), 4) for p in step.fault_probability]
            fields["battery_v"] = None if math.isnan(step.battery_v) else round(step.battery_v, 2)
        if self.rotors is not None:
            self.rotors.freeze()  # the flight's own baseline ends before the change the alert is about
            fields.update(self.rotors.event_fields())
        return Alert(a, time_boot_ms, fields)


class Decider:
    """One grid step's whole way after the pipeline, in one call (``step``): what is live and why the decision
    pauses (from the step itself; the pause journal), the judges (``DecisionStage``), STATUS, blindness seen from
    the step, then the announcer (latency, named values, the step's alerts). Blind spells from the loop and the
    autopilot's clock come in through ``transition`` and ``loop_blind``; VIBRATION and ESC_STATUS through
    ``side_evidence``."""

    def __init__(self, config, stage: DecisionStage, announce: Announcer, blind: BlindTracker, autopilot: Autopilot):
        self.cfg = config
        self.stage = stage
        self.announce = announce
        self.blind = blind
        self.autopilot = autopilot  # its boot clock dates a blind spell's events line
        self._evidence_t: dict[str, float] = {}  # evidence -> boot time (s) it was last usable
        self._context_t: dict[str, float] = {}  # context (CONTEXT) -> boot time (s) a step last had it
        self._paused = ""  # why the classifier's evidence stopped while airborne ('' = flowing)
        self._airborne = False
        self._bad_steps = False  # an airborne step without usable data was told to the tracker since it last recovered
        self.tick_reason: str | None = None  # the loop's own blindness (link, clock, streams), else None

    def live_evidence(self, t_s: float) -> list[str]:
        """Which evidence is flowing now: classifier (motor stream + attitude), vibration, esc_rpm."""
        return [k for k, last in sorted(self._evidence_t.items()) if t_s - last <= EVIDENCE_FRESH_S]

    def live_context(self, t_s: float) -> list[str]:
        """Which context the grid steps carry now: velocity (LOCAL_POSITION_NED), imu (the specific force). Not
        evidence itself: what the omega^2 shares' baseline follows."""
        return [k for k in CONTEXT if t_s - self._context_t.get(k, -math.inf) <= EVIDENCE_FRESH_S]

    def step(self, step: StepResult) -> None:
        t = step.timestamp_us / US_PER_S
        self._airborne = step.airborne
        if step.valid:
            self._evidence_t["classifier"] = t
        if step.inputs is not None:
            if step.inputs.vel_heading_m_s is not None:
                self._context_t["velocity"] = t
            if step.inputs.accel_xy_frd_m_s2 is not None:
                self._context_t["imu"] = t
        announce = self.announce
        live = announce.live = self.live_evidence(t)
        context = announce.context = self.live_context(t)
        if step.airborne and not step.valid:
            self._paused = step.reason
            # at every such step: one held back by the journal's rate limit is written later
            announce.paused(step.time_boot_ms, step.reason, MOTOR_STREAM[self.cfg.input.motor_source])
        elif step.valid and self._paused:
            self._paused = ""
            announce.resumed(step.time_boot_ms)
        out = self.stage.step(step, self.pause_reason())
        context_status = f"; context live: {', '.join(context)}" if context else ""
        if step.airborne and not step.valid:
            announce.set_status(f"classifier paused: {step.reason}; evidence live: {', '.join(live) or 'none'}{context_status}")
        elif step.valid:
            announce.set_status(
                f"airborne: deciding; evidence live: {', '.join(live)}{context_status}{out.shares_learning}{out.memory_status}"
            )
        elif not self._paused:
            announce.set_status(f"not deciding: {step.reason}{out.memory_status}")
        self._blind_step(step)  # after the step's own pause state, so a recovered line says whether it runs
        if step.valid and step.fault_probability is not None:
            announce.classified(step)
        for a in out.alerts:
            announce.alert(a)

    def side_evidence(self, pipeline: Pipeline) -> None:
        """VIBRATION and ESC_STATUS since the last message: validated (bad ones counted), then used."""
        vib, esc = pipeline.vibration, pipeline.esc_samples
        pipeline.vibration, pipeline.esc_samples = [], []
        alerts, fresh = self.stage.side_evidence(vib, esc, self._airborne)
        self._evidence_t.update(fresh)
        for a in alerts:
            self.announce.alert(a)

    def pause_reason(self) -> str:
        """The decision pauses while a stream is stopped (``_paused``) or the monitor is blind; else it runs ('')."""
        return self._paused if self.blind.reason is None else f"blind: {self.blind.reason}"

    def _blind_step(self, step: StepResult) -> None:
        """Blindness seen from one grid step: bad data while airborne for ``blind.after_s``, or good data again."""
        if step.data_ok:
            # A lost link or frozen clock ends at the next tick that clears it. Nothing to recover from (not blind,
            # no bad step counting towards blind.after_s) is the common step: the tracker is not called then.
            if self.tick_reason is None and (self._bad_steps or self.blind.reason is not None):
                self._bad_steps = False
                self.transition(self.blind.recover())
        elif step.airborne:
            self._bad_steps = True
            self.transition(self.blind.data(False, *_blind_reason(step.reason)))

    def loop_blind(self, found: tuple[str, str] | None) -> None:
        """Blindness seen from the loop (``Autopilot.loop_blindness``): a lost link, a frozen clock, a stream gone."""
        self.tick_reason = None if found is None else found[0]
        if found is not None:
            self.transition(self.blind.enter(*found))

    def transition(self, t: Transition | None) -> None:
        if t is None:
            return
        if t.blind:
            log.warning("BLIND: %s", t.detail)
        else:
            log.info("recovered: %s (blind %.1f s)", t.detail, t.duration_s)
        clock_us = self.autopilot.clock_us
        record = t.record(clock_us // 1000 if clock_us is not None else None)
        self.stage.pause(self.pause_reason())  # blind: the decision adds nothing; recovered: it runs unless a stream is stopped
        record["decision"] = "paused" if self.stage.decision.paused_reason else "running"
        self.announce.transition(record)


def _blind_reason(step_reason: str) -> tuple[str, str]:
    """(short reason, detail) of an airborne step without usable data."""
    if "implausible" in step_reason:
        return ("implausible attitude" if step_reason.startswith("attitude") else "implausible motor data"), step_reason
    if step_reason.startswith("attitude") and "motor" not in step_reason:
        return "no attitude data", step_reason
    return "no motor data", step_reason
