"""MAVLink 2 signing checked in the order the protocol intends: the signature first, then the timestamp.

pymavlink's own check records a sender's timestamp before it compares the
signature, so one forged frame with a far-future timestamp made every genuine
frame "old" for the rest of the flight. Here nothing about a frame is believed
before its signature verifies with our key:

1. the frame is MAVLink 2 and signed (else refused: ``unsigned``);
2. SHA-256(key + frame without the 6 signature bytes)[:6] matches (else ``bad signature``);
3. the timestamp (10 µs units since 2015-01-01) is newer than the last verified one of its stream, a
   stream being (link id, system id, component id) (else ``replayed``);
4. the timestamp is at most the stream's last verified timestamp plus the monotonic time elapsed since
   it was verified, plus ``FUTURE_SLACK_S`` (else ``timestamp ahead``): companion boards often have no
   real-time clock, so the bound comes from what was verified, never from our own date. A new stream is
   bounded the same way by the newest verified stream; the very first verified frame sets the reference.

A sender whose signing clock truly jumps forward (GPS time arrives at the autopilot) keeps signing
correctly: its frames, each verified, that stay consistent with the jumped clock for ``REANCHOR_S``
of monotonic time re-anchor the stream (``jumps`` counts it). A forger without the key cannot do that.

Only verified streams are remembered (bounded by ``MAX_STREAMS``, oldest dropped), so frames without the
key cannot grow the state.
"""

from __future__ import annotations

import hashlib
import time
from collections import Counter, OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

MAVLINK2_MAGIC = 0xFD
IFLAG_SIGNED = 0x01
SIGNATURE_BLOCK = 13  # link id (1) + timestamp (6) + signature (6)
HEADER_V2 = 10
TIMESTAMP_UNITS_PER_S = 100_000  # MAVLink signing timestamps count 10 µs
# Headroom above the verified clock: a sender adds one unit per frame on top of its clock (100 frames/s is
# 1 ms/s), and the MAVLink signing spec accepts a new stream up to one minute behind; a minute either way.
FUTURE_SLACK_S = 60.0
NEW_STREAM_BEHIND_S = 60.0  # the MAVLink spec's window for a stream not seen before
REANCHOR_S = 2.0  # verified frames consistent with a jumped signing clock for this long re-anchor the stream
MAX_STREAMS = 256
REFUSALS = ("unsigned", "bad signature", "replayed", "timestamp ahead", "stale new stream")


@dataclass
class _Stream:
    timestamp: int  # last verified, 10 µs units
    at_s: float  # monotonic time it was verified


@dataclass
class _Jump:
    first: int
    first_at_s: float
    last: int


def signature_ok(key: bytes, frame: bytes) -> bool:
    return hashlib.sha256(key + frame[:-6]).digest()[:6] == frame[-6:]


def is_signed_v2(frame: bytes) -> bool:
    return len(frame) >= HEADER_V2 + 2 + SIGNATURE_BLOCK and frame[0] == MAVLINK2_MAGIC and bool(frame[2] & IFLAG_SIGNED)


class SignatureGate:
    """Verifies each incoming frame; ``check`` returns '' when accepted, else the refusal (one of ``REFUSALS``)."""

    def __init__(self, key: bytes, clock: Callable[[], float] = time.monotonic, max_streams: int = MAX_STREAMS):
        self.key = bytes(key)
        self.clock = clock
        self.max_streams = max_streams
        self.streams: OrderedDict[tuple[int, int, int], _Stream] = OrderedDict()
        self._jumps: dict[tuple[int, int, int], _Jump] = {}
        self.accepted = 0
        self.refused: Counter = Counter()
        self.jumps = 0  # streams re-anchored after a consistent forward jump of their signing clock

    def newest(self, now_s: float) -> float | None:
        """The newest verified timestamp extrapolated to ``now_s`` (10 µs units), None before any."""
        if not self.streams:
            return None
        return max(s.timestamp + (now_s - s.at_s) * TIMESTAMP_UNITS_PER_S for s in self.streams.values())

    def check(self, frame: bytes, sys_id: int, comp_id: int) -> str:
        reason = self._check(bytes(frame), sys_id, comp_id)
        if reason:
            self.refused[reason] += 1
        else:
            self.accepted += 1
        return reason

    def _check(self, frame: bytes, sys_id: int, comp_id: int) -> str:
        if not is_signed_v2(frame):
            return "unsigned"
        if not signature_ok(self.key, frame):
            return "bad signature"
        stamp = int.from_bytes(frame[-12:-6], "little")
        key = (frame[-13], sys_id, comp_id)
        now = self.clock()
        slack = FUTURE_SLACK_S * TIMESTAMP_UNITS_PER_S
        stream = self.streams.get(key)
        if stream is not None:
            if stamp <= stream.timestamp:
                return "replayed"
            ceiling = stream.timestamp + (now - stream.at_s) * TIMESTAMP_UNITS_PER_S + slack
        else:
            ref = self.newest(now)
            if ref is not None and stamp < ref - NEW_STREAM_BEHIND_S * TIMESTAMP_UNITS_PER_S:
                return "stale new stream"
            ceiling = None if ref is None else ref + slack
        if ceiling is not None and stamp > ceiling and not self._jumped(key, stamp, now):
            return "timestamp ahead"
        self._jumps.pop(key, None)
        self.streams[key] = _Stream(stamp, now)
        self.streams.move_to_end(key)
        while len(self.streams) > self.max_streams:
            self.streams.popitem(last=False)
        return ""

    def _jumped(self, key: tuple[int, int, int], stamp: int, now: float) -> bool:
        """A verified frame ahead of the bound: True once the stream has kept to its new clock for REANCHOR_S."""
        j = self._jumps.get(key)
        if j is not None:
            consistent = j.last < stamp <= j.first + (now - j.first_at_s + FUTURE_SLACK_S) * TIMESTAMP_UNITS_PER_S
            if consistent:
                j.last = stamp
                if now - j.first_at_s >= REANCHOR_S:
                    self.jumps += 1
                    return True
                return False
        if len(self._jumps) >= self.max_streams:
            self._jumps.clear()
        self._jumps[key] = _Jump(stamp, now, stamp)
        return False
