"""The monitor's settings: one frozen dataclass tree, read from YAML by ``monitor.config``.

Every key has a default, so an empty file is a valid config; unknown keys are
rejected by name. ``deploy/monitor.yaml`` lists them all with their meaning.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path

from monitor.config import from_mapping, read_yaml
from monitor.decision.config import DecisionConfig
from monitor.decision.envelope import FROZEN_S
from monitor.errors import ConfigError
from monitor.resources import shipped

MOTOR_SOURCES = ("servo", "actuator", "esc")
ALERT_RULES = ("sequential",)
RETIRED_RULE = (
    "alerts.rule: 'consecutive' is no longer an onboard rule; use 'sequential' (the default)"
    " - the consecutive rule lives on as the offline comparison in offline/alerts"
)
RETIRED_ALERT_KEYS = ("threshold", "consecutive", "refractory_s", "critical_threshold")  # the consecutive rule's own
LANDED_STATE_MODES = ("auto", "required", "ignore")


def _check(cond: bool, key: str, msg: str) -> None:
    if not cond:
        raise ConfigError(f"{key}: {msg}")


def _within(value: float, lo: float, hi: float, key: str, lo_open: bool = False) -> None:
    """Every numeric key has finite bounds: a typo such as 1e9 s must not pass as 'never'."""
    ok = (lo < value if lo_open else lo <= value) and value <= hi
    _check(ok, key, f"must be in {'(' if lo_open else '['}{lo:g}, {hi:g}], got {value!r}")


def parse_source(text: str) -> tuple[int | None, int | None]:
    """``"1/1"`` -> (1, 1); ``"1/*"`` -> (1, None): a mavlink-router style SYSID/COMPID filter."""
    parts = str(text).split("/")
    try:
        if len(parts) != 2:
            raise ValueError
        ids = tuple(None if p.strip() == "*" else int(p) for p in parts)
    except ValueError:
        raise ConfigError(f"link.allow_sources: {text!r} is not SYSID/COMPID (e.g. 1/1 or 1/*)") from None
    if any(i is not None and not 0 <= i <= 255 for i in ids):
        raise ConfigError(f"link.allow_sources: {text!r}: ids are 0..255")
    return ids  # type: ignore[return-value]


def parse_address(text: str, key: str = "link.allow_addresses") -> tuple[str, int | None]:
    """``"127.0.0.1"`` -> (host, None) any port; ``"127.0.0.1:14580"`` -> (host, port)."""
    host, _, port = str(text).partition(":")
    if not host:
        raise ConfigError(f"{key}: {text!r} has no host")
    if not port:
        return host, None
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"{key}: {text!r}: port must be 1..65535")
    return host, int(port)


def parse_endpoint(text: str, key: str) -> tuple[str, int]:
    """``"10.0.0.7:14550"`` -> (host, port); both are required."""
    host, port = parse_address(text, key)
    if port is None:
        raise ConfigError(f"{key}: {text!r} must be HOST:PORT")
    return host, port


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
    # MAVLink 2 signing (pymavlink's): a file holding the 32-byte secret key, raw or as 64 hex digits.
    # When set, every incoming frame must carry a valid signature (unsigned and MAVLink 1 frames are
    # refused) and everything we send is signed. '' = off.
    signing_key_path: str = ""
    signing_link_id: int = 1  # our link id in the signature (0..255)
    # Source allow-lists, mavlink-router style; empty = any. Addresses "HOST" or "HOST:PORT" (UDP/TCP
    # peers); sources "SYSID/COMPID" with * for any ("1/1", "1/*"). Anything else is dropped and counted.
    allow_addresses: tuple[str, ...] = ()
    allow_sources: tuple[str, ...] = ()
    max_peers: int = 8  # udpin: distinct sender addresses remembered for the report (replies go only to the autopilot's)
    # The pinned autopilot (monitor.daemon.pin): on udpin its "HOST:PORT" ('' = the one loopback address whose
    # HEARTBEATs pin it first; another candidate is announced and ignored, one on another computer never pins). Its
    # system id is learnt only from its HEARTBEATs on that link (system_id 0), and nothing else ever moves the pin.
    autopilot_address: str = ""
    # "HOST:PORT" that also get our HEARTBEAT, STATUSTEXT and NAMED_VALUE_FLOAT (never a command); nobody else does.
    ground_stations: tuple[str, ...] = ()
    pin_wait_s: float = 2.0  # a candidate autopilot's HEARTBEATs span this long before it is pinned (first heard wins)
    # Autopilots of distinct system ids monitored on the link, each its own vehicle (monitor.daemon.vehicles); one
    # more is announced and ignored. With system_id set, that one alone.
    max_vehicles: int = 4
    # udpin: sleep through the datagrams that cannot complete the next 20 Hz step and read them together
    # (monitor.daemon.pacing): measured 85 -> 55-60 wake-ups/s at 20 Hz; latency still counts from each arrival.
    pace_reads: bool = True

    def __post_init__(self) -> None:
        _check(0 <= self.system_id <= 255, "link.system_id", "must be 0..255")
        _check(0 <= self.autopilot_component_id <= 255, "link.autopilot_component_id", "must be 0..255")
        _check(1 <= self.component_id <= 255, "link.component_id", "must be 1..255")
        _within(self.heartbeat_rate_hz, 0.0, 10.0, "link.heartbeat_rate_hz", lo_open=True)
        _check(self.stream_rate_hz >= 20.0, "link.stream_rate_hz", "must be >= 20 (the classifier's grid)")
        _within(self.stream_rate_hz, 20.0, 1000.0, "link.stream_rate_hz")
        _within(self.request_retry_s, 0.1, 3600.0, "link.request_retry_s")
        _within(self.rate_check_period_s, 0.0, 3600.0, "link.rate_check_period_s", lo_open=True)
        _within(self.min_rate_fraction, 0.0, 1.0, "link.min_rate_fraction", lo_open=True)
        _within(self.link_timeout_s, 0.0, 3600.0, "link.link_timeout_s", lo_open=True)
        _within(self.tlog_speed, 0.0, 1000.0, "link.tlog_speed")
        _check(0 <= self.signing_link_id <= 255, "link.signing_link_id", "must be 0..255")
        _within(self.max_peers, 1, 1024, "link.max_peers")
        _within(self.max_vehicles, 1, 16, "link.max_vehicles")
        for a in self.allow_addresses:
            parse_address(a)
        for s in self.allow_sources:
            parse_source(s)
        _within(self.pin_wait_s, 0.0, 60.0, "link.pin_wait_s")
        if self.autopilot_address:
            parse_endpoint(self.autopilot_address, "link.autopilot_address")
        for g in self.ground_stations:
            parse_endpoint(g, "link.ground_stations")


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
        _check(0 <= self.battery_id <= 255, "input.battery_id", "must be 0..255 (BATTERY_STATUS.id)")
        _check(self.landed_state in LANDED_STATE_MODES, "input.landed_state", f"must be one of {LANDED_STATE_MODES}")


@dataclass(frozen=True)
class ResampleConfig:
    rate_hz: float = 20.0  # the model's grid; checked against its metadata
    max_gap_s: float = 0.25  # a fast stream older than this is a gap: the buffer empties
    state_max_age_s: float = 3.0  # HEARTBEAT / EXTENDED_SYS_STATE (1 Hz class streams)
    battery_max_age_s: float = 5.0
    reorder_s: float = 0.0  # extra wait for reordering within one stream (PX4 sends each in order)

    def __post_init__(self) -> None:
        _within(self.rate_hz, 0.0, 1000.0, "resample.rate_hz", lo_open=True)
        _check(self.max_gap_s >= 1.0 / self.rate_hz, "resample.max_gap_s", "must be at least one grid period")
        _within(self.max_gap_s, 0.0, 10.0, "resample.max_gap_s")
        _within(self.state_max_age_s, 0.0, 60.0, "resample.state_max_age_s", lo_open=True)
        _within(self.battery_max_age_s, 0.0, 600.0, "resample.battery_max_age_s", lo_open=True)
        _within(self.reorder_s, 0.0, 1.0, "resample.reorder_s")


@dataclass(frozen=True)
class InferenceConfig:
    window: int = 100  # steps; checked against the model's metadata
    every_k_steps: int = 1
    threads: int = 1

    def __post_init__(self) -> None:
        _within(self.window, 1, 10_000, "inference.window")
        _within(self.every_k_steps, 1, 10_000, "inference.every_k_steps")
        _within(self.threads, 1, 64, "inference.threads")


_RULE = DecisionConfig()  # the rule's defaults, once


@dataclass(frozen=True)
class AlertConfig:
    # sequential: monitor.decision (CUSUM; thresholds from the false-alarm rates below), shared with diagnose.
    rule: str = "sequential"
    # The sequential rule's keys: their defaults, meanings and measured sources are DecisionConfig's.
    false_alarms_per_hour: float = _RULE.false_alarms_per_hour  # fault level (WARNING / CRITICAL)
    suspect_false_alarms_per_hour: float = _RULE.suspect_false_alarms_per_hour  # suspect level (NOTICE)
    aggressive_tilt_deg: float = _RULE.aggressive_tilt_deg
    aggressive_rate_deg_s: float = _RULE.aggressive_rate_deg_s
    collective_step_fraction: float = _RULE.collective_step_fraction
    battery_sag_fraction: float = _RULE.battery_sag_fraction
    min_thrust_loss: float = _RULE.min_thrust_loss
    fault_evidence: str = _RULE.fault_evidence
    suspect_evidence: str = _RULE.suspect_evidence
    calibration_path: str = _RULE.calibration_path  # '' = models/decision-calibration.json
    statustext_min_interval_s: float = 5.0  # rate limit of STATUSTEXT to the GCS
    named_value_float: bool = False  # send each probability as NAMED_VALUE_FLOAT PWF1..PWF4

    def __post_init__(self) -> None:
        if self.rule == "consecutive":
            raise ConfigError(RETIRED_RULE)
        _check(self.rule in ALERT_RULES, "alerts.rule", f"must be one of {ALERT_RULES}")
        self.decision()  # bounds of the sequential rule's keys, named alerts.*
        _within(self.statustext_min_interval_s, 0.0, 3600.0, "alerts.statustext_min_interval_s")

    def decision(self) -> DecisionConfig:
        """The sequential rule's settings; its own checks bound every number (finite, named alerts.*)."""
        return DecisionConfig(
            false_alarms_per_hour=self.false_alarms_per_hour,
            suspect_false_alarms_per_hour=self.suspect_false_alarms_per_hour,
            aggressive_tilt_deg=self.aggressive_tilt_deg,
            aggressive_rate_deg_s=self.aggressive_rate_deg_s,
            collective_step_fraction=self.collective_step_fraction,
            battery_sag_fraction=self.battery_sag_fraction,
            min_thrust_loss=self.min_thrust_loss,
            fault_evidence=self.fault_evidence,
            suspect_evidence=self.suspect_evidence,
            calibration_path=self.calibration_path,
        )


