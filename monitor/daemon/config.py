"""The monitor's settings: one frozen dataclass tree, read from YAML by ``monitor.config``.

Every key has a default, so an empty file is a valid config; unknown keys are
rejected by name. ``deploy/monitor.yaml`` lists them all with their meaning.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from monitor.config import from_mapping, load_dataclass
from monitor.decision import DecisionConfig
from monitor.errors import ConfigError
from monitor.vehicle import REPO_ROOT

MOTOR_SOURCES = ("servo", "actuator", "esc")
ALERT_RULES = ("sequential", "consecutive")
LANDED_STATE_MODES = ("auto", "required", "ignore")


def _check(cond: bool, key: str, msg: str) -> None:
    if not cond:
        raise ConfigError(f"{key}: {msg}")


@dataclass(frozen=True)
class LinkConfig:
    system_id: int = 0  # autopilot system id; 0 = from its first HEARTBEAT
    autopilot_component_id: int = 1  # MAV_COMP_ID_AUTOPILOT1
    component_id: int = 191  # ours: MAV_COMP_ID_ONBOARD_COMPUTER
    heartbeat_rate_hz: float = 1.0  # MAVLink microservice convention
    request_streams: bool = True  # MAV_CMD_SET_MESSAGE_INTERVAL; the only command we ever send
    stream_rate_hz: float = 25.0  # >= the 20 Hz grid, so every grid instant has a fresh sample
    request_retry_s: float = 5.0  # re-request while a stream is below its rate (PX4 may have rebooted)
    rate_check_period_s: float = 5.0
    min_rate_fraction: float = 0.8  # warn below this share of the 20 Hz grid rate
    link_timeout_s: float = 3.0  # no autopilot HEARTBEAT for this long = link lost
    tlog_speed: float = 1.0  # .tlog input: 1 = recorded pace, 0 = as fast as it reads

    def __post_init__(self) -> None:
        _check(0 <= self.system_id <= 255, "link.system_id", "must be 0..255")
        _check(1 <= self.component_id <= 255, "link.component_id", "must be 1..255")
        _check(self.heartbeat_rate_hz > 0, "link.heartbeat_rate_hz", "must be > 0")
        _check(self.stream_rate_hz >= 20.0, "link.stream_rate_hz", "must be >= 20 (the classifier's grid)")
        _check(0 < self.min_rate_fraction <= 1, "link.min_rate_fraction", "must be in (0, 1]")
        _check(self.rate_check_period_s > 0 and self.link_timeout_s > 0, "link", "periods must be > 0")
        _check(self.tlog_speed >= 0, "link.tlog_speed", "must be >= 0")


@dataclass(frozen=True)
class InputConfig:
    motor_source: str = "servo"  # servo (SERVO_OUTPUT_RAW) | actuator (ACTUATOR_OUTPUT_STATUS) | esc (ESC_STATUS rpm)
    # Output channel (1-based servo/actuator output, or ESC number) driving PX4 rotor 1, 2, 3, 4.
    motor_outputs: tuple[int, int, int, int] = (1, 2, 3, 4)
    battery_id: int = 0
    landed_state: str = "auto"  # auto: use EXTENDED_SYS_STATE once the autopilot sends it; required; ignore

    def __post_init__(self) -> None:
        _check(self.motor_source in MOTOR_SOURCES, "input.motor_source", f"must be one of {MOTOR_SOURCES}")
        _check(all(1 <= c <= 32 for c in self.motor_outputs), "input.motor_outputs", "channels are 1..32")
        _check(len(set(self.motor_outputs)) == 4, "input.motor_outputs", "must name four different outputs")
        _check(self.landed_state in LANDED_STATE_MODES, "input.landed_state", f"must be one of {LANDED_STATE_MODES}")


@dataclass(frozen=True)
class ResampleConfig:
    rate_hz: float = 20.0  # the model's grid; checked against its metadata
    max_gap_s: float = 0.25  # a fast stream older than this is a gap: the buffer empties
    state_max_age_s: float = 3.0  # HEARTBEAT / EXTENDED_SYS_STATE (1 Hz class streams)
    battery_max_age_s: float = 5.0
    reorder_s: float = 0.0  # extra wait for reordering within one stream (PX4 sends each in order)

    def __post_init__(self) -> None:
        _check(self.rate_hz > 0, "resample.rate_hz", "must be > 0")
        _check(self.max_gap_s >= 1.0 / self.rate_hz, "resample.max_gap_s", "must be at least one grid period")
        _check(self.state_max_age_s > 0 and self.battery_max_age_s > 0, "resample", "ages must be > 0")
        _check(self.reorder_s >= 0, "resample.reorder_s", "must be >= 0")


@dataclass(frozen=True)
class InferenceConfig:
    window: int = 100  # steps; checked against the model's metadata
    every_k_steps: int = 1
    threads: int = 1

    def __post_init__(self) -> None:
        _check(self.window > 0, "inference.window", "must be > 0")
        _check(self.every_k_steps >= 1, "inference.every_k_steps", "must be >= 1")
        _check(self.threads >= 1, "inference.threads", "must be >= 1")


@dataclass(frozen=True)
class AlertConfig:
    # sequential: monitor.decision (CUSUM; thresholds from the false-alarm rates below), shared with diagnose.
    # consecutive: the older rule below (threshold x consecutive windows), kept for comparison.
    rule: str = "sequential"
    false_alarms_per_hour: float = 0.1  # fault level (WARNING / CRITICAL)
    suspect_false_alarms_per_hour: float = 2.0  # suspect level (NOTICE)
    aggressive_tilt_deg: float = 45.0  # windows holding a manoeuvre beyond this add no evidence
    aggressive_rate_deg_s: float = 200.0
    collective_step_fraction: float = 0.12  # payload drop / pick-up: 5-s median RPM change that discounts evidence
    battery_sag_fraction: float = 0.04  # voltage lost within one window that discounts evidence
    min_thrust_loss: float = 0.05  # the omega^2-share evidence is tuned to this per-rotor thrust loss
    calibration_path: str = ""  # '' = models/decision-calibration.json (threshold calibration of the model)
    # Consecutive rule. Threshold and run length chosen on the shipped classifier (bc948c1) over simulated flights on random
    # routes: 8 healthy x 80 s (0.165 flight-hours) and 8 single-propeller faults (bent/cracked, each rotor).
    # 0.8 x 3 windows: 60.7 false alarms per flight-hour; 0.9 x 20 windows (1 s): none, every fault named
    # right, first alert 5.9 s into the flight (5 s of window + 1 s). Tighten further per airframe.
    threshold: float = 0.9  # P(propeller faulty) at or above this counts
    consecutive: int = 20  # windows in a row (20 = 1 s at 20 Hz) before an alert
    refractory_s: float = 30.0  # per propeller, on time.monotonic()
    critical_threshold: float = 0.95  # STATUSTEXT severity CRITICAL at or above, WARNING below
    statustext_min_interval_s: float = 5.0  # rate limit of STATUSTEXT to the GCS
    named_value_float: bool = False  # send each probability as NAMED_VALUE_FLOAT PWF1..PWF4

    def __post_init__(self) -> None:
        _check(self.rule in ALERT_RULES, "alerts.rule", f"must be one of {ALERT_RULES}")
        self.decision()  # bounds of the sequential rule's keys, named alerts.*
        _check(0 < self.threshold <= 1, "alerts.threshold", "must be in (0, 1]")
        _check(self.threshold <= self.critical_threshold <= 1, "alerts.critical_threshold", "must be in [threshold, 1]")
        _check(self.consecutive >= 1, "alerts.consecutive", "must be >= 1")
        _check(self.refractory_s >= 0 and self.statustext_min_interval_s >= 0, "alerts", "intervals must be >= 0")

    def decision(self) -> DecisionConfig:
        return DecisionConfig(
            false_alarms_per_hour=self.false_alarms_per_hour,
            suspect_false_alarms_per_hour=self.suspect_false_alarms_per_hour,
            aggressive_tilt_deg=self.aggressive_tilt_deg,
            aggressive_rate_deg_s=self.aggressive_rate_deg_s,
            collective_step_fraction=self.collective_step_fraction,
            battery_sag_fraction=self.battery_sag_fraction,
            min_thrust_loss=self.min_thrust_loss,
            calibration_path=self.calibration_path,
        )


@dataclass(frozen=True)
class MonitorConfig:
    model_path: str = str(REPO_ROOT / "models" / "classifier.onnx")
    vehicle_path: str = ""  # optional vehicle YAML whose ESC curve overrides the model's
    events_path: str = ""  # JSON lines, one per alert ('' = none; --events overrides)
    link: LinkConfig = field(default_factory=LinkConfig)
    input: InputConfig = field(default_factory=InputConfig)
    resample: ResampleConfig = field(default_factory=ResampleConfig)
    inference: InferenceConfig = field(default_factory=InferenceConfig)
    alerts: AlertConfig = field(default_factory=AlertConfig)


def load_monitor_config(path: str | Path | None) -> MonitorConfig:
    if path is None:
        return MonitorConfig()
    cfg, _ = load_dataclass(MonitorConfig, path)
    return cfg


def monitor_config_from_mapping(data: dict) -> MonitorConfig:
    return from_mapping(MonitorConfig, data)[0]
