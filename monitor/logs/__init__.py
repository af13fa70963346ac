"""Flight-log readers: every format into one ``monitor.flight.FlightTable``.

    table = read_log("flight.tlog", esc=vehicle.esc)          # format from the file
    table = read_log("E8_log00.csv.gz", fmt="crazypad")      # CSV needs a named mapping

Formats: MAVLink ``.tlog`` (``tlog``), PX4 ULog ``.ulg`` (``ulog``), ArduPilot
DataFlash ``.bin`` (``dataflash``), and CSV through ``monitor/formats.yaml``.
Each reader decodes to a ``RawFlight`` (streams in project units and frames);
``to_flight_table`` puts it on the model's grid.
"""

from __future__ import annotations

from pathlib import Path

from monitor.errors import LogFormatError
from monitor.esc import EscCurve
from monitor.flight import FlightTable
from monitor.logs.raw import RawFlight, Stream, to_flight_table

BINARY_FORMATS = ("tlog", "ulog", "dataflash")
ULOG_MAGIC = b"ULog\x01\x12\x35"
DATAFLASH_HEAD = b"\xa3\x95"


def detect_format(path: str | Path) -> str:
    """Binary format from the file's first bytes, else its extension; CSV must be named."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            head = f.read(16)
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot open: {exc.strerror or exc}") from exc
    if not head:
        raise LogFormatError(f"{path}: empty file (0 bytes): nothing was logged")
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    if head.startswith(DATAFLASH_HEAD):
        return "dataflash"
    if len(head) > 8 and head[8] in (0xFD, 0xFE):
        return "tlog"
    suffixes = "".join(path.suffixes).lower()
    if ".csv" in suffixes:
        from monitor.logs.csvlog import load_formats

        names = ", ".join(sorted(load_formats()))
        raise LogFormatError(f"{path}: CSV logs need --format NAME, one of: {names} (column mappings in monitor/formats.yaml)")
    named = NAMED_BY_SUFFIX.get(path.suffix.lower())
    if named is not None:  # the name promises a format the bytes do not hold
        raise LogFormatError(f"{path}: unknown log format: named as {named} but not one, it starts with {_looks_like(head)}")
    raise LogFormatError(f"{path}: unknown log format (expected .tlog, .ulg, DataFlash .bin, or CSV with --format)")


NAMED_BY_SUFFIX = {
    ".tlog": "a MAVLink telemetry log (.tlog)",
    ".ulg": "a PX4 ULog (.ulg)",
    ".bin": "an ArduPilot DataFlash log (.bin)",
}


def _looks_like(head: bytes) -> str:
    """What a file's first bytes are, for an error message: text (quoted) or binary (in hex)."""
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        text = None
    if text is not None and all(c.isprintable() or c in "\r\n\t" for c in text):
        return f"text ({text.splitlines()[0][:16]!r}...)"
    return f"bytes {head[:8].hex(' ')} (none of the three formats' headers)"


def read_raw(path: str | Path, fmt: str | None = None, extras: bool = True) -> RawFlight:
    """Decode a log into streams. ``fmt``: None (detect), a binary format name, or a CSV mapping name.

    ``extras=False`` lets a reader skip what only calibration uses (ESC telemetry,
    position, accelerometer) where that saves time (tlogs).
    """
    fmt = fmt or detect_format(path)
    if fmt == "tlog":
        from monitor.logs.tlog import read_tlog

        return read_tlog(path, extras=extras)
    if fmt == "ulog":
        from monitor.logs.ulog import read_ulog

        return read_ulog(path)
    if fmt == "dataflash":
        from monitor.logs.dataflash import read_dataflash

        return read_dataflash(path)
    from monitor.logs.csvlog import read_csv

    return read_csv(path, fmt)


def read_log(
    path: str | Path, fmt: str | None = None, esc: EscCurve | None = None, rate_hz: float = 20.0, extras: bool = True
) -> FlightTable:
    """Read any supported log onto the ``rate_hz`` grid; RPM from ``esc`` when its unit matches."""
    return to_flight_table(read_raw(path, fmt, extras), esc=esc, rate_hz=rate_hz)


__all__ = ["BINARY_FORMATS", "RawFlight", "Stream", "detect_format", "read_log", "read_raw", "to_flight_table"]
