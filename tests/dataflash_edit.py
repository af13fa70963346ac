"""Rewrite an ArduPilot DataFlash ``.bin`` log message by message, for tests that need a real log altered.

A DataFlash log is a chain of messages ``A3 95 <type> <payload>``; FMT messages (type 128) give each type's
name, total length and field formats. ``messages`` splits a file along that chain, ``pack`` builds a new message
of a type the file defines, ``message_time_us`` reads a message's leading TimeUS/TimeMS, and ``write`` joins
them back. Only the few field kinds these tests write are packed (numbers and fixed-width names).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

HEAD = b"\xa3\x95"
FMT_TYPE = 128
# DataFlash format characters -> struct codes (AP_Logger/LogStructure.h), the ones these logs use.
STRUCT = {
    "b": "b", "B": "B", "h": "h", "H": "H", "i": "i", "I": "I", "f": "f", "d": "d", "q": "q", "Q": "Q",
    "n": "4s", "N": "16s", "Z": "64s", "c": "h", "C": "H", "e": "i", "E": "I", "L": "i", "M": "B",
    "a": "64s",
}  # fmt: skip


@dataclass(frozen=True)
class Format:
    type_id: int
    length: int  # bytes, header included
    name: str
    fmt: str
    columns: tuple[str, ...]

    @property
    def struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(STRUCT[c] for c in self.fmt))


@dataclass(frozen=True)
class Message:
    type_id: int
    data: bytes  # the whole message, header included


def messages(path: str | Path) -> tuple[list[Message], dict[int, Format]]:
    """The file's messages in order and the formats its FMT messages define (a clean, whole log expected)."""
    data = Path(path).read_bytes()
    formats = {FMT_TYPE: Format(FMT_TYPE, 89, "FMT", "BBnNZ", ("Type", "Length", "Name", "Format", "Columns"))}
    out, p = [], 0
    while p + 3 <= len(data):
        if data[p : p + 2] != HEAD or data[p + 2] not in formats:
            raise ValueError(f"{path}: no message header at byte {p}")
        f = formats[data[p + 2]]
        msg = Message(f.type_id, data[p : p + f.length])
        if f.type_id == FMT_TYPE:
            typ, length, name, fmt, cols = f.struct.unpack(msg.data[3:])
            formats[typ] = Format(typ, length, _text(name), _text(fmt), tuple(_text(cols).split(",")))
        out.append(msg)
        p += f.length
    return out, formats


def by_name(formats: dict[int, Format], name: str) -> Format:
    return next(f for f in formats.values() if f.name == name)


def fields(msg: Message, formats: dict[int, Format]) -> dict:
    f = formats[msg.type_id]
    return dict(zip(f.columns, f.struct.unpack(msg.data[3:]), strict=True))


def message_time_us(msg: Message, formats: dict[int, Format]) -> int | None:
    f = formats[msg.type_id]
    if not f.columns or f.columns[0] not in ("TimeUS", "TimeMS"):
        return None
    t = struct.unpack_from("<" + STRUCT[f.fmt[0]], msg.data, 3)[0]
    return int(t) if f.columns[0] == "TimeUS" else int(t) * 1000


def pack(f: Format, values: dict) -> Message:
    """A message of format ``f``; ``values`` by column name (text as str), every column given."""
    vals = [values[c].encode() if isinstance(values[c], str) else values[c] for c in f.columns]
    return Message(f.type_id, HEAD + bytes([f.type_id]) + f.struct.pack(*vals))


def write(path: str | Path, msgs: list[Message]) -> Path:
    Path(path).write_bytes(b"".join(m.data for m in msgs))
    return Path(path)


def _text(b: bytes) -> str:
    return b.split(b"\0", 1)[0].decode("ascii", "replace")
