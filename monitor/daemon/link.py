"""The MAVLink link: open any pymavlink URL, read messages with their arrival time, send ours.

What we send is limited by construction to HEARTBEAT, STATUSTEXT,
NAMED_VALUE_FLOAT and COMMAND_LONG(MAV_CMD_SET_MESSAGE_INTERVAL): there is no
method here that could send anything that changes the flight.

URLs: ``udpin:HOST:PORT``, ``udpout:HOST:PORT``, ``tcp:HOST:PORT``, a serial
device with its baud rate (``/dev/ttyAMA0,921600``), or a ``.tlog`` file
(played at its recorded pace times ``tlog_speed``; 0 = as fast as it reads).
On ``udpin`` one read takes every datagram waiting (bounded), each with the
kernel's arrival stamp where Linux gives one, so the loop can sleep between
grid steps (``monitor.daemon.pacing``) without hiding the wait from the latency.

Trust (``LinkGuard``): with a signing key, pymavlink's MAVLink 2 signing
verifies every incoming frame (unsigned, MAVLink 1 and badly signed frames
come out as bad data) and signs everything we send. Source allow-lists by
address and by SYSID/COMPID drop the rest, counted. On ``udpin`` nothing is
sent before the autopilot is known, then only to the address its HEARTBEAT
came from; other senders are remembered in a bounded list for the report,
never answered.
"""

from __future__ import annotations

import logging
import os
import select
import socket
import struct
import sys
import time
from collections import Counter, OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")  # ESC_STATUS (id 291) exists only in MAVLink 2 frames
os.environ.setdefault("MAVLINK_DIALECT", "common")  # mavutil's default 'all' costs ~1 s of start-up

from pymavlink import mavutil  # noqa: E402

from monitor.errors import ConfigError  # noqa: E402
from monitor.resample import US_PER_S  # noqa: E402

log = logging.getLogger("propwatch.monitor.link")

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
MAV_STATE_ACTIVE = 4
NAMED_VALUE_MAX_CHARS = 10
LOG_SUFFIXES = (".tlog", ".mavlink")
REOPEN_PERIOD_S = 1.0
UDP_MAX_PACKET = 65535
SIGNING_KEY_BYTES = 32
MAX_SIGNING_STREAMS = 256  # pymavlink keeps one timestamp per (link, sys, comp) it ever saw: keep it bounded
MAX_DATAGRAMS_PER_READ = 256  # a read drains the socket, within bounds (PX4 sends ~100 a second)
# Kernel receive stamps (struct timespec on CLOCK_REALTIME), Linux only; Python's socket module does not name
# the option. 35 = SO_TIMESTAMPNS (asm-generic: x86, arm, arm64, riscv); SCM_TIMESTAMPNS is the same number.
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
_TIMESPEC = struct.Struct("@ll")
_ANC_BUFSIZE = socket.CMSG_SPACE(_TIMESPEC.size)
NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class LinkGuard:
    """Who is trusted: a signing key (32 bytes) and allow-lists; the defaults trust everyone, as before."""

    signing_key: bytes | None = None
    signing_link_id: int = 1
    allow_addresses: tuple[tuple[str, int | None], ...] = ()  # (host, port or None = any)
    allow_sources: tuple[tuple[int | None, int | None], ...] = ()  # (sysid, compid), None = any
    max_peers: int = 8

    def address_ok(self, addr: tuple[str, int]) -> bool:
        return not self.allow_addresses or any(h == addr[0] and p in (None, addr[1]) for h, p in self.allow_addresses)

    def source_ok(self, sys_id: int, comp_id: int) -> bool:
        return not self.allow_sources or any(s in (None, sys_id) and c in (None, comp_id) for s, c in self.allow_sources)


