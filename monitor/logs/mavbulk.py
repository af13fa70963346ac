"""Whole-file unpacking of MAVLink frames into message objects for ``MavlinkDecoder``.

pymavlink's ``decode`` costs ~12 µs per message in Python (CRC byte by byte,
generic field handling); a 30-minute tlog has ~200 000 messages propwatch
needs. Here the frames of each (message id, version, payload length) are
CRC-checked and unpacked together with numpy, from pymavlink's own message
definitions (wire field order, types, array lengths, CRC extra), and handed
on, in file order, as small tuples with the same attributes and the
``get_type`` / ``get_srcSystem`` / ``get_srcComponent`` methods the shared
decoder reads. Meaning (which system, boot clock, unknown values) stays with
``monitor.mavlink.decode``; only the byte unpacking is done in bulk.

Anything unusual (bytes skipped while walking, a CRC that fails, an id
pymavlink does not know) makes ``unpack_frames`` return None, and the reader
falls back to pymavlink frame by frame.
"""

from __future__ import annotations

import collections
import functools
from dataclasses import dataclass

import numpy as np

V2_MAGIC = 0xFD
V1_HEADER, V2_HEADER = 6, 10
X25_INIT = 0xFFFF
# struct format character -> numpy little-endian type (pymavlink's native_format)
NP_TYPE = {
    "B": "u1",
    "b": "i1",
    "H": "u2",
    "h": "i2",
    "I": "u4",
    "i": "i4",
    "Q": "u8",
    "q": "i8",
    "f": "f4",
    "d": "f8",
    "c": "S1",
    "s": "S1",
}


@functools.cache
def message_class(name: str, fields: tuple[str, ...]) -> type:
    """A tuple type per message: the fields as attributes, plus the methods the decoder calls."""
    base = collections.namedtuple(name, fields + ("src_system_", "src_component_"))

    class Message(base):
        __slots__ = ()

        def get_type(self) -> str:
            return name

        def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's name
            return self.src_system_

        def get_srcComponent(self) -> int:  # noqa: N802 - pymavlink's name
            return self.src_component_

    Message.__name__ = f"Bulk_{name}"
    return Message


def _dtype(cls) -> np.dtype:
    fmt = cls.native_format.decode() if isinstance(cls.native_format, (bytes, bytearray)) else cls.native_format
    chars = fmt[1:]
    fields = []
    for name, ch, n in zip(cls.ordered_fieldnames, chars, cls.array_lengths):
        t = NP_TYPE[ch]
        if t == "S1":
            fields.append((name, f"S{max(n, 1)}"))
        else:
            fields.append((name, "<" + t, (n,)) if n else (name, "<" + t))
    dt = np.dtype(fields)
    if dt.itemsize != cls.unpacker.size:
        raise ValueError(f"{cls.msgname}: numpy layout {dt.itemsize} B != struct {cls.unpacker.size} B")
    return dt


def x25_crc(rows: np.ndarray, extra: int) -> np.ndarray:
    """MAVLink's X.25 CRC of each row of bytes (N, M), then the message's CRC extra byte.

    Byte-wide and 16-bit arithmetic, in place: the shifts wrap where the CRC's masks (& 0xFF, & 0xFFFF) cut."""
    n = len(rows)
    crc = np.full(n, X25_INIT, dtype=np.uint16)
    tmp = np.empty(n, dtype=np.uint8)
    t16 = np.empty(n, dtype=np.uint16)
    shifted = np.empty(n, dtype=np.uint16)
    for b in [*np.ascontiguousarray(rows.T), np.full(n, extra, dtype=np.uint8)]:
        np.bitwise_xor(b, crc, out=tmp, casting="unsafe")  # b ^ (crc & 0xFF)
        tmp ^= tmp << 4
        t16[:] = tmp
        crc >>= 8
        np.left_shift(t16, 8, out=shifted)
        crc ^= shifted
        np.left_shift(t16, 3, out=shifted)
        crc ^= shifted
        t16 >>= 4
        crc ^= t16
    return crc


@dataclass(frozen=True)
class Group:
    """The frames of one (message id, version, payload length), CRC-checked and unpacked together."""

    cls: type  # pymavlink's message class
    rows: np.ndarray  # (n,) their indices in ``starts`` (file order)
    values: np.ndarray  # (n,) structured: pymavlink's fields in wire order (a short v2 payload zero-filled)
    sys_id: np.ndarray  # (n,) sender system id
    comp_id: np.ndarray  # (n,) sender component id


def unpack_groups(buf: bytes, starts: np.ndarray, mavlink_map: dict) -> list[Group] | None:
    """The frames starting at ``starts`` (offsets of the magic byte), grouped; None on any CRC failure or unknown id."""
    data = np.frombuffer(buf, dtype=np.uint8)
    p = np.asarray(starts, dtype=np.int64)
    v2 = data[p] == V2_MAGIC
    plen = data[p + 1].astype(np.int64)
    msgid = np.where(
        v2,
        data[p + 7].astype(np.int64)
        | (data[p + 8].astype(np.int64) << 8)
        | (data[np.minimum(p + 9, len(data) - 1)].astype(np.int64) << 16),
        data[p + 5],
    )
    sys_id = np.where(v2, data[p + 5], data[p + 3])
    comp_id = np.where(v2, data[p + 6], data[p + 4])
    groups = []
    key = (msgid << 10) | (v2.astype(np.int64) << 9) | plen
    for k in np.unique(key):
        rows = np.flatnonzero(key == k)
        mid, is_v2, n = int(k >> 10), bool((k >> 9) & 1), int(k & 0x1FF)
        cls = mavlink_map.get(mid)
        if cls is None:
            return None
        h = V2_HEADER if is_v2 else V1_HEADER
        frame = np.lib.stride_tricks.sliding_window_view(data, h + n + 2)[p[rows]]  # (rows, frame bytes), copied
        stored = frame[:, h + n].astype(np.uint32) | (frame[:, h + n + 1].astype(np.uint32) << 8)
        if np.any(x25_crc(frame[:, 1 : h + n], cls.crc_extra) != stored):
            return None
        dt = _dtype(cls)
        payload = np.zeros((len(rows), dt.itemsize), dtype=np.uint8)
        m = min(n, dt.itemsize)
        payload[:, :m] = frame[:, h : h + m]
        groups.append(Group(cls, rows, payload.view(dt).reshape(len(rows)), sys_id[rows], comp_id[rows]))
    return groups


def messages(groups: list[Group], n: int) -> list:
    """Message objects for ``n`` frames' groups, in file order (a frame in no group stays None)."""
    out: list = [None] * n
    for g in groups:
        make = message_class(g.cls.msgname, tuple(g.values.dtype.names))
        for r, vals, s, c in zip(g.rows.tolist(), g.values.tolist(), g.sys_id.tolist(), g.comp_id.tolist()):
            out[r] = make(*vals, s, c)
    return out


def unpack_frames(buf: bytes, starts: np.ndarray, mavlink_map: dict) -> list | None:
    """Message objects for the frames starting at ``starts`` (offsets of the magic byte), in order."""
    groups = unpack_groups(buf, starts, mavlink_map)
    return None if groups is None else messages(groups, len(starts))
