"""Who flew a log, and when: vehicle id and the UTC clock of the autopilot's boot time.

The vehicle id comes from the log itself where the format carries one:
- PX4 ULog: the ``sys_uuid`` info message (the board's unique id, PX4 >= 1.11);
- MAVLink .tlog: AUTOPILOT_VERSION ``uid`` / ``uid2`` (ground stations request it on connect);
- ArduPilot DataFlash: the ``BRD_SERIAL_NUM`` parameter when set, else the board's
  unique id that ArduPilot writes as a MSG at boot (``PX4v2 004A002F 33345119 32383433``).
Otherwise there is none here and the caller falls back to a folder name.

The clock: UTC µs = boot µs + ``utc_minus_boot_us``, from GPS time (ULog
``time_utc_usec``, DataFlash GPS week and ms) or, in a .tlog, the ground
station's receive time of the first ATTITUDE against its ``time_boot_ms``.
"""

from __future__ import annotations

import datetime as _dt
import re
from dataclasses import dataclass
from pathlib import Path

from monitor.resample import US_PER_S

# UTC from 2000 on: an autopilot clock before that is a board without time, never a flight date.
MIN_PLAUSIBLE_UTC_US = 946_684_800 * 1_000_000
MAX_PLAUSIBLE_UTC_US = 4_102_444_800 * 1_000_000  # 2100
GPS_EPOCH_UNIX_S = 315_964_800  # 1980-01-06T00:00:00Z
# GPS - UTC (leap seconds) from each UTC date on; IERS Bulletin C. Before 2006 logs are out of scope.
GPS_LEAP_S = ((1_483_228_800, 18), (1_435_708_800, 17), (1_341_100_800, 16), (1_230_768_000, 15), (1_136_073_600, 14))
TS_BYTES = 8
AUTOPILOT_VERSION_ID, ATTITUDE_ID = 148, 30
BOARD_UID_MSG = re.compile(r"^\S+ ([0-9A-Fa-f]{8}) ([0-9A-Fa-f]{8}) ([0-9A-Fa-f]{8})$")


@dataclass(frozen=True)
class LogIdentity:
    vehicle_id: str | None = None
    vehicle_id_source: str | None = None
    utc_minus_boot_us: int | None = None
    time_source: str | None = None


def plausible_utc(us: float | int | None) -> bool:
    return us is not None and MIN_PLAUSIBLE_UTC_US <= us <= MAX_PLAUSIBLE_UTC_US


def gps_to_unix_us(week: int, ms_of_week: float) -> int:
    """GPS week + milliseconds of week -> UTC µs since 1970 (leap seconds removed)."""
    gps_s = GPS_EPOCH_UNIX_S + week * 604_800 + ms_of_week / 1000.0
    leap = next((s for since, s in GPS_LEAP_S if gps_s - s >= since), 13)
    return int(round((gps_s - leap) * US_PER_S))


def identify(path: str | Path, fmt: str) -> LogIdentity:
    """The vehicle id and clock this log carries (fields None where it carries none)."""
    if fmt == "ulog":
        return _ulog(Path(path))
    if fmt == "tlog":
        return _tlog(Path(path))
    if fmt == "dataflash":
        return _dataflash(Path(path))
    return LogIdentity()


def _ulog(path: Path) -> LogIdentity:
    from pyulog import ULog

    ulog = ULog(str(path), ["vehicle_gps_position", "sensor_gps"])
    uuid = str(ulog.msg_info_dict.get("sys_uuid", "")).strip()
    offset = None
    for d in sorted(ulog.data_list, key=lambda d: (d.name != "vehicle_gps_position", d.multi_id)):
        utc, boot = d.data.get("time_utc_usec"), d.data.get("timestamp")
        if utc is None or boot is None:
            continue
        ok = [k for k in range(len(utc)) if plausible_utc(int(utc[k]))]
        if ok:
            offset = int(utc[ok[0]]) - int(boot[ok[0]])
            break
    return LogIdentity(uuid or None, "ulog:sys_uuid" if uuid else None, offset, "ulog:gps" if offset is not None else None)