def read_signing_key(path: str | Path) -> bytes:
    """A key file holds the 32-byte secret: raw bytes, or 64 hex digits (whitespace ignored)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the signing key: {exc.strerror or exc}") from None
    if len(raw) == SIGNING_KEY_BYTES:
        return raw
    try:
        key = bytes.fromhex(raw.decode("ascii").strip())
    except (UnicodeDecodeError, ValueError):
        key = b""
    if len(key) != SIGNING_KEY_BYTES:
        raise ConfigError(f"{path}: a signing key is 32 raw bytes or 64 hex digits, got {len(raw)} bytes")
    return key


def split_serial(url: str) -> tuple[str, int | None]:
    """``/dev/ttyAMA0,921600`` -> (device, baud); anything else -> (url, None)."""
    if "," in url and ":" not in url.split(",", 1)[0]:
        device, baud = url.rsplit(",", 1)
        try:
            return device, int(baud)
        except ValueError:
            raise ConfigError(f"--connect {url}: baud rate {baud!r} is not an integer") from None
    return url, None


class Link:
    def __init__(
        self,
        url: str,
        component_id: int,
        tlog_speed: float = 1.0,
        system_id: int | None = None,
        guard: LinkGuard | None = None,
    ):
        self.url = url
        self.component_id = component_id
        self.is_log = url.lower().endswith(LOG_SUFFIXES)
        self.is_tcp = url.startswith("tcp:")
        self.is_udpout = url.startswith("udpout:")
        self.tlog_speed = tlog_speed
        self.conn: Any = None
        self.bytes_in = 0
        self._pace: tuple[float, float] | None = None  # (first log time, monotonic start)
        self.eof = False
        self._pending: Any = None
        self._system_id = system_id
        self._next_open = 0.0
        self._open_failures = 0
        self.guard = guard or LinkGuard()
        self.is_udpin = url.startswith(("udpin:", "udp:"))
        self.peers: OrderedDict[tuple[str, int], int] = OrderedDict()  # udpin senders, bounded, for the report
        self.rejected: Counter = Counter()  # why frames/datagrams were dropped
        self._origin: dict[int, tuple[str, int]] = {}  # id(message) -> sender address, for the last udpin read
        self.drained = True  # the last read left nothing waiting
        self._autopilot_addr: tuple[str, int] | None = None
        self._signing: Any = None
        if self.is_log:
            self.open()
        else:
            self._try_open()

    # -- connection ------------------------------------------------------------
    def open(self) -> None:
        """Open once, without blocking retries: a live link that is not there yet is retried by ``read``."""
        device, baud = split_serial(self.url)
        if self.is_log and not os.path.isfile(device):
            raise ConfigError(f"--connect {self.url}: log file not found")
        try:
            self.conn = mavutil.mavlink_connection(
                device,
                baud=baud or 115200,
                source_system=self._system_id or 1,
                source_component=self.component_id,
                dialect="common",
                robust_parsing=True,
                autoreconnect=False,
                retries=0,
            )
        except ValueError as exc:
            raise ConfigError(f"--connect {self.url}: {exc}") from exc
        if not self.is_log:
            self.conn.mav.robust_parsing = True
            if self.guard.signing_key is not None:
                self.conn.setup_signing(
                    self.guard.signing_key, sign_outgoing=True, allow_unsigned_callback=None, link_id=self.guard.signing_link_id
                )
                self._signing = self.conn.mav.signing  # its counters outlive a reopen's connection
            if self.is_udpin:
                _stamp_arrivals(self.conn.port)
                self.conn.clients = set()  # replies go to the autopilot's address only, once it is known
                if self._autopilot_addr is not None:
                    self.conn.clients.add(self._autopilot_addr)
        elif self.guard.signing_key is not None:
            log.warning("%s: a recorded log is read without signature checks (its timestamps are in the past)", self.url)
        log.info("link open: %s%s", self.url, " (MAVLink 2 signing on)" if self.guard.signing_key else "")

    def _try_open(self) -> None:
        try:
            self.open()
            self._open_failures = 0
        except OSError as exc:  # no peer yet, serial device absent: keep trying, the loop stays alive
            self.conn = None
            self._next_open = time.monotonic() + REOPEN_PERIOD_S
            if self._open_failures % 60 == 0:  # once a minute is enough for the journal
                log.error("cannot open %s: %s; retrying every %.0f s", self.url, exc, REOPEN_PERIOD_S)
            self._open_failures += 1

    def close(self) -> None:
        """Close; a live link reopens on a later ``read`` after ``REOPEN_PERIOD_S``."""
        if self.conn is not None:
            try:
                self.conn.close()
            except (OSError, AttributeError):  # pymavlink's TCP close fails on a socket already gone
                pass
            self.conn = None
            self._next_open = time.monotonic() + REOPEN_PERIOD_S

    def set_system_id(self, system_id: int) -> None:
        """We speak as a component of the vehicle we monitor."""
        self._system_id = system_id
        if self.conn is None:
            return
        self.conn.mav.srcSystem = system_id
        self.conn.mav.srcComponent = self.component_id

    # -- reading ---------------------------------------------------------------
    def read(self, timeout_s: float) -> list[tuple[Any, float, float]]:
        """Messages available within ``timeout_s``: (message, arrival, read) times on the perf_counter clock.

        On ``udpin`` every datagram waiting is read (up to ``MAX_DATAGRAMS_PER_READ``; ``drained`` says
        whether that left the socket empty), and the arrival is the kernel's receive stamp where it gives
        one (SO_TIMESTAMPNS, Linux): the time a datagram waited in the socket counts in the latency.
        Elsewhere the arrival is the read."""
        self.drained = True
        if self.is_log:
            return [(m, t, t) for m, t in self._read_log(timeout_s)]
        if self.conn is None and time.monotonic() >= self._next_open:
            self._try_open()
        if self.conn is None:
            time.sleep(timeout_s)
            return []
        fd = self.conn.fd
        if fd is None:
            time.sleep(timeout_s)
            return []
        ready, _, _ = select.select([fd], [], [], timeout_s)
        if not ready:
            return []
        if self.is_udpin:
            return self._read_datagrams()
        data = self.conn.recv(4096)
        received = time.perf_counter()
        if not data:
            if self.is_tcp:  # readable and empty: the peer closed the connection
                raise ConnectionError(f"{self.url}: connection closed by the peer")
            return []
        return [(m, received, received) for m in self._parse(data)]

    def _read_datagrams(self) -> list[tuple[Any, float, float]]:
        """Every datagram waiting on the udpin socket, in order; the sender's address is checked and never
        added as a peer (our own recvmsg, not pymavlink's)."""
        port = self.conn.port
        out: list[tuple[Any, float, float]] = []
        self._origin = {}
        for _ in range(MAX_DATAGRAMS_PER_READ):
            try:
                data, anc, _flags, addr = port.recvmsg(UDP_MAX_PACKET, _ANC_BUFSIZE)
            except (BlockingIOError, InterruptedError):
                return out
            read_s = time.perf_counter()
            received = read_s - _queued_s(anc, time.time_ns())
            if not self.guard.address_ok(addr):
                self.rejected["address not allowed"] += 1
                continue
            self.peers[addr] = self.peers.pop(addr, 0) + 1
            while len(self.peers) > self.guard.max_peers:
                self.peers.popitem(last=False)
                self.rejected["peers forgotten"] += 1
            if not data:
                continue
            for m in self._parse(data):
                self._origin[id(m)] = addr
                out.append((m, received, read_s))
        self.drained = False
        return out

    def _parse(self, data: bytes) -> list[Any]:
        """The messages in ``data`` (BAD_DATA for what does not parse), signature and source checks applied."""
        self.bytes_in += len(data)
        if self.conn.first_byte:
            self.conn.auto_mavlink_version(data)
        try:
            msgs = self.conn.mav.parse_buffer(data) or []
        except Exception as exc:  # noqa: BLE001 - pymavlink raises MAVError and struct errors on garbage
            log.debug("parse error: %s", exc)
            return [_BadData(str(exc))]
        if self._signing is not None:
            self.rejected["invalid or missing signature"] += sum(
                1 for m in msgs if m.get_type() == "BAD_DATA" and "signature" in str(getattr(m, "reason", ""))
            )
            if len(self._signing.stream_timestamps) > MAX_SIGNING_STREAMS:
                self._prune_signing_streams()
        if self.guard.allow_sources:
            kept = [
                m for m in msgs if m.get_type() == "BAD_DATA" or self.guard.source_ok(m.get_srcSystem(), m.get_srcComponent())
            ]
            self.rejected["source not allowed"] += len(msgs) - len(kept)
            msgs = kept
        return msgs

    def autopilot_seen(self, msg: Any = None) -> None:
        """``msg`` is the autopilot's HEARTBEAT: udpin answers the address it came from, and only that one."""
        addr = self._origin.get(id(msg))
        if not self.is_udpin or self.conn is None or addr is None:
            return
        if addr != self._autopilot_addr:
            if self._autopilot_addr is not None:
                log.warning("autopilot now at %s:%d (was %s:%d)", *addr, *self._autopilot_addr)
            self._autopilot_addr = addr
            self.conn.clients = {addr}
            self.conn.clients_last_alive = {}

    def _prune_signing_streams(self) -> None:
        """pymavlink records a timestamp for every (link, sys, comp) that sent a signed-looking frame,
        valid or not: keep the autopilot's (replay protection) and forget the rest."""
        keep = self._system_id
        ts = self._signing.stream_timestamps
        self._signing.stream_timestamps = {k: v for k, v in ts.items() if k[1] == keep}
        self.rejected["signing streams forgotten"] += len(ts) - len(self._signing.stream_timestamps)

    def stats(self) -> dict:
        out: dict[str, Any] = {"rejected": dict(self.rejected), "peers_remembered": len(self.peers)}
        signing = self._signing
        if signing is not None:
            out["signing"] = {
                "good": signing.goodsig_count,
                "bad": signing.badsig_count,
                "refused": self.rejected["invalid or missing signature"],
            }
        if self._autopilot_addr is not None:
            out["autopilot_address"] = f"{self._autopilot_addr[0]}:{self._autopilot_addr[1]}"
        return out

    def _read_log(self, timeout_s: float) -> list[tuple[Any, float]]:
        if self._pending is None:
            if self.eof:
                time.sleep(timeout_s)
                return []
            try:
                m = self.conn.recv_msg()
            except Exception as exc:  # noqa: BLE001 - a corrupt log must not kill the reader
                return [(_BadData(str(exc)), time.perf_counter())]
            if m is None:
                self.eof = True
                return []
            self._pending = m
        m = self._pending
        if self.tlog_speed > 0:
            t_log = float(getattr(m, "_timestamp", 0.0))
            if self._pace is None:
                self._pace = (t_log, time.monotonic())
            delay = self._pace[1] + (t_log - self._pace[0]) / self.tlog_speed - time.monotonic()
            if delay > 0:
                time.sleep(min(delay, timeout_s))
                if delay > timeout_s:
                    return []
        self._pending = None
        return [(m, time.perf_counter())]

    # -- sending (the complete list of what we ever send) ---------------------
    def _send(self, encode: Callable[[Any], Any]) -> None:
        """``encode(mav)`` builds the message; nothing is sent to a log or while the link is down."""
        if self.is_log or self.conn is None:
            return
        try:
            self.conn.mav.send(encode(self.conn.mav))
        except OSError as exc:
            log.warning("send failed: %s", exc)

    def send_heartbeat(self) -> None:
        self._send(lambda mav: mav.heartbeat_encode(MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, MAV_STATE_ACTIVE))

    def send_statustext(self, text: str, severity: int) -> None:
        self._send(lambda mav: mav.statustext_encode(severity, text[:50].encode("ascii", "replace")))

    def send_named_value_float(self, time_boot_ms: int, name: str, value: float) -> None:
        self._send(
            lambda mav: mav.named_value_float_encode(
                int(time_boot_ms) & 0xFFFFFFFF, name[:NAMED_VALUE_MAX_CHARS].encode(), float(value)
            )
        )

    def request_message_interval(self, target_system: int, target_component: int, message_id: int, rate_hz: float) -> None:
        interval_us = int(round(US_PER_S / rate_hz))
        self._send(
            lambda mav: mav.command_long_encode(
                target_system,
                target_component,
                MAV_CMD_SET_MESSAGE_INTERVAL,
                0,
                float(message_id),
                float(interval_us),
                0,
                0,
                0,
                0,
                0,
            )
        )


def _stamp_arrivals(sock: socket.socket) -> None:
    """Ask the kernel to stamp each datagram's arrival (Linux); elsewhere the arrival is the read."""
    if not sys.platform.startswith("linux"):
        return
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError as exc:
        log.info("no kernel receive stamps (%s): latency is measured from the read", exc)


def _queued_s(ancillary: list[tuple[int, int, bytes]], now_ns: int) -> float:
    """How long a datagram waited in the socket, from its kernel stamp (0 without one, or for a clock step)."""
    for level, kind, payload in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(payload) >= _TIMESPEC.size:
            sec, nsec = _TIMESPEC.unpack_from(payload)
            return max(0, now_ns - (sec * NS_PER_S + nsec)) / NS_PER_S
    return 0.0


class _BadData:
    """Stands for bytes that did not parse, so the caller can count and report them."""

    def __init__(self, reason: str):
        self.reason = reason

    def get_type(self) -> str:
        return "BAD_DATA"
