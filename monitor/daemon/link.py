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

Trust (``LinkGuard``, docs/SECURITY.md): with a signing key every incoming
frame is verified by ``monitor.daemon.signing`` (signature first, then its
timestamp, per stream) and everything we send is signed; refused frames are
counted and each (reason, sender) is written to the journal once. Source
allow-lists by address and by SYSID/COMPID drop the rest, counted. The
autopilot is pinned (``monitor.daemon.pin``): its system id is learnt only
from its HEARTBEATs on the pinned link, and on ``udpin`` nothing is sent
before that, then only to the pinned address and the configured ground
stations; the pin never follows a newcomer. ``flight_authenticated`` says
whether every frame the daemon used was verified.
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
from pymavlink.dialects.v20 import common as mavlink2  # noqa: E402

from monitor.daemon.pin import MAX_VEHICLES, PIN_WAIT_S, AutopilotPin, Origin  # noqa: E402
from monitor.daemon.signing import TIMESTAMP_UNITS_PER_S, SignatureGate  # noqa: E402
from monitor.errors import ConfigError  # noqa: E402
from monitor.resample import US_PER_S  # noqa: E402

log = logging.getLogger("propwatch.monitor.link")

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
MAV_STATE_ACTIVE = 4
NAMED_VALUE_MAX_CHARS = 10
LOG_SUFFIXES = (".tlog", ".mavlink")
REOPEN_PERIOD_S = 1.0
UDP_MAX_PACKET = 65535
SIGNING_KEY_BYTES = 32
SIGNING_EPOCH_S = 1420070400  # MAVLink signing timestamps count from 2015-01-01 00:00 UTC
MAX_ANNOUNCED = 64  # (reason, sender) pairs written to the journal once each; beyond that, counted only
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
    autopilot_address: tuple[str, int] | None = None  # udpin: the autopilot's pinned (host, port); None = learnt
    ground_stations: tuple[tuple[str, int], ...] = ()  # (host, port) that also get our HEARTBEAT, STATUSTEXT, values
    autopilot_component_id: int = 1
    pin_wait_s: float = PIN_WAIT_S
    max_vehicles: int = MAX_VEHICLES  # autopilots of distinct system ids pinned at most (monitor.daemon.pin)

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
        self.drained = True  # the last read left nothing waiting
        # Signature checks and the pin apply to a live link; a recorded log is read as it was recorded.
        key = self.guard.signing_key
        self.gate = SignatureGate(key) if key is not None and not self.is_log else None
        self.pin = (
            None
            if self.is_log
            else AutopilotPin(
                system_id,
                self.guard.autopilot_component_id,
                self.guard.autopilot_address,
                self.guard.pin_wait_s,
                one_peer=not self.is_udpin,
                max_vehicles=self.guard.max_vehicles,
            )
        )
        self.unverified_frames = 0  # frames passed on without a verified signature (all of them with signing off)
        self._announced: set[tuple[str, str]] = set()
        self._tx = mavlink2.MAVLink(None, srcSystem=system_id or 1, srcComponent=component_id)
        if key is not None:
            self._tx.signing.secret_key = key
            self._tx.signing.sign_outgoing = True
            self._tx.signing.link_id = self.guard.signing_link_id
            self._tx.signing.timestamp = max(1, int((time.time() - SIGNING_EPOCH_S) * TIMESTAMP_UNITS_PER_S))
        self._gcs_sock: socket.socket | None = None
        if not self.is_log:
            self._warn_if_trusting()
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
            if self.is_udpin:
                _stamp_arrivals(self.conn.port)
                self.conn.clients = set()  # pymavlink sends to no one: ``_write`` sends to the pinned address only
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
        if self._gcs_sock is not None:
            self._gcs_sock.close()
            self._gcs_sock = None
        if self.conn is not None:
            try:
                self.conn.close()
            except (OSError, AttributeError):  # pymavlink's TCP close fails on a socket already gone
                pass
            self.conn = None
            self._next_open = time.monotonic() + REOPEN_PERIOD_S

    def _warn_if_trusting(self) -> None:
        """Once, at start-up: a network link without signing trusts whoever can reach it."""
        if self.gate is not None or not (self.is_udpin or self.is_tcp or self.is_udpout):
            return
        pinned = self.guard.autopilot_address is not None or self.guard.allow_addresses
        log.warning(
            "SECURITY: MAVLink signing is off on %s%s: this configuration TRUSTS THE NETWORK "
            "(set link.signing_key_path%s; docs/SECURITY.md)",
            self.url,
            "" if pinned else " and no autopilot address is pinned: anyone who reaches it can pose as the autopilot",
            "" if pinned else " and link.autopilot_address",
        )

    @property
    def flight_authenticated(self) -> bool:
        """True when signing is on and every frame the daemon was given verified (so far): a flight whose
        evidence may be forged must never become a vehicle's history."""
        return self.gate is not None and self.gate.accepted > 0 and self.unverified_frames == 0

    def set_system_id(self, system_id: int) -> None:
        """We speak as a component of the vehicle we monitor."""
        self._system_id = system_id
        self._tx.srcSystem = system_id
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
            for m in self._parse(data, addr):
                out.append((m, received, read_s))
        self.drained = False
        return out

    def _parse(self, data: bytes, origin: Origin = None) -> list[Any]:
        """The messages in ``data`` (BAD_DATA for what does not parse) that pass the signature, source and pin
        checks; ``origin`` is the udpin sender (None: the link has one peer)."""
        self.bytes_in += len(data)
        if self.conn.first_byte:
            self.conn.auto_mavlink_version(data)
        try:
            msgs = self.conn.mav.parse_buffer(data) or []
        except Exception as exc:  # noqa: BLE001 - pymavlink raises MAVError and struct errors on garbage
            log.debug("parse error: %s", exc)
            return [_BadData(str(exc))]
        out = []
        for m in msgs:
            if m.get_type() == "BAD_DATA":
                out.append(m)
                continue
            sys_id, comp_id = m.get_srcSystem(), m.get_srcComponent()
            if self.gate is not None:
                why = self.gate.check(m.get_msgbuf(), sys_id, comp_id)
                if why:
                    self.rejected["invalid or missing signature"] += 1
                    self._announce(f"{why} frames", origin)
                    continue
            if self.guard.allow_sources and not self.guard.source_ok(sys_id, comp_id):
                self.rejected["source not allowed"] += 1
                continue
            if self.pin is not None and not self.pin.admit(m, origin):
                continue
            if self.gate is None:
                self.unverified_frames += 1
            out.append(m)
        return out

    def _announce(self, what: str, origin: Origin) -> None:
        who = self.url if origin is None else f"{origin[0]}:{origin[1]}"
        if (what, who) in self._announced or len(self._announced) >= MAX_ANNOUNCED:
            return
        self._announced.add((what, who))
        log.warning("%s from %s refused (counted from now on, not logged again)", what, who)

    def autopilot_seen(self, msg: Any = None) -> None:
        """The autopilot's HEARTBEAT: nothing to do, the reply address is the pin's (``monitor.daemon.pin``), and a
        later HEARTBEAT from anywhere never moves it."""

    def stats(self) -> dict:
        out: dict[str, Any] = {
            "rejected": dict(self.rejected),
            "peers_remembered": len(self.peers),
            "unverified_frames": self.unverified_frames,
            "flight_authenticated": self.flight_authenticated,
        }
        if self.gate is not None:
            out["signing"] = {
                "good": self.gate.accepted,
                "refused": dict(self.gate.refused),
                "streams": len(self.gate.streams),
                "clock_jumps": self.gate.jumps,
            }
        if self.pin is not None:
            out["pin"] = {"system_id": self.pin.system_id, "refused": dict(self.pin.refused), "conflict": self.pin.conflict}
            out["pin"]["vehicles"] = {str(k): None if a is None else f"{a[0]}:{a[1]}" for k, a in self.pin.vehicles.items()}
            if self.pin.address is not None:
                out["autopilot_address"] = f"{self.pin.address[0]}:{self.pin.address[1]}"
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
    def _send(self, encode: Callable[[Any], Any], to_ground: bool = True, as_system: int | None = None) -> None:
        """``encode(mav)`` builds the message (signed with a key); it goes to the autopilot and, with ``to_ground``,
        to the configured ground stations. ``as_system``: sent as a component of that vehicle, to its autopilot's
        pinned address (None: the first pinned). Nothing is sent to a log or while the link is down."""
        if self.is_log or self.conn is None:
            return
        tx = self._tx
        tx.srcSystem = (self._system_id or 1) if as_system is None else as_system
        if self.gate is not None:  # MAVLink signing: never sign behind the newest timestamp verified
            ref = self.gate.newest(time.monotonic())
            if ref is not None and ref > tx.signing.timestamp:
                tx.signing.timestamp = int(ref)
        try:
            buf = encode(tx).pack(tx)
            tx.seq = (tx.seq + 1) % 256
            self._write(buf, to_ground, as_system)
        except OSError as exc:
            log.warning("send failed: %s", exc)

    def _write(self, buf: bytes, to_ground: bool, as_system: int | None = None) -> None:
        to = self.pin.address_of(as_system) if self.pin is not None and self.pin.pinned else None
        if not self.is_udpin:
            self.conn.write(buf)
        elif to is not None:
            self.conn.port.sendto(buf, to)
        if not to_ground or not self.guard.ground_stations:
            return
        if self.is_udpin:
            sock = self.conn.port
        else:
            if self._gcs_sock is None:
                self._gcs_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock = self._gcs_sock
        for addr in self.guard.ground_stations:
            sock.sendto(buf, addr)

    def send_heartbeat(self, as_system: int | None = None) -> None:
        hb = (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, MAV_STATE_ACTIVE)
        self._send(lambda mav: mav.heartbeat_encode(*hb), as_system=as_system)

    def send_statustext(self, text: str, severity: int, as_system: int | None = None) -> None:
        self._send(lambda mav: mav.statustext_encode(severity, text[:50].encode("ascii", "replace")), as_system=as_system)

    def send_named_value_float(self, time_boot_ms: int, name: str, value: float, as_system: int | None = None) -> None:
        self._send(
            lambda mav: mav.named_value_float_encode(
                int(time_boot_ms) & 0xFFFFFFFF, name[:NAMED_VALUE_MAX_CHARS].encode(), float(value)
            ),
            as_system=as_system,
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
            ),
            to_ground=False,  # a command is for the autopilot only
            as_system=target_system,
        )

    def request_message(self, target_system: int, target_component: int, message_id: int) -> None:
        """Ask the autopilot for one message now (MAV_CMD_REQUEST_MESSAGE), e.g. AUTOPILOT_VERSION."""
        self._send(
            lambda mav: mav.command_long_encode(
                target_system, target_component, MAV_CMD_REQUEST_MESSAGE, 0, float(message_id), 0, 0, 0, 0, 0, 0
            ),
            to_ground=False,
            as_system=target_system,
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