@dataclass(frozen=True)
class PlausibleConfig:
    """Physical envelope of each signal: a sample outside it is never evidence (dropped and counted)."""

    attitude_max_rad: float = 3.1416  # |roll|, |yaw| <= pi (MAVLink ATTITUDE is in [-pi, pi]); |pitch| <= pi/2
    rate_max_rad_s: float = 35.0  # body rates within the gyro range (PX4 IMUs: 2000 deg/s = 34.9 rad/s)
    pwm_min_us: float = 1000.0  # motor commands in [min, max] (PX4 PWM_MAIN_MINn/MAXn) ...
    pwm_max_us: float = 2000.0
    pwm_disarmed_us: float = 900.0  # ... or exactly the disarmed value (PWM_MAIN_DISn)
    rpm_max: float = 60_000.0  # motor_source esc: 0 <= rpm <= this
    battery_max_v: float = 100.0
    frozen_s: float = FROZEN_S  # a fast stream whose values stay bit-identical this long is a frozen channel

    def __post_init__(self) -> None:
        _within(self.attitude_max_rad, 3.0, 3.2, "plausible.attitude_max_rad")
        _within(self.rate_max_rad_s, 1.0, 100.0, "plausible.rate_max_rad_s")
        _within(self.pwm_min_us, 0.0, 3000.0, "plausible.pwm_min_us")
        _within(self.pwm_max_us, self.pwm_min_us, 3000.0, "plausible.pwm_max_us", lo_open=True)
        _within(self.pwm_disarmed_us, 0.0, 3000.0, "plausible.pwm_disarmed_us")
        _within(self.rpm_max, 1.0, 500_000.0, "plausible.rpm_max")
        _within(self.battery_max_v, 1.0, 1000.0, "plausible.battery_max_v")
        _within(self.frozen_s, 0.1, 60.0, "plausible.frozen_s")


