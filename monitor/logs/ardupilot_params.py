"""ArduCopter parameters as a DataFlash log records them through time: frame, motor outputs, lift level.

PARM messages are a dump at the start of the log and a message for every later write. What the
reader needs from them:

- the frame (FRAME_CLASS / FRAME_TYPE, Copter 3.3's FRAME): only a quad X fits the model;
- the output of each motor: motor k is on the output whose SERVOn_FUNCTION is 32 + k
  (ArduPilot >= 3.5), else on output k (Copter 3.3 has no such parameter). ArduPilot SITL's
  motor-fault injection rewrites SERVOn_FUNCTION in flight; the mapping at take-off is the
  vehicle's, and every later change is reported, not obeyed;
- the output above which the rotors lift (``lift_pwm``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError
from monitor.logs.units import US_PER_S

SERVO_FUNCTION_MOTOR1 = 33  # SERVOn_FUNCTION: 33..36 = Motor1..Motor4
FRAME_CLASS_QUAD, FRAME_TYPE_X, OLD_FRAME_X = 1, 1, 1
# AP_Motors_Class.h motor_frame_class / motor_frame_type, and Copter 3.3's FRAME (the same numbers as its types).
FRAME_CLASS_NAMES = {
    0: "undefined", 1: "Quad", 2: "Hexa", 3: "Octa", 4: "OctaQuad", 5: "Y6", 6: "Heli", 7: "Tri",
    8: "SingleCopter", 9: "CoaxCopter", 10: "BiCopter", 11: "Heli_Dual", 12: "DodecaHexa", 13: "HeliQuad",
    14: "Deca", 15: "Scripting Matrix", 16: "6DoF Scripting", 17: "Dynamic Scripting Matrix",
}  # fmt: skip
FRAME_TYPE_NAMES = {
    0: "Plus", 1: "X", 2: "V", 3: "H", 4: "V-Tail", 5: "A-Tail", 10: "Y6B", 11: "Y6F", 12: "BetaFlightX",
    13: "DJIX", 14: "ClockwiseX", 15: "I", 18: "BetaFlightXReversed", 19: "Y4",
}  # fmt: skip
OTHER_X_NUMBERINGS = (12, 13, 14, 18)  # BetaFlightX, DJIX, ClockwiseX, BetaFlightXReversed
# ArduCopter >= 3.5 defaults (AP_MotorsMulticopter.cpp): MOT_SPIN_ARM 0.10, MOT_SPIN_MIN 0.15 of the output range.
SPIN_ARM_DEFAULT, SPIN_MIN_DEFAULT = 0.10, 0.15


def _name(names: dict[int, str], value: float) -> str:
    return f"{value:g} ({names[int(value)]})" if value == int(value) and int(value) in names else f"{value:g}"


def check_quad_x(params: dict[str, float], path: Path) -> None:
    """Refuse, naming what the log says the frame is, any frame but a quad X."""
    frame_class = params.get("FRAME_CLASS", FRAME_CLASS_QUAD)
    if frame_class != FRAME_CLASS_QUAD:
        raise LogFormatError(
            f"{path}: not a quad-X: the log says FRAME_CLASS {_name(FRAME_CLASS_NAMES, frame_class)}; the model is for quad X"
        )
    if "FRAME_CLASS" in params:
        key, frame_type = "FRAME_TYPE", params.get("FRAME_TYPE", FRAME_TYPE_X)
    else:
        key, frame_type = "FRAME", params.get("FRAME", OLD_FRAME_X)
    if frame_type in OTHER_X_NUMBERINGS and key == "FRAME_TYPE":
        raise LogFormatError(
            f"{path}: the log says FRAME_TYPE {_name(FRAME_TYPE_NAMES, frame_type)}: a quad X whose motors are "
            "numbered otherwise than ArduCopter's X (FRAME_TYPE 1), which this reader does not map"
        )
    if frame_type != FRAME_TYPE_X:
        raise LogFormatError(
            f"{path}: not a quad-X: the log says {key} {_name(FRAME_TYPE_NAMES, frame_type)}; the model is for quad X"
        )


def motor_outputs(params: dict[str, float], path: Path) -> tuple[int, int, int, int]:
    """1-based output channel of motors 1..4, after checking the frame is a quad X."""
    check_quad_x(params, path)
    by_function = {int(v): int(k[5:-9]) for k, v in params.items() if _servo_number(k)}
    if any(SERVO_FUNCTION_MOTOR1 + i in by_function for i in range(4)):
        try:
            return tuple(by_function[SERVO_FUNCTION_MOTOR1 + i] for i in range(4))  # type: ignore[return-value]
        except KeyError:
            raise LogFormatError(f"{path}: SERVOn_FUNCTION does not assign all of Motor1..Motor4") from None
    return (1, 2, 3, 4)


def _servo_number(name: str) -> bool:
    return name.startswith("SERVO") and name.endswith("_FUNCTION") and name[5:-9].isdigit()


def lift_pwm(params: dict[str, float]) -> float | None:
    """Mean motor output (µs) above which the rotors lift: the in-flight minimum MOT_SPIN_MIN (or the armed
    idle MOT_SPIN_ARM, if set higher) on the MOT_PWM_MIN..MAX range, else RC3_MIN..MAX where those are 0.
    None where the log lacks MOT_SPIN_MIN (Copter 3.3: the reader's default level applies)."""
    if "MOT_SPIN_MIN" not in params:
        return None
    lo = params.get("MOT_PWM_MIN", 0.0) or params.get("RC3_MIN", 0.0)
    hi = params.get("MOT_PWM_MAX", 0.0) or params.get("RC3_MAX", 0.0)
    if not 0.0 < lo < hi:
        return None
    spin = max(params["MOT_SPIN_MIN"], params.get("MOT_SPIN_ARM", SPIN_ARM_DEFAULT))
    return lo + spin * (hi - lo)


@dataclass(frozen=True)
class ParamHistory:
    """PARM writes in log order: (boot time µs, name, value)."""

    writes: list[tuple[int, str, float]]

    def latest(self) -> dict[str, float]:
        return {name: value for _, name, value in self.writes}

    def before_change(self, k: int, changes: list[ServoChange]) -> dict[str, float]:
        """Every parameter's value just before ``changes[k]`` (all writes when ``k`` is past the last)."""
        end = changes[k].index if k < len(changes) else len(self.writes)
        return {name: value for _, name, value in self.writes[:end]}

    def servo_changes(self) -> list[ServoChange]:
        """SERVOn_FUNCTION writes that change an output to or from a motor function, after the first value."""
        seen: dict[str, float] = {}
        out = []
        for i, (t, name, value) in enumerate(self.writes):
            if not _servo_number(name):
                continue
            before = seen.get(name)
            seen[name] = value
            if before is not None and before != value and (_is_motor(before) or _is_motor(value)):
                out.append(ServoChange(t, name, value, before, i))
        return out


def _is_motor(function: float) -> bool:
    return SERVO_FUNCTION_MOTOR1 <= function < SERVO_FUNCTION_MOTOR1 + 4


@dataclass(frozen=True)
class ServoChange:
    t_us: int
    name: str
    value: float
    before: float
    index: int  # in ParamHistory.writes

    def warning(self, takeoff_us: int | None) -> str:
        if takeoff_us is None:
            when = f"at {self.t_us / US_PER_S:.1f} s of the log (no take-off found)"
        else:
            dt = (self.t_us - takeoff_us) / US_PER_S
            when = f"at {dt:.1f} s after take-off" if dt >= 0 else f"at {-dt:.1f} s before take-off"
        return (
            f"{self.name} changed from {_function_name(self.before)} to {_function_name(self.value)} "
            f"{when}: motors read on the outputs the mapping at take-off gave them"
        )


def _function_name(function: float) -> str:
    return f"{function:g} (Motor{int(function) - SERVO_FUNCTION_MOTOR1 + 1})" if _is_motor(function) else f"{function:g}"


def takeoff_mapping(
    history: ParamHistory, cmd: list[tuple[int, dict[int, float]]], lift_us: float, path: Path
) -> tuple[int | None, tuple[int, int, int, int], list[ServoChange]]:
    """(take-off time or None, motor outputs then, the SERVOn_FUNCTION changes) for RCOU rows ``cmd``.

    Take-off is the first RCOU sample whose four motors, on the mapping in force at that time, average
    above ``lift_us``; the mapping is checked (quad X, all four motors assigned) only there. With no such
    sample, the mapping of the log's first parameters (its dump at the start) is used."""
    changes = history.servo_changes()
    bounds = [c.t_us for c in changes]
    times = np.array([t for t, _ in cmd], dtype=np.int64)
    starts = np.searchsorted(times, [0, *bounds], side="left")
    stops = [*starts[1:], len(times)]
    for k, (a, b) in enumerate(zip(starts, stops, strict=True)):
        if a >= b:
            continue
        try:
            channels = motor_outputs(history.before_change(k, changes), path)
        except LogFormatError:
            continue  # a mapping the vehicle never took off with
        for t, outs in cmd[a:b]:
            if np.mean([outs.get(c, np.nan) for c in channels]) > lift_us:
                return t, channels, changes
    return None, motor_outputs(history.before_change(0, changes), path), changes
