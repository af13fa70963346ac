"""ESC_STATUS (MAVLink message 291), decoded from its published definition.

ESC_STATUS is a work-in-progress message in MAVLink's common.xml and is absent
from the dialects bundled with pymavlink 2.4.50, so a stock reader returns it
as ``UNKNOWN_291`` (or skips it when matching by type). PX4 streams it to
companion computers and DShot ESCs report real RPM through it, so we register
a message class built from the definition in common.xml:

    <message id="291" name="ESC_STATUS">
      <field type="uint8_t"    name="index">     index of the first ESC in this message
      <field type="uint64_t"   name="time_usec"  units="us">
      <field type="int32_t[4]" name="rpm"        units="rpm">
      <field type="float[4]"   name="voltage"    units="V">
      <field type="float[4]"   name="current"    units="A">

Wire order (fields sorted by type size): time_usec, rpm[4], voltage[4],
current[4], index; 57 bytes. CRC_EXTRA = 10, computed by pymavlink's own
generator (``pymavlink.generator.mavparse``) from that definition; a test
recomputes it the same way.

``register()`` adds the class to pymavlink's dialect modules so any
``mavutil.mavlink_connection`` (serial, UDP, TCP, .tlog) yields real
``ESC_STATUS`` messages; encoding uses the same class, so the simulator's
.tlog writer and the monitor agree byte for byte.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from pymavlink.dialects.v20 import common as _common

MSG_ID_ESC_STATUS = 291
CRC_EXTRA_ESC_STATUS = 10


class MAVLink_esc_status_message(_common.MAVLink_message):
    """ESC information for higher-rate streaming (4 ESCs per message, from ``index``)."""

    id = MSG_ID_ESC_STATUS
    msgname = "ESC_STATUS"
    fieldnames = ["index", "time_usec", "rpm", "voltage", "current"]
    ordered_fieldnames = ["time_usec", "rpm", "voltage", "current", "index"]
    fieldtypes = ["uint8_t", "uint64_t", "int32_t", "float", "float"]
    fielddisplays_by_name: dict[str, str] = {}
    fieldenums_by_name: dict[str, str] = {}
    fieldunits_by_name: dict[str, str] = {"time_usec": "us", "rpm": "rpm", "voltage": "V", "current": "A"}
    native_format = bytearray(b"<QifiB")
    orders = [4, 0, 1, 2, 3]
    lengths = [1, 4, 4, 4, 1]
    array_lengths = [0, 4, 4, 4, 0]
    crc_extra = CRC_EXTRA_ESC_STATUS
    unpacker = struct.Struct("<Q4i4f4fB")
    instance_field = None
    instance_offset = -1

    def __init__(self, index: int, time_usec: int, rpm: Sequence[int], voltage: Sequence[float], current: Sequence[float]):
        _common.MAVLink_message.__init__(self, MSG_ID_ESC_STATUS, "ESC_STATUS")
        self._fieldnames = MAVLink_esc_status_message.fieldnames
        self._instance_field = None
        self._instance_offset = -1
        self.index = index
        self.time_usec = time_usec
        self.rpm = list(rpm)
        self.voltage = list(voltage)
        self.current = list(current)

    def pack(self, mav, force_mavlink1: bool = False) -> bytes:
        payload = self.unpacker.pack(self.time_usec, *self.rpm[:4], *self.voltage[:4], *self.current[:4], self.index)
        return self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1)


_DIALECTS = ("common", "ardupilotmega", "all")


def register(module=None) -> None:
    """Make pymavlink decode message 291 as ESC_STATUS.

    With no argument, registers in the v1.0 and v2.0 ``common``,
    ``ardupilotmega`` and ``all`` dialects (a connection switches to
    ``v20.all`` when it first sees a MAVLink 2 frame, so registering only in
    the current ``mavutil.mavlink`` is not enough) and in ``mavutil.mavlink``.
    """
    import importlib

    targets = [module] if module is not None else []
    if module is None:
        for version in ("v10", "v20"):
            for name in _DIALECTS:
                try:
                    targets.append(importlib.import_module(f"pymavlink.dialects.{version}.{name}"))
                except ImportError:
                    pass
        from pymavlink import mavutil

        if getattr(mavutil, "mavlink", None) is not None:
            targets.append(mavutil.mavlink)
    for mod in targets:
        mod.mavlink_map.setdefault(MSG_ID_ESC_STATUS, MAVLink_esc_status_message)
        if not hasattr(mod, "MAVLINK_MSG_ID_ESC_STATUS"):
            mod.MAVLINK_MSG_ID_ESC_STATUS = MSG_ID_ESC_STATUS
        if not hasattr(mod, "MAVLink_esc_status_message"):
            mod.MAVLink_esc_status_message = MAVLink_esc_status_message


def encode_esc_status(
    mav,
    time_usec: int,
    rpm: Sequence[int],
    voltage: Sequence[float] = (0.0,) * 4,
    current: Sequence[float] = (0.0,) * 4,
    index: int = 0,
) -> bytes:
    """Packed bytes of one ESC_STATUS message from ``mav`` (a pymavlink MAVLink instance)."""
    msg = MAVLink_esc_status_message(index, int(time_usec), [int(r) for r in rpm], list(voltage), list(current))
    return msg.pack(mav)


def decode_esc_status(msg) -> tuple[int, int, list[int]]:
    """(index, time_usec, rpm[4]) from an ESC_STATUS message, or from an UNKNOWN_291 carrying raw bytes."""
    if msg.get_type() == "ESC_STATUS":
        return int(msg.index), int(msg.time_usec), [int(r) for r in msg.rpm]
    if getattr(msg, "id", None) == MSG_ID_ESC_STATUS or msg.get_type() == "UNKNOWN_291":
        buf = bytes(msg.get_msgbuf())
        # MAVLink 2 header is 10 bytes (no signature handling needed for the payload slice).
        payload = buf[10:-2]
        payload = payload + bytes(max(0, MAVLink_esc_status_message.unpacker.size - len(payload)))
        t = MAVLink_esc_status_message.unpacker.unpack(payload[: MAVLink_esc_status_message.unpacker.size])
        return int(t[13]), int(t[0]), [int(r) for r in t[1:5]]
    raise ValueError(f"not an ESC_STATUS message: {msg.get_type()}")
