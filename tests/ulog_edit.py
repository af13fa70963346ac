"""Rewrite a PX4 ULog's data messages topic by topic, for tests that need a real log altered.

A ULog is a 16-byte header and then messages ``uint16 size, uint8 type, payload``. A topic is
subscribed by an ``A`` message (``uint8 multi_id, uint16 msg_id, name``) and logged as ``D`` messages
(``uint16 msg_id, fields``). ``rewrite`` keeps or drops each subscription and each data sample; every
other message (formats, parameters, log text) is copied as it is.
"""

from __future__ import annotations

import struct
from collections import Counter
from collections.abc import Callable
from pathlib import Path

HEADER_BYTES = 16
MSG_HEADER = struct.Struct("<HB")
ADD_LOGGED, DATA, PARAMETER = ord("A"), ord("D"), ord("P")


def rewrite(src: str | Path, dst: str | Path, keep: Callable[[str, int], bool], params: dict[str, float] | None = None) -> Path:
    """Copy ``src`` to ``dst`` keeping the data samples for which ``keep(topic, k)`` is true (``k``: the
    sample's index in its topic instance); a topic none of whose samples is kept loses its subscription too.
    ``params``: new values for parameters the log holds (float or int32, as logged)."""
    data = Path(src).read_bytes()
    names: dict[int, str] = {}
    subscriptions: dict[int, bytes] = {}
    kept: dict[int, bool] = {}
    count: Counter[int] = Counter()
    out = [data[:HEADER_BYTES]]
    body: list[tuple[int | None, bytes]] = []  # (msg_id of an A message or None, bytes)
    p = HEADER_BYTES
    while p + MSG_HEADER.size <= len(data):
        size, kind = MSG_HEADER.unpack_from(data, p)
        msg = data[p : p + MSG_HEADER.size + size]
        p += MSG_HEADER.size + size
        payload = msg[MSG_HEADER.size :]
        if kind == PARAMETER and params:
            msg = _set_parameter(msg, params)
        if kind == ADD_LOGGED:
            msg_id = struct.unpack_from("<H", payload, 1)[0]
            names[msg_id] = payload[3:].decode("ascii", "replace")
            subscriptions[msg_id] = msg
            body.append((msg_id, msg))
            continue
        if kind == DATA:
            msg_id = struct.unpack_from("<H", payload)[0]
            k = count[msg_id]
            count[msg_id] += 1
            if not keep(names[msg_id], k):
                continue
            kept[msg_id] = True
        body.append((None, msg))
    out += [msg for msg_id, msg in body if msg_id is None or kept.get(msg_id)]
    Path(dst).write_bytes(b"".join(out) + data[p:])
    return Path(dst)


def decimate(src: str | Path, dst: str | Path, topic: str, every: int) -> Path:
    """Keep one ``topic`` sample in ``every``."""
    return rewrite(src, dst, lambda name, k: name != topic or k % every == 0)


def _set_parameter(msg: bytes, params: dict[str, float]) -> bytes:
    """A ``P`` message (``uint8 key_len, "type name", value``) with its value from ``params`` where named there."""
    n = msg[MSG_HEADER.size]
    key = msg[MSG_HEADER.size + 1 : MSG_HEADER.size + 1 + n].decode("ascii")
    kind, name = key.split(" ", 1)
    if name not in params:
        return msg
    value = struct.pack("<f", params[name]) if kind == "float" else struct.pack("<i", int(params[name]))
    return msg[: MSG_HEADER.size + 1 + n] + value


def drop_topics(src: str | Path, dst: str | Path, topics: set[str]) -> Path:
    return rewrite(src, dst, lambda name, _k: name not in topics)