def _mav_decoder():
    from pymavlink.dialects.v20 import common

    return common.MAVLink(None)


def _tlog_frames(buf: bytes, msgid: int):
    """(receive time µs, decoded message) of CRC-valid frames with ``msgid`` (v1 and v2)."""
    mav = _mav_decoder()
    v2 = re.compile(rb"\xfd.{6}" + re.escape(bytes([msgid, 0, 0])), re.DOTALL)
    v1 = re.compile(rb"\xfe.{4}" + re.escape(bytes([msgid])), re.DOTALL)
    starts = sorted({m.start() for m in v2.finditer(buf)} | {m.start() for m in v1.finditer(buf)})
    for p in starts:
        if p < TS_BYTES:
            continue
        flen = (12 + buf[p + 1]) if buf[p] == 0xFD else (8 + buf[p + 1])
        try:
            msg = mav.decode(bytearray(buf[p : p + flen]))
        except Exception:  # noqa: BLE001 - pymavlink raises bare MAVError / struct errors on false starts
            continue
        yield int.from_bytes(buf[p - TS_BYTES : p], "big"), msg


def _tlog(path: Path) -> LogIdentity:
    buf = path.read_bytes()
    vid = src = None
    for _, msg in _tlog_frames(buf, AUTOPILOT_VERSION_ID):
        if msg.get_srcComponent() != 1:  # MAV_COMP_ID_AUTOPILOT1: the flight controller's own id
            continue
        if msg.uid:
            vid, src = f"{msg.uid:016x}", "mavlink:AUTOPILOT_VERSION.uid"
        elif any(msg.uid2):
            vid, src = bytes(msg.uid2).hex(), "mavlink:AUTOPILOT_VERSION.uid2"
        if vid:
            break
    offset = None
    for t_wall_us, msg in _tlog_frames(buf, ATTITUDE_ID):
        if plausible_utc(t_wall_us):
            offset = t_wall_us - int(msg.time_boot_ms) * 1000
        break
    return LogIdentity(vid, src, offset, "tlog:receive_time" if offset is not None else None)


def _dataflash(path: Path) -> LogIdentity:
    from pymavlink import DFReader

    reader = DFReader.DFReader_binary(str(path), zero_time_base=False)
    serial = uid = None
    offset = None
    while offset is None:
        m = reader.recv_match(type=["PARM", "MSG", "GPS"])
        if m is None:
            break
        kind = m.get_type()
        if kind == "PARM" and m.Name == "BRD_SERIAL_NUM" and int(m.Value) != 0:
            serial = str(int(m.Value))
        elif kind == "MSG" and uid is None and (hit := BOARD_UID_MSG.match(str(m.Message).strip())):
            uid = "".join(hit.groups()).upper()
        elif kind == "GPS":
            week = getattr(m, "GWk", getattr(m, "Week", 0))
            ms = getattr(m, "GMS", getattr(m, "TimeMS", 0))
            boot_us = getattr(m, "TimeUS", None)
            if boot_us is None:
                boot_us = int(getattr(m, "T", 0)) * 1000
            if week > 0:
                utc = gps_to_unix_us(int(week), float(ms))
                if plausible_utc(utc):
                    offset = utc - int(boot_us)
    if serial:
        return LogIdentity(serial, "dataflash:BRD_SERIAL_NUM", offset, "dataflash:gps" if offset is not None else None)
    src = "dataflash:MSG board uid" if uid else None
    return LogIdentity(uid, src, offset, "dataflash:gps" if offset is not None else None)


def iso_utc(us: int | None) -> str | None:
    if us is None:
        return None
    return _dt.datetime.fromtimestamp(us / US_PER_S, tz=_dt.timezone.utc).isoformat(timespec="seconds")