@dataclass(frozen=True)
class BlindConfig:
    """When the monitor cannot see (no motor data, frozen clock, ...) it says so: STATUS, events, STATUSTEXT NOTICE."""

    after_s: float = 1.0  # data missing or implausible this long (monotonic) = blind
    frozen_clock_s: float = 1.0  # autopilot messages keep coming but its boot clock stands still this long
    notice_min_interval_s: float = 10.0  # rate limit of the BLIND / recovered NOTICEs to the ground station
    events_retry_s: float = 5.0  # a failed events-file write is retried this often (the line is kept)
    events_backlog: int = 1000  # lines kept for retry; older ones are dropped and counted

    def __post_init__(self) -> None:
        _within(self.after_s, 0.0, 60.0, "blind.after_s")
        _within(self.frozen_clock_s, 0.1, 60.0, "blind.frozen_clock_s")
        _within(self.notice_min_interval_s, 0.0, 3600.0, "blind.notice_min_interval_s")
        _within(self.events_retry_s, 0.1, 3600.0, "blind.events_retry_s")
        _within(self.events_backlog, 1, 100_000, "blind.events_backlog")


DEFAULT_STATE_DIR = "/var/lib/propwatch"


@dataclass(frozen=True)
class MonitorConfig:
    model_path: str = str(shipped("classifier.onnx"))
    vehicle_path: str = ""  # optional vehicle YAML whose ESC curve overrides the model's
    # Whether this vehicle is declared to be the classifier's airframe: a configuration that names ``model_path`` or
    # ``vehicle_path``, or ``--model``/``--vehicle``, declares it (as ``propwatch diagnose --model/--vehicle``).
    # Undeclared, the network is silent and physics judges alone (``monitor.decision.network_gate``).
    airframe_declared: bool = False
    events_path: str = ""  # JSON lines, one per alert ('' = none; --events overrides)
    # Vehicle memory (monitor.daemon.memory_adapter): one healthy baseline per vehicle. Default /var/lib/propwatch, or
    # $PROPWATCH_STATE_DIR where set; '' = no vehicle memory. --state-dir overrides.
    state_dir: str = field(default_factory=lambda: os.environ.get("PROPWATCH_STATE_DIR", DEFAULT_STATE_DIR))
    link: LinkConfig = field(default_factory=LinkConfig)
    input: InputConfig = field(default_factory=InputConfig)
    resample: ResampleConfig = field(default_factory=ResampleConfig)
    inference: InferenceConfig = field(default_factory=InferenceConfig)
    alerts: AlertConfig = field(default_factory=AlertConfig)
    plausible: PlausibleConfig = field(default_factory=PlausibleConfig)
    blind: BlindConfig = field(default_factory=BlindConfig)


