"""What ``propwatch adapt`` refuses as "healthy" input, each time naming the log and why.

- a log of another vehicle type: the model is a quad X. MAVLink logs say their type in the
  autopilot's HEARTBEAT (MAV_TYPE; 2 = quadrotor), PX4 ULogs in the ``MAV_TYPE`` and
  ``CA_ROTOR_COUNT`` parameters and ``vehicle_status.is_vtol``; DataFlash logs are refused by
  their reader (FRAME_CLASS / FRAME_TYPE); a CSV mapping has four motors by construction;
- a log with no airborne time (nothing to learn a healthy airframe from);
- a log whose per-motor share lies beyond ``OUTLIER_SPREADS`` flight-to-flight spreads of the
  other healthy logs (a faulty or loaded vehicle), leave-one-out, so one bad log cannot hide
  by widening the spread it is judged against.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError
from monitor.flight import FlightTable
from monitor.logs import detect_format
from offline.adapt.share_rule import OUTLIER_SPREADS, SPREAD_FLOOR, flight_shares

MAV_TYPE_QUADROTOR = 2
MIN_AIRBORNE_S = 5.0  # less than one classifier window (5 s) of flight teaches nothing


class NotHealthyError(LogFormatError):
    """A log given as healthy is not usable as such (wrong vehicle, no flight, a fault)."""


def vehicle_type_problem(path: str | Path, fmt: str | None) -> str | None:
    """Why this log is not of a quad X, or None when it is (or the format cannot say otherwise)."""
    kind = fmt or detect_format(path)
    if kind == "tlog":
        return _tlog_type(Path(path))
    if kind == "ulog":
        return _ulog_type(Path(path))
    return None


def _tlog_type(path: Path) -> str | None:
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(path), dialect="common")
    types = set()
    try:
        for _ in range(200):
            msg = conn.recv_match(type="HEARTBEAT", blocking=False)
            if msg is None:
                break
            if msg.autopilot != mavutil.mavlink.MAV_AUTOPILOT_INVALID:  # GCS and companions say INVALID
                types.add(int(msg.type))
    finally:
        conn.close()
    other = sorted(types - {MAV_TYPE_QUADROTOR})
    if other:
        names = [mavutil.mavlink.enums["MAV_TYPE"][t].name if t in mavutil.mavlink.enums["MAV_TYPE"] else str(t) for t in other]
        return f"the autopilot's HEARTBEAT says {', '.join(names)}, not MAV_TYPE_QUADROTOR: the model is for a quad X"
    return None


def _ulog_type(path: Path) -> str | None:
    from pyulog import ULog

    try:
        ulog = ULog(str(path), ["vehicle_status"])
    except Exception as exc:  # pyulog raises plain exceptions on bad files
        raise LogFormatError(f"{path}: not a readable ULog file: {exc}") from exc
    p = ulog.initial_parameters
    if "MAV_TYPE" in p and int(p["MAV_TYPE"]) != MAV_TYPE_QUADROTOR:
        return f"parameter MAV_TYPE = {int(p['MAV_TYPE'])}, not 2 (quadrotor): the model is for a quad X"
    if "CA_ROTOR_COUNT" in p and int(p["CA_ROTOR_COUNT"]) != 4:
        return f"parameter CA_ROTOR_COUNT = {int(p['CA_ROTOR_COUNT'])}: the model is for a quad X (4 rotors)"
    for d in ulog.data_list:
        if d.name == "vehicle_status" and "is_vtol" in d.data and np.any(d.data["is_vtol"]):
            return "vehicle_status.is_vtol is set: a VTOL, the model is for a quad X"
    return None


def check_airborne(table: FlightTable, name: str) -> None:
    airborne_s = float(table.airborne.sum()) / table.rate_hz
    if airborne_s < MIN_AIRBORNE_S:
        raise NotHealthyError(
            f"{name}: refused as healthy: {airborne_s:.1f} s airborne (need >= {MIN_AIRBORNE_S:g} s): "
            "no flight to learn a healthy airframe from"
        )


def check_consistent(tables: list[FlightTable], names: list[str]) -> None:
    """Refuse any log whose per-motor share is beyond 3 spreads of the other logs (leave-one-out)."""
    if len(tables) < 2:
        return
    shares = np.array([flight_shares(t)[0] for t in tables])
    problems = []
    for i, name in enumerate(names):
        others = np.delete(shares, i, axis=0)
        spread = np.maximum(others.std(axis=0, ddof=1) if len(others) > 1 else 0.0, SPREAD_FLOOR)
        dev = (shares[i] - others.mean(axis=0)) / spread
        bad = np.flatnonzero(np.abs(dev) > OUTLIER_SPREADS)
        if len(bad):
            k = int(bad[np.argmax(np.abs(dev[bad]))])
            problems.append(
                (
                    float(np.abs(dev[k])),
                    f"{name}: refused as healthy: rotor {tables[i].motor_names[k]} share {100 * shares[i, k]:.1f} % is "
                    f"{dev[k]:+.1f} spreads from the other healthy logs' {100 * others[:, k].mean():.1f} % "
                    f"(limit {OUTLIER_SPREADS:g}): a faulty or loaded vehicle",
                )
            )
    if not problems:
        return
    if len(tables) == 2:
        raise NotHealthyError(
            f"{names[0]} and {names[1]} disagree beyond {OUTLIER_SPREADS:g} spreads and two logs cannot say which is "
            "healthy: " + problems[0][1]
        )
    # The worst offender is named first; with it out the others may agree, so refuse it alone.
    problems.sort(reverse=True)
    raise NotHealthyError(problems[0][1])
