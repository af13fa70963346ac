"""The streaming core: MAVLink messages in, per-step fault probabilities out.

    msg -> MavlinkDecoder -> StreamingHold (20 Hz boot-clock grid)
        -> features (monitor.features, as in training) -> 100-step ring -> Classifier

Public API (also used by ``propwatch diagnose``'s parity test):

    p = Pipeline(classifier, config, esc_curve)
    for msg in messages:
        for step in p.feed(msg):      # StepResult per grid instant made final
            ...
    tail = p.flush()                  # end of a log: emit the remaining instants

A step is classified only when it ends a window of ``window`` consecutive
steps that are all airborne (armed, and IN_AIR when the landed state is used)
and all finite. Anything else (a gap, NaN, disarm, reboot) empties the ring:
no window ever spans invented or missing data. The first classification comes
at the first full window, then every ``every_k_steps``.

LOCAL_POSITION_NED's horizontal velocity is held on the same grid (stale after
``resample.max_gap_s``, like the fast streams it is sampled beside) and turned
into the heading frame with the step's own yaw: ``StepInputs.vel_heading_m_s``,
None where it is missing, stale or implausible. It is optional context for the
decision, never a reason for a step to be invalid.

The accelerometer's horizontal specific force (body x, y; FRD) is context the
same way: ``StepInputs.accel_xy_frd_m_s2`` is the mean of the IMU samples in
the step's own period ``(g - period, g]`` (a 50-250 Hz stream that vibrates:
one sample held would be noise), stale after ``resample.max_gap_s``. The
source is HIGHRES_IMU; SCALED_IMU stands in only while no HIGHRES_IMU came
within ``max_gap_s`` of it, so the two never mix in one period.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.daemon.clockguard import GuardedDecoder
from monitor.daemon.config import MonitorConfig
from monitor.daemon.pacing import ReadPacer
from monitor.daemon.plausible import Plausibility
from monitor.daemon.resampler import GridStep, StreamingHold, StreamSpec
from monitor.decision.regime import StepInputs, heading_velocity
from monitor.esc import EscCurve
from monitor.features import step_feature_function
from monitor.mavlink import decode as md
from monitor.model import Classifier
from monitor.resample import US_PER_S, period_us


@dataclass(frozen=True)
class StepResult:
    timestamp_us: int
    airborne: bool
    valid: bool  # airborne and every feature finite
    buffered: int  # consecutive valid steps in the ring (capped at the window)
    battery_v: float
    fault_probability: np.ndarray | None = None  # (4,) when classified at this step
    label_probability: np.ndarray | None = None  # (16,)
    latency_s: float | None = None  # from the message that completed the step to its classification
    reason: str = ""  # why an invalid step is invalid
    data_ok: bool = True  # attitude and motor data present and plausible (airborne or not)
    inputs: StepInputs | None = None  # flight state for the decision's regime tracker
    rates_rad_s: np.ndarray | None = None  # (3,) body rates FRD of this step (valid steps), for the moment balance
    roll_rad: float = math.nan  # attitude of this step, for the vehicle memory's tilt regime
    pitch_rad: float = math.nan

    @property
    def time_boot_ms(self) -> int:
        return self.timestamp_us // 1000


def _us(seconds: float) -> int:
    return int(round(seconds * US_PER_S))


# A boot clock that goes back by more than this is a discontinuity (the hold restarts); beyond
# REBOOT_BACK_US, or landing below REBOOT_BOOT_US, it is read as an autopilot reboot.
CLOCK_BACK_US = 1_000_000
REBOOT_BACK_US = 10_000_000
REBOOT_BOOT_US = 30_000_000
NAN6 = (math.nan,) * 6
NAN2 = (math.nan,) * 2
PACING_STREAMS = ("attitude", "motor")  # the hold's fast streams: a step is final once both passed it


class Pipeline:
    def __init__(self, classifier: Classifier, config: MonitorConfig, esc: EscCurve):
        self.classifier = classifier
        self.config = config
        self.esc = esc
        r, inf = config.resample, config.inference
        classifier.check_compatible(classifier.info.features, r.rate_hz, inf.window)
        self.features = classifier.info.features
        self._compute_features = step_feature_function(self.features)  # = feature_function on one step, bit for bit
        self._feats = np.empty(len(self.features), dtype=np.float32)  # this step's row, reused
        self.window = inf.window
        self.decoder = GuardedDecoder(  # boot clock moved only by a plausible sequence (monitor.daemon.clockguard)
            system_id=config.link.system_id or None,
            component_id=config.link.autopilot_component_id,
            battery_id=config.input.battery_id,
            reboot_jump_us=CLOCK_BACK_US,
        )
        self.plausible = Plausibility(config.plausible, esc, config.input.motor_source)
        self.clock_events: deque[str] = deque(maxlen=8)  # "autopilot rebooted ..." for the service to report
        fast, state = _us(r.max_gap_s), _us(r.state_max_age_s)
        self.hold = StreamingHold(
            period_us(r.rate_hz),
            {
                "attitude": StreamSpec(6, fast, True),
                "motor": StreamSpec(4, fast, True),
                "armed": StreamSpec(1, state, False),
                "landed": StreamSpec(1, state, False),
                "battery": StreamSpec(1, _us(r.battery_max_age_s), False),
                # (north, east) m/s: optional context, so it neither paces nor moves the grid (steps as without it)
                "velocity": StreamSpec(2, fast, False, moves_clock=False),
                # (x, y) FRD m/s^2: context as velocity, averaged over each step's period
                "imu": StreamSpec(2, fast, False, moves_clock=False, mean_us=period_us(r.rate_hz)),
            },
            reorder_us=_us(r.reorder_s),
        )
        self.pacer = ReadPacer(PACING_STREAMS)  # when the next step can complete, for the loop's sleep
        self._channels = np.asarray(config.input.motor_outputs, dtype=np.int64)
        self._layouts: dict[tuple[int, int], np.ndarray | bool] = {}  # (first channel, count) -> indices, False = unmapped
        self._source = {"servo": "SERVO_OUTPUT_RAW", "actuator": "ACTUATOR_OUTPUT_STATUS"}.get(config.input.motor_source)
        self.seen_landed = config.input.landed_state == "required"
        self.stats = {
            "steps": 0,
            "valid_steps": 0,
            "classified": 0,
            "resets": 0,
            "skipped_steps": 0,
            "clock_resets": 0,
            "motor_msgs_unmapped": 0,
            "clock_steps_back": 0,
            "implausible_samples": 0,
            "velocity_steps": 0,  # grid steps with a heading-frame velocity
            "velocity_late": 0,  # LOCAL_POSITION_NED at or before an instant already emitted (dropped)
            "imu_steps": 0,  # grid steps with a horizontal specific force
            "imu_late": 0,  # IMU samples at or before an instant already emitted (dropped)
            "clock_jumps": 0,  # confirmed forward jumps of the boot clock (the grid restarted)
        }
        self._max_gap_us = fast
        self._highres_us: int | None = None  # boot time of the latest HIGHRES_IMU (SCALED_IMU is used without one)
        self._period_us = period_us(r.rate_hz)
        # Boot times of implausible samples: the grid step whose period holds one is invalid even when
        # the sample falls between two instants (a 50 Hz stream on the 20 Hz grid), so no window spans it.
        self._bad_times: deque[int] = deque(maxlen=256)
        # Ring of features, stored twice so any window is one contiguous slice.
        self._ring = np.zeros((2 * self.window, len(self.features)), dtype=np.float32)
        self._head = 0
        self._count = 0
        self._since_inference = 0
        # VIBRATION and ESC_STATUS samples since the caller last took them (the decision validates them).
        self.vibration: list[md.Vibration] = []
        self.esc_samples: list[md.EscRpm] = []
        # Shown each message once decoded, when the decoder knows the autopilot's ids and clock: the daemon's
        # autopilot bookkeeping (monitor.daemon.autopilot.Autopilot.watch), set by the daemon; None outside it.
        self.watch: Callable[[Any], None] | None = None

    # -- input -----------------------------------------------------------------------
    def feed(self, msg: Any, received_s: float | None = None) -> list[StepResult]:
        """Decode one pymavlink message; return the steps it made final (maybe classified)."""
        received_s = time.perf_counter() if received_s is None else received_s
        out: list[StepResult] = []
        for sample in self.decoder.decode(msg):
            out += self.feed_sample(sample, received_s)
        if self.watch is not None:
            self.watch(msg)
        return out

    def feed_sample(self, s: md.Sample, received_s: float) -> list[StepResult]:
        if isinstance(s, md.ClockReset):
            back_us = s.previous_us - s.timestamp_us
            if back_us < 0:  # a confirmed forward jump (GuardedDecoder): the grid starts again, no empty catch-up
                self.stats["clock_jumps"] += 1
                self.clock_events.append(f"autopilot clock jumped {-back_us / US_PER_S:+.1f} s")
            elif back_us > REBOOT_BACK_US or s.timestamp_us < REBOOT_BOOT_US:
                self.stats["clock_resets"] += 1
                self.clock_events.append(
                    f"autopilot rebooted (boot clock {s.previous_us / US_PER_S:.1f} -> {s.timestamp_us / US_PER_S:.1f} s)"
                )
            else:
                self.stats["clock_steps_back"] += 1
                self.clock_events.append(f"autopilot clock stepped back {back_us / US_PER_S:.1f} s")
            self.reset()
            return []
        if s.timestamp_us is None:
            return []  # before the boot clock is known: nothing to place it on
        if isinstance(s, md.Attitude):
            vals = (s.roll_rad, s.pitch_rad, s.yaw_rad, s.roll_rate_rad_s, s.pitch_rate_rad_s, s.yaw_rate_rad_s)
            if self.plausible.attitude(s.timestamp_us, vals) is not None:
                self.stats["implausible_samples"] += 1
                self._bad_times.append(s.timestamp_us)
                vals = NAN6  # never evidence: the instants it would hold become a gap
            return self._push("attitude", s.timestamp_us, vals, received_s)
        if isinstance(s, md.ActuatorOutputs) and s.source == self._source:
            cmd = self._map(s.first_channel, s.values_us)
            return [] if cmd is None else self._push_motor(s.timestamp_us, cmd, True, received_s)
        if isinstance(s, md.Vibration):
            self.vibration.append(s)
            return []
        if isinstance(s, md.EscRpm) and self.config.input.motor_source != "esc":
            self.esc_samples.append(s)  # telemetry beside the commanded RPM: evidence, not the motor stream
            return []
        if isinstance(s, md.EscRpm) and self.config.input.motor_source == "esc":
            rpm = self._map(s.first_index + 1, s.rpm)
            return [] if rpm is None else self._push_motor(s.timestamp_us, rpm, False, received_s)
        if isinstance(s, md.LocalVelocity):
            return self._push_velocity(s.timestamp_us, s.vel_ned_m_s, received_s)
        if isinstance(s, md.ImuAccel):
            return self._push_imu(s, received_s)
        if isinstance(s, md.Heartbeat):
            return self._push("armed", s.timestamp_us, (1.0 if s.armed else 0.0,), received_s)
        if isinstance(s, md.LandedState):
            if self.config.input.landed_state != "ignore":
                self.seen_landed = True
            return self._push("landed", s.timestamp_us, (float(s.landed_state),), received_s)
        if isinstance(s, md.Battery):
            v = s.voltage_v if self.plausible.battery(s.timestamp_us, s.voltage_v) else math.nan
            return self._push("battery", s.timestamp_us, (v,), received_s)
        return []

    def _push_motor(self, t_us: int, values: np.ndarray, is_cmd: bool, received_s: float) -> list[StepResult]:
        if self.plausible.motor(t_us, values) is not None:
            self.stats["implausible_samples"] += 1
            self._bad_times.append(t_us)
            return self._push("motor", t_us, np.full(4, np.nan), received_s)
        return self._push("motor", t_us, self.esc.cmd_to_rpm(values) if is_cmd else values, received_s)

    def _push_velocity(self, t_us: int, vel_ned_m_s: tuple[float, float, float], received_s: float) -> list[StepResult]:
        # An unusable velocity only makes the instants it would hold unknown (NaN); the step stays valid.
        vel = NAN2 if self.plausible.velocity(t_us, vel_ned_m_s) is not None else vel_ned_m_s[:2]
        return self._push_context("velocity", t_us, vel, received_s)

    def _push_imu(self, s: md.ImuAccel, received_s: float) -> list[StepResult]:
        t_us = s.timestamp_us
        if s.source == "HIGHRES_IMU":
            self._highres_us = t_us
        elif self._highres_us is not None and t_us - self._highres_us <= self._max_gap_us:
            return []  # SCALED_IMU beside a live HIGHRES_IMU: the coarser copy of the same sensor
        # As velocity: an unusable sample is NaN, left out of its period's mean; the step stays valid.
        acc = NAN2 if self.plausible.imu(t_us, s.accel_frd_m_s2) is not None else s.accel_frd_m_s2[:2]
        return self._push_context("imu", t_us, acc, received_s)

    def _push_context(self, stream: str, t_us: int, values, received_s: float) -> list[StepResult]:
        last = self.hold.last_emitted
        if last is not None and t_us <= last:  # PX4 may stamp it a little behind ATTITUDE: counted apart from `late`
            self.stats[f"{stream}_late"] += 1
            return []
        return self._push(stream, t_us, values, received_s)

    def reset(self) -> None:
        """Drop everything held (grid and ring); decoding state (autopilot, clock) is kept."""
        self.hold.reset()
        self.pacer.reset()
        self.plausible.reset()
        self._highres_us = None
        self._bad_times.clear()
        self._clear()

    def flush(self) -> list[StepResult]:
        return [self._step(g, time.perf_counter()) for g in self.hold.flush()]

    def _map(self, first: int, values: tuple[float, ...]) -> np.ndarray | None:
        key = (first, len(values))  # a handful of layouts per vehicle (ports, ESC index offsets): bounded
        idx = self._layouts.get(key)
        if idx is None:
            idx = self._channels - first
            idx = self._layouts[key] = idx if idx.min() >= 0 and idx.max() < len(values) else False
        if idx is False:
            self.stats["motor_msgs_unmapped"] += 1
            return None
        return np.asarray(values, dtype=np.float64)[idx]

    def _push(self, stream: str, t_us: int, values, received_s: float) -> list[StepResult]:
        steps = [self._step(g, received_s) for g in self.hold.push(stream, t_us, values)]
        if stream in PACING_STREAMS:
            self.pacer.observe(stream, int(t_us), received_s, bool(steps))
        return steps

    def wake_at(self, now_s: float) -> float | None:
        """The earliest time (``received_s``'s clock) a message can complete the next grid step; None when the
        schedule is not known (``monitor.daemon.pacing``)."""
        g = self.hold.next_g
        return None if g is None else self.pacer.wake_at(g + self.hold.reorder_us, now_s)

    # -- one grid step -------------------------------------------------------------------
    def _clear(self) -> None:
        if self._count:
            self.stats["resets"] += 1
        self._count = 0
        self._since_inference = 0

    def _airborne(self, v: dict[str, np.ndarray]) -> bool:
        if not v["armed"][0] == 1.0:  # NaN (stale heartbeat) is not armed
            return False
        if self.seen_landed and self.config.input.landed_state != "ignore":
            return bool(md.is_flying(v["landed"][0])) if math.isfinite(v["landed"][0]) else False
        return True

    def _why(self, v: dict[str, np.ndarray], airborne: bool, t_us: int) -> str:
        if not airborne:
            return "not armed" if v["armed"][0] != 1.0 else "not in the air"
        bad = [k for k in ("attitude", "motor") if not np.isfinite(v[k]).all()] or list(self.plausible.last)
        for k in bad:  # a sample dropped as implausible is the reason, not a mere gap
            last = self.plausible.last.get(k)
            if last is not None and last[0] >= t_us - self._max_gap_us:  # dropped at or after this instant's data
                return f"{k} implausible: {last[1]}"
        return f"{' and '.join(bad) or 'features'} missing, stale or NaN"

    def _step(self, g: GridStep, received_s: float) -> StepResult:
        self.stats["steps"] += 1
        if g.skipped_before:
            self.stats["skipped_steps"] += g.skipped_before
            self._clear()
        v = g.values
        airborne = self._airborne(v)
        att = v["attitude"]
        feats = self._feats
        self._compute_features(v["motor"], att, feats)
        bad = self._bad_times
        while bad and bad[0] <= g.timestamp_us - self._period_us:
            bad.popleft()
        tainted = bool(bad) and bad[0] <= g.timestamp_us
        valid = airborne and not tainted and bool(np.isfinite(feats).all())
        battery_v = float(v["battery"][0])
        motor = v["motor"]
        vel = v["velocity"]
        vel_heading = None
        if math.isfinite(vel[0]) and math.isfinite(vel[1]) and math.isfinite(att[2]):
            vel_heading = heading_velocity(vel, att[2])  # with this step's yaw
            self.stats["velocity_steps"] += 1
        acc = v["imu"]  # a fresh array (the period's mean) or the sample held: the hold never writes into either
        accel_xy = None
        if math.isfinite(acc[0]) and math.isfinite(acc[1]):
            accel_xy = acc
            self.stats["imu_steps"] += 1
        roll, pitch = float(att[0]), float(att[1])
        inputs = StepInputs.of_state(  # .max(): np.max bit for bit, without its wrapper
            airborne,
            motor,
            max(abs(att[0]), abs(att[1])),
            np.abs(att[3:6]).max(),
            battery_v,
            vel_heading_m_s=vel_heading,
            accel_xy_frd_m_s2=accel_xy,
        )
        if not valid:
            self._clear()
            data_ok = not tainted and bool(np.isfinite(att).all() and np.isfinite(v["motor"]).all())
            return StepResult(
                g.timestamp_us,
                airborne,
                False,
                0,
                battery_v,
                reason=self._why(v, airborne, g.timestamp_us),
                data_ok=data_ok,
                inputs=inputs,
                roll_rad=roll,
                pitch_rad=pitch,
            )
        self.stats["valid_steps"] += 1
        w = self.window
        self._ring[self._head] = feats
        self._ring[self._head + w] = feats
        self._head = (self._head + 1) % w
        self._count = min(self._count + 1, w)
        rates = att[3:6]
        if self._count < w:
            return StepResult(
                g.timestamp_us,
                True,
                True,
                self._count,
                battery_v,
                inputs=inputs,
                rates_rad_s=rates,
                roll_rad=roll,
                pitch_rad=pitch,
            )
        self._since_inference -= 1
        if self._since_inference > 0:
            return StepResult(
                g.timestamp_us, True, True, w, battery_v, inputs=inputs, rates_rad_s=rates, roll_rad=roll, pitch_rad=pitch
            )
        self._since_inference = self.config.inference.every_k_steps
        window = self._ring[self._head : self._head + w]  # oldest first
        labels, faults = self.classifier.predict(window[None])
        self.stats["classified"] += 1
        return StepResult(
            g.timestamp_us,
            True,
            True,
            w,
            battery_v,
            faults[0].astype(np.float64),
            labels[0].astype(np.float64),
            time.perf_counter() - received_s,
            inputs=inputs,
            rates_rad_s=rates,
            roll_rad=roll,
            pitch_rad=pitch,
        )