def load_monitor_config(path: str | Path | None) -> MonitorConfig:
    if path is None:
        return MonitorConfig()
    return monitor_config_from_mapping(read_yaml(path), origin=str(path))


def monitor_config_from_mapping(data: dict, origin: str = "") -> MonitorConfig:
    try:
        _check_retired(data)
    except ConfigError as exc:
        raise ConfigError(f"{origin}: {exc}" if origin else str(exc)) from None
    cfg = from_mapping(MonitorConfig, data, origin=origin)[0]
    if data.get("model_path") or data.get("vehicle_path"):
        cfg = replace(cfg, airframe_declared=True)
    return cfg


def _check_retired(data: dict) -> None:
    """The consecutive rule and its keys are named as such, not as unknown keys (a config written for it)."""
    alerts = data.get("alerts")
    if not isinstance(alerts, dict):
        return
    if alerts.get("rule") == "consecutive":
        raise ConfigError(RETIRED_RULE)
    retired = [k for k in RETIRED_ALERT_KEYS if k in alerts]
    if retired:
        what = "a key" if len(retired) == 1 else "keys"
        keys = ", ".join(f"alerts.{k}" for k in retired)
        raise ConfigError(f"{keys}: {what} of the consecutive rule, which is no longer onboard (offline/alerts); remove")
