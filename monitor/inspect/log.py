"""What propwatch read from a log: per message/topic statistics, the parameters that matter, the grid.

pymavlink (tlog, DataFlash) and pyulog (ULog) do the parsing, as their own tools
``mavlogdump.py`` and ``ulog_info`` do; this module only tabulates. The grid and
the features come from the same readers and ``monitor.features`` that
``propwatch diagnose`` uses, so ``write_csv`` writes exactly what the model is fed.
"""

from __future__ import annotations

import re
from collections import defaultdict
from pathlib import Path

import numpy as np

from monitor.diagnose.engine import window_ends
from monitor.errors import LogFormatError
from monitor.features import compute_features
from monitor.flight import FlightTable
from monitor.logs import detect_format
from monitor.resample import US_PER_S

# Parameters that decide how motor commands, motor order and frame are read (PX4 and ArduPilot names).
PARAMETER_PATTERN = re.compile(
    r"^(MAV_TYPE|SYS_AUTOSTART|CA_AIRFRAME|CA_ROTOR_COUNT|PWM_(MAIN_|AUX_)?(MIN|MAX|FUNC)\d*|"
    r"MOT_PWM_(MIN|MAX|TYPE)|MOT_SPIN_(ARM|MIN|MAX)|RC3_(MIN|MAX)|SERVO[1-8]_FUNCTION|FRAME|FRAME_CLASS|FRAME_TYPE|Q_ENABLE)$"
)
# A gap: an interval longer than this many times the stream's median interval (and over 0.2 s).
GAP_FACTOR, GAP_MIN_S = 5.0, 0.2


def stream_stats(name: str, t_us: np.ndarray) -> dict:
    """Count, mean rate, span and gaps of one message stream (timestamps in µs)."""
    t_all = np.asarray(t_us, dtype=np.float64)
    t = np.sort(t_all[np.isfinite(t_all)]) / US_PER_S  # messages without a time field are counted, not timed
    out = {"name": name, "count": len(t_all), "rate_hz": 0.0, "first_s": None, "last_s": None, "max_gap_s": 0.0, "gaps": 0}
    if len(t) == 0:
        return out
    out.update(first_s=float(t[0]), last_s=float(t[-1]))
    if len(t) > 1:
        dt = np.diff(t)
        span = t[-1] - t[0]
        out["rate_hz"] = (len(t) - 1) / span if span > 0 else 0.0
        out["max_gap_s"] = float(dt.max())
        out["gaps"] = int(np.sum(dt > max(GAP_FACTOR * float(np.median(dt)), GAP_MIN_S)))
    return out


def _boot_us(m, dataflash: bool) -> float:
    """A DataFlash message's boot-clock time (TimeUS, or TimeMS in old logs); a tlog's receive time."""
    if dataflash:
        t_us = getattr(m, "TimeUS", None)
        if t_us is None and getattr(m, "TimeMS", None) is not None:
            t_us = m.TimeMS * 1000.0
        return float("nan") if t_us is None else float(t_us)
    return m._timestamp * US_PER_S


def _mavlink_streams(path: Path, dataflash: bool) -> tuple[list[dict], dict, list[str]]:
    """(stream stats, parameters, vehicle types) from pymavlink's reader of a tlog or DataFlash log."""
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(path), robust_parsing=True)
    times: dict[str, list[float]] = defaultdict(list)
    params: dict[str, float] = {}
    types: dict[str, int] = defaultdict(int)
    while (m := conn.recv_match()) is not None:
        kind = m.get_type()
        if kind == "BAD_DATA":
            continue
        times[kind].append(_boot_us(m, dataflash))
        if kind == "PARM":
            params[m.Name] = m.Value
        elif kind == "PARAM_VALUE":
            params[m.param_id] = m.param_value
        elif kind == "HEARTBEAT" and m.get_srcComponent() == 1:  # the autopilot's own heartbeat
            types[mavutil.mavlink.enums["MAV_TYPE"][m.type].name] += 1
        elif dataflash and kind == "MSG" and m.Message.startswith("Frame:"):
            types[m.Message] += 1
    stats = [stream_stats(k, np.array(v)) for k, v in sorted(times.items())]
    return stats, params, sorted(types, key=types.get, reverse=True)


def _ulog_streams(path: Path) -> tuple[list[dict], dict, list[str]]:
    try:
        from pyulog import ULog
    except ImportError as exc:
        raise LogFormatError("reading .ulg needs pyulog (pip install 'propwatch[logs]')") from exc
    from monitor.logs.ulog import mav_type_name

    ulog = ULog(str(path))
    stats = [stream_stats(f"{d.name}[{d.multi_id}]", d.data["timestamp"]) for d in ulog.data_list]
    params = dict(ulog.initial_parameters)
    vtype = mav_type_name(params.get("MAV_TYPE"))
    return sorted(stats, key=lambda s: s["name"]), params, [vtype] if vtype else []


