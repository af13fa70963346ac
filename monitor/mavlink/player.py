"""``propwatch replay LOG.tlog --connect udpout:127.0.0.1:14540 [--speed 10]``: a .tlog as if it were PX4.

Sends every recorded frame byte for byte (HEARTBEATs included) at its recorded
pace divided by ``--speed``, from the same socket listens to what comes back,
and answers like PX4 would: MAV_CMD_SET_MESSAGE_INTERVAL gets a COMMAND_ACK
ACCEPTED from the autopilot's ids, any other command COMMAND_ACK UNSUPPORTED.
A log cannot be played faster than it was recorded, so accepted rates are
acknowledged, not honoured; tests read what was asked from ``--requests``
(one JSON line per command) and everything the other side sent from
``--received`` (one JSON line per message).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import select
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")  # ESC_STATUS (id 291) exists only in MAVLink 2 frames
os.environ.setdefault("MAVLINK_DIALECT", "common")  # mavutil's default 'all' costs ~1 s of start-up

from pymavlink import mavutil  # noqa: E402

from monitor.daemon.link import MAV_CMD_SET_MESSAGE_INTERVAL, split_serial  # noqa: E402
from monitor.errors import ConfigError, LogFormatError  # noqa: E402
from monitor.mavlink import decode as md  # noqa: E402
from monitor.mavlink import esc as mavlink_esc  # noqa: E402

log = logging.getLogger("propwatch.replay")

MAV_RESULT_ACCEPTED = 0
MAV_RESULT_UNSUPPORTED = 3


def read_tlog(path: str | Path) -> list[tuple[float, bytes, Any]]:
    """(recorded time s, frame bytes, message) for every frame of a .tlog, in file order."""
    path = Path(path)
    if not path.is_file():
        raise LogFormatError(f"{path}: log file not found")
    mavlink_esc.register()
    conn = mavutil.mavlink_connection(str(path), dialect="common", robust_parsing=True)
    frames = []
    try:
        while True:
            m = conn.recv_msg()
            if m is None:
                break
            if m.get_type() == "BAD_DATA":
                continue
            frames.append((float(m._timestamp), bytes(m.get_msgbuf()), m))
    finally:
        conn.close()
    if not frames:
        raise LogFormatError(f"{path}: no MAVLink messages")
    return frames


def autopilot_ids(frames: list[tuple[float, bytes, Any]]) -> tuple[int, int]:
    """(system, component) of the first autopilot HEARTBEAT, as the monitor's decoder picks it."""
    for _, _, m in frames:
        if (
            m.get_type() == "HEARTBEAT"
            and m.autopilot != md.MAV_AUTOPILOT_INVALID
            and m.type not in (md.MAV_TYPE_GCS, md.MAV_TYPE_ONBOARD_CONTROLLER)
        ):
            return m.get_srcSystem(), m.get_srcComponent()
    raise LogFormatError("log has no autopilot HEARTBEAT: a monitor would never see an armed vehicle")


class Replayer:
    def __init__(self, frames, url: str, speed: float, requests_path: str | None, received_path: str | None):
        if speed <= 0:
            raise ConfigError(f"--speed {speed}: must be > 0")
        self.frames = frames
        self.speed = speed
        self.system_id, self.component_id = autopilot_ids(frames)
        device, baud = split_serial(url)
        try:
            self.conn = mavutil.mavlink_connection(
                device, baud=baud or 115200, source_system=self.system_id, source_component=self.component_id, dialect="common"
            )
        except (OSError, ValueError) as exc:
            raise ConfigError(f"--connect {url}: cannot open: {exc}") from exc
        self.conn.mav.robust_parsing = True
        self._requests = open(requests_path, "a", encoding="utf-8") if requests_path else None  # noqa: SIM115
        self._received = open(received_path, "a", encoding="utf-8") if received_path else None  # noqa: SIM115
        self.sent = 0
        self.requests = 0

    def run(self, linger_s: float) -> int:
        t0_log, t0 = self.frames[0][0], time.monotonic()
        for t_log, buf, _ in self.frames:
            due = t0 + (t_log - t0_log) / self.speed
            self._serve_until(due)
            self.conn.write(buf)
            self.sent += 1
        self._serve_until(time.monotonic() + linger_s)
        log.info("replayed %d messages; %d commands answered", self.sent, self.requests)
        return 0

    def _serve_until(self, due: float) -> None:
        while True:
            wait = due - time.monotonic()
            if wait <= 0:
                return
            ready, _, _ = select.select([self.conn.fd], [], [], wait)
            if ready:
                self._serve_once()

    def _serve_once(self) -> None:
        data = self.conn.recv(4096)
        if not data:
            return
        try:
            msgs = self.conn.mav.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - whatever the other side sends, keep playing
            return
        for m in msgs:
            self._record(self._received, m)
            if m.get_type() == "COMMAND_LONG" and m.target_system in (0, self.system_id):
                self._answer(m)

    def _answer(self, m: Any) -> None:
        self.requests += 1
        ok = m.command == MAV_CMD_SET_MESSAGE_INTERVAL
        result = MAV_RESULT_ACCEPTED if ok else MAV_RESULT_UNSUPPORTED
        self.conn.mav.command_ack_send(m.command, result)
        if self._requests is not None:
            entry = {
                "command": int(m.command),
                "result": result,
                "from": [m.get_srcSystem(), m.get_srcComponent()],
                "message_id": int(m.param1),
                "interval_us": int(m.param2),
            }
            self._requests.write(json.dumps(entry) + "\n")
            self._requests.flush()

    @staticmethod
    def _record(fh, m: Any) -> None:
        if fh is None:
            return
        d = m.to_dict()
        d = {k: (v.decode(errors="replace") if isinstance(v, bytes) else v) for k, v in d.items()}
        d["_from"] = [m.get_srcSystem(), m.get_srcComponent()]
        fh.write(json.dumps(d, default=str) + "\n")
        fh.flush()

    def close(self) -> None:
        for fh in (self._requests, self._received):
            if fh is not None:
                fh.close()
        self.conn.close()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="propwatch replay", description="Play a .tlog as if it were PX4.")
    p.add_argument("log", help=".tlog file")
    p.add_argument("--connect", default="udpout:127.0.0.1:14540", help="pymavlink URL to send to")
    p.add_argument("--speed", type=float, default=1.0, help="playback speed (10 = ten times faster)")
    p.add_argument("--linger", type=float, default=1.0, help="seconds to keep answering after the last message")
    p.add_argument("--requests", help="append one JSON line per command received (and how it was answered)")
    p.add_argument("--received", help="append one JSON line per message received from the other side")
    p.add_argument(
        "--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"], help="logging threshold (default INFO)"
    )
    args = p.parse_args(argv)
    logging.basicConfig(level=args.log_level, stream=sys.stderr, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    frames = read_tlog(args.log)
    rep = Replayer(frames, args.connect, args.speed, args.requests, args.received)
    try:
        return rep.run(args.linger)
    finally:
        rep.close()
