"""MAVLink telemetry logs (``.tlog``) -> ``RawFlight``.

A tlog is a sequence of [8-byte big-endian receive time µs][MAVLink v1/v2
frame]. Frames are located here by their headers and only the message ids
propwatch uses are unpacked; the rest are skipped unparsed. A clean file is
CRC-checked and unpacked in bulk (``monitor.logs.mavbulk``, from pymavlink's
message definitions); a damaged one goes frame by frame through pymavlink's
``decode``. Either way every message then goes, in file order, through
``monitor.mavlink.decode``'s ``MavlinkDecoder``, the same decoder the onboard
daemon uses, so both see the same samples on the same boot clock.

Bytes that are not a valid frame (corruption) are skipped with a warning; a
frame cut off at the end of the file (truncation) ends the read with a warning.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError
from monitor.logs.guards import check_marker_gaps
from monitor.logs.mavbulk import messages, unpack_groups
from monitor.logs.raw import RawFlight, Stream
from monitor.logs.tlog_columns import decode_columns
from monitor.logs.units import US_PER_MS
from monitor.mavlink import decode as md

TS_BYTES = 8
V1_MAGIC, V2_MAGIC = 0xFE, 0xFD
V1_OVERHEAD = 8  # magic, len, seq, sys, comp, msgid, crc(2)
V2_OVERHEAD = 12  # magic, len, incompat, compat, seq, sys, comp, msgid(3), crc(2)
V2_SIGNATURE = 13
MAVLINK_IFLAG_SIGNED = 0x01
HEARTBEAT_ID, LOCAL_POSITION_NED_ID = 0, 32
# What a diagnosis needs: the ids the shared decoder handles, less ESC telemetry, plus the accelerometer the daemon
# requests (the decision rule's specific force: without it the rule's baseline plane has no force term, and a
# forward flight's trims read as a change).
CORE_IDS = frozenset((set(md.STREAM_IDS.values()) | {HEARTBEAT_ID, md.HIGHRES_IMU_ID, md.SCALED_IMU_ID}) - {md.ESC_STATUS_ID})
# Plus ESC RPM (calibration); LOCAL_POSITION_NED is one of the decoder's streams already.
WANTED_IDS = CORE_IDS | {md.ESC_STATUS_ID, LOCAL_POSITION_NED_ID}
# A receive time further than this from the previous one is a false frame start.
MAX_TS_JUMP_US = 3_600_000_000
# Records proposed as a clean file's chain: those within a day of the first one's receive time. Speed only: the
# proposal is checked link by link (``_chain``), and any other file is followed one record at a time.
PROPOSAL_SPAN_US = 86_400_000_000


def _mavlink():
    """A MAVLink 2 ``common`` parser (reads v1 frames too) and its id -> message class map."""
    from pymavlink.dialects.v20 import common

    # ESC_STATUS in this dialect only: registering in every dialect imports ardupilotmega and all (0.15 s).
    md.mavlink_esc.register(common)
    return common.MAVLink(None), common.mavlink_map


def _next_is_frame(buf: bytes, off: int) -> bool:
    """True at the end of the file or where a [time][magic] record starts."""
    return off >= len(buf) or (off + TS_BYTES < len(buf) and buf[off + TS_BYTES] in (V1_MAGIC, V2_MAGIC))


def _next_magic(buf: bytes, start: int, n: int) -> int:
    """Index of the next MAVLink magic byte at or after ``start`` (``n`` if none), in C-speed steps."""
    width = 256
    while start < n:
        end = min(start + width, n)
        hits = [i for i in (buf.find(b"\xfd", start, end), buf.find(b"\xfe", start, end)) if i >= 0]
        if hits:
            return min(hits)
        start, width = end, min(width * 2, 1 << 20)
    return n


def iter_frames(buf: bytes, wanted=WANTED_IDS):
    """Yield (offset, frame bytes) for wanted ids; returns (skipped_bytes, truncated) via StopIteration.value."""
    n, off, skipped, last_ts = len(buf), 0, 0, None
    while off + TS_BYTES + 1 < n:
        magic = buf[off + TS_BYTES]
        p = off + TS_BYTES
        if magic == V2_MAGIC and p + 10 <= n:
            flen = V2_OVERHEAD + buf[p + 1] + (V2_SIGNATURE if buf[p + 2] & MAVLINK_IFLAG_SIGNED else 0)
            msgid = buf[p + 7] | (buf[p + 8] << 8) | (buf[p + 9] << 16)
        elif magic == V1_MAGIC and p + 6 <= n:
            flen = V1_OVERHEAD + buf[p + 1]
            msgid = buf[p + 5]
        else:
            if p + 10 > n and magic in (V1_MAGIC, V2_MAGIC):
                return skipped, True
            # Not a magic byte: every start before the next one would be skipped one by one; jump there.
            step = max(min(_next_magic(buf, p + 1, n), n - 1) - TS_BYTES - off, 1)
            off, skipped = off + step, skipped + step
            continue
        ts = int.from_bytes(buf[off : off + TS_BYTES], "big")
        if last_ts is not None and abs(ts - last_ts) > MAX_TS_JUMP_US and not _next_is_frame(buf, p + flen):
            # A receive time far off and no frame after it: a false start inside damaged bytes.
            # (A real jump of the recording clock is followed by more frames and is kept.)
            off, skipped = off + 1, skipped + 1
            continue
        if p + flen > n:
            return skipped, True
        if msgid in wanted:
            ok = yield off, buf[p : p + flen]
            if ok is False:  # CRC failed: not a frame after all
                off, skipped = off + 1, skipped + 1
                continue
        last_ts = ts
        off = p + flen
    return skipped, off < n  # bytes left that cannot hold a frame: cut off


class _Collector:
    """Decoder samples -> per-boot-session lists of (t_us, values)."""

    def __init__(self):
        self.sessions: list[dict[str, list]] = [self._empty()]
        self.output_source: str | None = None
        self.battery_source: str | None = None

    @staticmethod
    def _empty() -> dict[str, list]:
        keys = ("cmd", "att", "rate", "bat", "armed", "landed", "esc", "pos", "vel", "acc_HIGHRES_IMU", "acc_SCALED_IMU")
        return {k: [] for k in keys}

    def add(self, s) -> None:
        cur = self.sessions[-1]
        if isinstance(s, md.ClockReset):
            self.sessions.append(self._empty())
        elif isinstance(s, md.Attitude):
            cur["att"].append((s.timestamp_us, (s.roll_rad, s.pitch_rad, s.yaw_rad)))
            cur["rate"].append((s.timestamp_us, (s.roll_rate_rad_s, s.pitch_rate_rad_s, s.yaw_rate_rad_s)))
        elif isinstance(s, md.ActuatorOutputs):
            # One source of motor outputs per log (PX4 may send both); motors 1..4 are outputs 1..4.
            self.output_source = self.output_source or s.source
            if s.source == self.output_source and s.first_channel == 1:
                cur["cmd"].append((s.timestamp_us, s.values_us[:4]))
        elif isinstance(s, md.EscRpm) and s.first_index == 0:
            cur["esc"].append((s.timestamp_us, s.rpm[:4]))
        elif isinstance(s, md.Battery) and s.timestamp_us is not None:
            self.battery_source = self.battery_source or s.source
            if s.source == self.battery_source:
                cur["bat"].append((s.timestamp_us, s.voltage_v))
        elif isinstance(s, md.Heartbeat) and s.timestamp_us is not None:
            cur["armed"].append((s.timestamp_us, 1.0 if s.armed else 0.0))
        elif isinstance(s, md.LandedState) and s.timestamp_us is not None:
            cur["landed"].append((s.timestamp_us, 0.0 if md.is_flying(s.landed_state) else 1.0))
        elif isinstance(s, md.ImuAccel):  # the decoder's: HIGHRES_IMU of IMU 0 in m/s^2, SCALED_IMU from milli-g
            cur["acc_" + s.source].append((s.timestamp_us, s.accel_frd_m_s2))
        elif isinstance(s, md.LocalVelocity):
            cur["vel"].append((s.timestamp_us, s.vel_ned_m_s))

    def acceleration(self, cur: dict) -> Stream | None:
        """HIGHRES_IMU where the log has it, else SCALED_IMU (the daemon's rule, per log rather than per gap)."""
        return _stream(cur["acc_HIGHRES_IMU"]) or _stream(cur["acc_SCALED_IMU"])


def _stream(items) -> Stream | None:
    """A list of (t_us, values), or the (t_us, values) arrays of ``tlog_columns``."""
    if not items:
        return None
    if isinstance(items, tuple):
        return Stream.build(*items)
    return Stream.build([i[0] for i in items], [i[1] for i in items])


def _chain(cand: np.ndarray, k: np.ndarray, data: np.ndarray) -> np.ndarray | None:
    """The candidates (indices) on the chain from the first byte, given each one's successor ``k`` (``len(cand)``:
    the file ends there; -1: the chain breaks); None where it does not reach the end.

    A record's receive time is 8 bytes before its magic; a candidate inside a payload has random bytes there. The
    candidates whose time lies within a day of the first record's are proposed as the chain and the proposal is
    checked link by link, which makes it exact: a chain from 0 whose every link is a successor and whose last link
    ends the file is the chain. Where the check fails (a payload that happens to look like a time), the chain is
    followed one record at a time."""
    end = len(cand)
    t_us = np.lib.stride_tricks.sliding_window_view(data, TS_BYTES)[cand].view(">u8").ravel()
    near = np.abs(t_us.astype(np.float64) - float(t_us[0])) < PROPOSAL_SPAN_US
    q = np.flatnonzero(near)
    if len(q) and q[0] == 0 and k[q[-1]] == end and np.array_equal(k[q[:-1]], q[1:]):
        return q
    chain, follow, i = [], k.tolist(), 0
    append = chain.append
    while 0 <= i < end:
        append(i)
        i = follow[i]
    return np.asarray(chain, dtype=np.int64) if i == end else None


def clean_frame_starts(buf: bytes, wanted) -> np.ndarray | None:
    """``frame_starts`` of a clean file, found with numpy: every [time][magic] record position is a candidate, each
    candidate's frame length says where the next record starts, and the chain from the first byte is followed
    through them. None where that chain is not the whole file (a broken record, a cut-off end, a receive time
    jumping by more than MAX_TS_JUMP_US): ``iter_frames`` walks such a file and says what it skipped."""
    n = len(buf)
    if n <= TS_BYTES:
        return None
    data = np.frombuffer(buf, dtype=np.uint8)
    # Record offsets whose frame may start there: V2_MAGIC 0xFD or V1_MAGIC 0xFE, found as ">= 0xFD, not 0xFF" (one
    # pass and one temporary over the file, where two comparisons took several times longer on a 26 MB log).
    c = np.flatnonzero(data[TS_BYTES:] >= V2_MAGIC)
    cand = c[data[c + TS_BYTES] != 0xFF]
    if len(cand) == 0 or cand[0] != 0:
        return None

    def at(i: np.ndarray) -> np.ndarray:  # bytes at offsets i; past the end reads the last byte (a cut-off frame)
        return data[np.minimum(i, n - 1)]

    p = cand + TS_BYTES
    v2 = data[p] == V2_MAGIC
    plen = at(p + 1).astype(np.int64)
    signed = np.where(v2 & (at(p + 2) & MAVLINK_IFLAG_SIGNED != 0), V2_SIGNATURE, 0)
    nxt = p + plen + np.where(v2, V2_OVERHEAD, V1_OVERHEAD) + signed  # the next record's offset
    k = np.searchsorted(cand, nxt)
    k[(k >= len(cand)) | (cand[np.minimum(k, len(cand) - 1)] != nxt)] = -1  # not a candidate: the chain breaks
    k[nxt == n] = len(cand)  # unless the file ends exactly there
    idx = _chain(cand, k, data)
    if idx is None:
        return None
    rec = cand[idx]
    ts = np.lib.stride_tricks.sliding_window_view(data, TS_BYTES)[rec].view(">u8").ravel().astype(np.int64)  # µs
    if len(ts) > 1 and np.any(np.abs(np.diff(ts)) > MAX_TS_JUMP_US):
        return None
    pp = p[idx]
    msgid = np.where(
        v2[idx],
        at(pp + 7).astype(np.int64) | (at(pp + 8).astype(np.int64) << 8) | (at(pp + 9).astype(np.int64) << 16),
        at(pp + 5),
    )
    return pp[np.isin(msgid, list(wanted))]


def frame_starts(buf: bytes, wanted) -> tuple[list[int], int, bool]:
    """Offsets of the wanted frames' magic bytes, bytes skipped, and whether the end is cut off."""
    clean = clean_frame_starts(buf, wanted)
    if clean is not None:
        return clean, 0, False
    starts: list[int] = []
    frames = iter_frames(buf, wanted)
    try:
        off, _ = next(frames)
        while True:
            starts.append(off + TS_BYTES)
            off, _ = frames.send(True)
    except StopIteration as stop:
        skipped, truncated = stop.value or (0, False)
    return starts, skipped, truncated


def read_tlog(path: str | Path, system_id: int | None = None, extras: bool = True, bulk: bool = True) -> RawFlight:
    """``extras=False`` skips ESC telemetry (a diagnosis does not use it).

    ``bulk``: unpack clean files with ``monitor.logs.mavbulk`` (same messages, several
    times faster) and, without ``extras``, decode their 50 Hz streams as columns (``monitor.logs.tlog_columns``,
    same samples); a file with skipped bytes or a bad CRC is always read frame by frame.
    """
    path = Path(path)
    if not path.is_file():
        raise LogFormatError(f"{path}: no such file")
    check_marker_gaps(path, (bytes([V1_MAGIC]), bytes([V2_MAGIC])), "MAVLink")
    buf = path.read_bytes()
    mav, mavlink_map = _mavlink()
    dec = md.MavlinkDecoder(system_id=system_id)
    col = _Collector()
    wanted = WANTED_IDS if extras else CORE_IDS
    bad_crc, skipped, truncated = 0, 0, False
    msgs = columns = None
    if bulk:
        starts, skipped, truncated = frame_starts(buf, wanted)
        groups = unpack_groups(buf, starts, mavlink_map) if skipped == 0 else None
        if groups is not None and not extras:  # the 50 Hz streams as columns where the file allows
            columns = decode_columns(groups, len(starts), dec, col.add)
        if groups is not None and columns is None:
            msgs = messages(groups, len(starts))
    if columns is not None:
        col.sessions[-1].update(columns)
    elif msgs is not None:
        for msg in msgs:
            for s in dec.decode(msg):
                col.add(s)
            if extras:
                _extras(msg, dec, col)
    else:
        bad_crc, skipped, truncated = _read_frame_by_frame(buf, wanted, mav, dec, col, extras)
    warnings = []
    if skipped or bad_crc:
        warnings.append(f"{path.name}: corrupted data skipped ({skipped} bytes, {bad_crc} frames failing their CRC)")
    if truncated:
        warnings.append(f"{path.name}: last frame cut off (truncated log): read up to the damage")
    if len(col.sessions) > 1:
        warnings.append(f"{path.name}: the autopilot rebooted {len(col.sessions) - 1} time(s): using the longest boot session")
    cur = max(col.sessions, key=lambda d: len(d["att"]))
    if dec.system_id is None:
        raise LogFormatError(f"{path}: no autopilot HEARTBEAT found: not a MAVLink telemetry log, or empty")
    for key, what in (("cmd", "SERVO_OUTPUT_RAW/ACTUATOR_OUTPUT_STATUS (motor outputs)"), ("att", "ATTITUDE")):
        if not cur[key]:
            raise LogFormatError(f"{path}: no {what} messages from the autopilot: cannot diagnose")
    pos = _stream(cur["pos"])
    height = None if pos is None else Stream(pos.t_us, -(pos.values[:, 2] - pos.values[0, 2]))
    return RawFlight(
        source=str(path),
        cmd_unit="us",
        motor_cmd=_stream(cur["cmd"]),
        attitude_rad=_stream(cur["att"]),
        rates_rad_s=_stream(cur["rate"]),
        battery_v=_stream(cur["bat"]),
        armed=_stream(cur["armed"]),
        landed=_stream(cur["landed"]),
        height_m=height,
        esc_rpm=_stream(cur["esc"]),
        accel_frd_m_s2=col.acceleration(cur),
        vel_ned_m_s=_stream(cur["vel"]),
        pos_ned_m=pos,
        warnings=warnings,
    )


def _read_frame_by_frame(buf: bytes, wanted, mav, dec: md.MavlinkDecoder, col: _Collector, extras: bool):
    """pymavlink ``decode`` per frame; a frame failing its CRC makes the walk resync one byte on."""
    frames = iter_frames(buf, wanted)
    bad_crc, skipped, truncated = 0, 0, False
    try:
        _, frame = next(frames)
        while True:
            try:
                msg = mav.decode(bytearray(frame))
            except Exception:  # pymavlink raises MAVError on a CRC or length mismatch
                bad_crc += 1
                _, frame = frames.send(False)
                continue
            for s in dec.decode(msg):
                col.add(s)
            if extras:
                _extras(msg, dec, col)
            _, frame = frames.send(True)
    except StopIteration as stop:
        skipped, truncated = stop.value or (0, False)
    return bad_crc, skipped, truncated


def _extras(msg, dec: md.MavlinkDecoder, col: _Collector) -> None:
    """Position for calibration (height, waypoints); velocity and the accelerometer come from the decoder."""
    if msg.get_type() != "LOCAL_POSITION_NED" or msg.get_srcSystem() != dec.system_id:
        return
    col.sessions[-1]["pos"].append((int(msg.time_boot_ms) * US_PER_MS, (msg.x, msg.y, msg.z)))
