"""The daemon's decision stage: one grid step in, its alerts out, in one call.

Everything that judges the flight sits behind ``DecisionStage.step``, in this order: the rotors' moment balance
(``rotor_evidence``: the effectiveness an alert's event carries), the vehicle's memory (``memory``: the flight against
the vehicle's own history), the shared rule (``monitor.decision.rule``: regime, omega^2 shares and the network's
windows, worded by ``monitor.decision.hypotheses``' set). The service says beforehand whether the rule is paused (a
stream stopped, or blind) and announces what comes out; it never reaches into the judges itself. VIBRATION and
ESC_STATUS samples come in through ``side_evidence`` the same way.

An alert is returned as an ``Alert``: the announcement and the fields its event carries beside it, made when the
alert is made (the rotors' baseline freezes then, and the vehicle's memory learns that the flight raised something).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from monitor.daemon.memory_adapter import VehicleMemory
from monitor.daemon.pipeline import StepResult
from monitor.daemon.rotor_evidence import RecentEffectiveness
from monitor.decision.hypotheses import FlightSets
from monitor.decision.regime import StepInputs
from monitor.decision.rotor_share import BASELINE_S
from monitor.decision.rule import Announcement, Decision, WindowEvidence
from monitor.decision.stream_evidence import EscTelemetry
from monitor.resample import US_PER_S


@dataclass(frozen=True)
class Alert:
    announcement: Announcement
    time_boot_ms: int
    fields: dict  # the event's fields beside the announcement's own (probabilities, battery, rotor effectiveness)


@dataclass
class StepOutcome:
    alerts: list[Alert] = field(default_factory=list)
    shares_learning: str = ""  # STATUS: how far the flight's omega^2 shares have learnt their baseline ('' = learnt)
    memory_status: str = ""  # STATUS: the vehicle's memory (its baseline, or how many flights it still needs)


class DecisionStage:
    def __init__(
        self,
        decision: Decision,
        flight_sets: FlightSets | None,
        rotors: RecentEffectiveness | None,
        memory: VehicleMemory | None,
    ):
        self.decision = decision
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
        if self._airborne and not step.airborne and self.flight_sets:
            self.flight_sets.reset()  # landed: the next flight gets a new set
        self._airborne = step.airborne
        self.decision.step(t, inputs or StepInputs.of_state(step.airborne))
        if step.valid:  # STATUS reads the shares' learning on a deciding step, the memory's on it or on the ground
            out.shares_learning = self._shares_learning()
        if self.memory is not None and (step.valid or not step.airborne):
            out.memory_status = self.memory.status()
        self.pause(paused)
        if not step.valid or step.fault_probability is None:
            return out
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