def inspect_log(path: str | Path, fmt: str | None, table: FlightTable) -> dict:
    """The ``propwatch inspect --json`` object for a log already read into ``table``."""
    path = Path(path)
    fmt = fmt or detect_format(path)
    if fmt == "ulog":
        stats, params, vtypes = _ulog_streams(path)
    elif fmt in ("tlog", "dataflash"):
        stats, params, vtypes = _mavlink_streams(path, dataflash=fmt == "dataflash")
    else:  # a CSV mapping: the streams are the mapping's columns, on the file's own clock
        stats, params, vtypes = [stream_stats(f"{fmt} rows", table.timestamp_us)], {}, []
    cmd = table.motor_cmd
    air = table.airborne
    with np.errstate(all="ignore"):
        motors = {
            "names": list(table.motor_names),
            "px4_rotor": [1, 2, 3, 4],
            "cmd_unit": table.extras.get("motor_cmd_unit", ""),
            "cmd_min": [float(x) for x in np.nanmin(cmd, axis=0)] if np.isfinite(cmd).any() else None,
            "cmd_max": [float(x) for x in np.nanmax(cmd, axis=0)] if np.isfinite(cmd).any() else None,
            "airborne_cmd_mean": [float(x) for x in np.nanmean(cmd[air], axis=0)] if air.any() else None,
        }
    return {
        "log": str(path),
        "format": fmt,
        "vehicle_type": vtypes[0] if vtypes else table.extras.get("vehicle_type", ""),
        # Output functions left unassigned (0) say nothing about the motors.
        "parameters": {
            k: float(v) for k, v in sorted(params.items()) if PARAMETER_PATTERN.match(k) and not ("FUNC" in k and v == 0)
        },
        "motors": motors,
        "messages": stats,
        "grid": {
            "rate_hz": table.rate_hz,
            "steps": len(table.timestamp_us),
            "airborne_steps": int(air.sum()),
            "start_boot_s": float(table.timestamp_us[0] / US_PER_S),
            "stop_boot_s": float(table.timestamp_us[-1] / US_PER_S),
            "stream_rates_hz": table.extras.get("stream_rates_hz", {}),
        },
        "warnings": list(table.warnings),
    }


def write_csv(out_dir: Path, table: FlightTable, features: tuple[str, ...], window: int, hop: int) -> list[Path]:
    """``<log>.signals.csv`` (the resampled table) and ``<log>.features.csv`` (the model's inputs per step,
    with ``window_end`` = 1 where diagnose classifies the window ending at that step)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = re.sub(r"[^A-Za-z0-9_.-]", "_", Path(table.source).name) or "log"
    t = table.timestamp_us
    cols = {"timestamp_us": t, "t_boot_s": t / US_PER_S}
    # PX4 rotor number, then the vehicle's own name when it differs: motor_cmd_2_M3.
    suffix = [str(i + 1) if n == str(i + 1) else f"{i + 1}_{n}" for i, n in enumerate(table.motor_names)]
    for i, sfx in enumerate(suffix):
        cols[f"motor_cmd_{sfx}"] = table.motor_cmd[:, i]
    for i, sfx in enumerate(suffix):
        cols[f"motor_rpm_{sfx}"] = table.motor_rpm[:, i]
    for name, values in table.signals().items():
        if name != "motor_rpm":
            cols[name] = values
    cols["battery_v"] = table.battery_v
    cols["airborne"] = table.airborne.astype(int)
    signals = _write(out_dir / f"{stem}.signals.csv", cols)
    feats = compute_features(table.signals(), features)
    ends = np.zeros(len(t), dtype=int)
    ends[window_ends(table, feats, window, hop)] = 1
    fcols = {"timestamp_us": t, **{f: feats[:, k] for k, f in enumerate(features)}, "window_end": ends}
    return [signals, _write(out_dir / f"{stem}.features.csv", fcols)]


def _write(path: Path, cols: dict[str, np.ndarray]) -> Path:
    names = list(cols)
    data = np.column_stack([np.asarray(cols[n], dtype=np.float64) for n in names])
    ints = {n for n in names if n in ("timestamp_us", "airborne", "window_end")}
    fmt = ["%d" if n in ints else "%.9g" for n in names]
    tmp = path.with_suffix(".csv.part")
    np.savetxt(tmp, data, delimiter=",", header=",".join(names), comments="", fmt=fmt)
    tmp.replace(path)  # nothing half-written under the final name
    return path
