"""Guards every reader applies before trusting a file: size, garbage stretches, time that stops advancing.

A log is read whole, so a file of zeros behind a valid header must be
refused quickly instead of being walked byte by byte for minutes:

- ``check_size``: more bytes than ``max_seconds`` of logging at a generous
  ``MAX_BYTES_PER_S`` could produce;
- ``check_marker_gaps``: a stretch longer than ``MAX_GARBAGE_BYTES`` without
  a single message marker (DataFlash ``A3 95``, MAVLink ``FD``/``FE``): no
  real log has one, damaged or not;
- ``check_time_advances``: a stream whose samples pile up on few distinct
  times (more than ``MAX_SAMPLES_PER_S`` per second of its span), or whose
  span exceeds ``max_seconds``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError

DEFAULT_MAX_SECONDS = 3 * 3600.0  # a 2-hour flight log fits with room to spare
MAX_BYTES_PER_S = 1_000_000  # PX4 high-rate ULog profiles stay well below 1 MB/s
MAX_GARBAGE_BYTES = 8 * 1024 * 1024
MAX_SAMPLES_PER_S = 2000.0  # the fastest logged stream (IMU at 1 kHz class) with margin
MIN_SAMPLES_FOR_RATE = 1000
CHUNK_BYTES = 4 * 1024 * 1024


def check_size(path: str | Path, max_seconds: float = DEFAULT_MAX_SECONDS) -> None:
    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot open: {exc.strerror or exc}") from None
    limit = max_seconds * MAX_BYTES_PER_S
    if size > limit:
        raise LogFormatError(
            f"{path}: {size / 1e6:.0f} MB is more than {max_seconds:g} s of logging could hold "
            f"(limit {limit / 1e6:.0f} MB; raise --max-seconds for a longer log)"
        )


def check_marker_gaps(path: str | Path, markers: tuple[bytes, ...], what: str) -> None:
    """Refuse a file with more than ``MAX_GARBAGE_BYTES`` in a row holding none of ``markers`` (1 or 2 bytes).

    Read in ``CHUNK_BYTES`` pieces, so the check itself costs little memory on a huge file.
    """
    path = Path(path)
    last = -1  # offset of the latest marker seen
    offset = 0
    prev_tail = b""
    with open(path, "rb") as fh:
        while True:
            chunk = fh.read(CHUNK_BYTES)
            if not chunk:
                break
            buf = prev_tail + chunk  # one byte of overlap finds a 2-byte marker split across chunks
            base = offset - len(prev_tail)
            a = np.frombuffer(buf, dtype=np.uint8)
            hit = np.zeros(len(a), dtype=bool)
            for m in markers:
                if len(m) == 1:
                    hit |= a == m[0]
                else:
                    hit[:-1] |= (a[:-1] == m[0]) & (a[1:] == m[1])
            pos = np.flatnonzero(hit) + base
            if len(pos):
                gaps = np.diff(np.concatenate(([last], pos))) - 1
                k = int(np.argmax(gaps))
                if gaps[k] > MAX_GARBAGE_BYTES:
                    _refuse(path, int(gaps[k]), (last if k == 0 else int(pos[k - 1])) + 1, what)
                last = int(pos[-1])
            offset += len(chunk)
            prev_tail = chunk[-1:]
            if offset - 1 - last > MAX_GARBAGE_BYTES:
                _refuse(path, offset - 1 - last, last + 1, what)


def _refuse(path: Path, gap: int, start: int, what: str) -> None:
    raise LogFormatError(
        f"{path}: {gap / 1e6:.1f} MB without any {what} message from byte {start}: not a log, or damaged beyond reading"
    )


def check_time_advances(streams: dict[str, object], path: str | Path, max_seconds: float = DEFAULT_MAX_SECONDS) -> None:
    """``streams``: name -> Stream (``t_us``). Refuse time that stands still or a span beyond ``max_seconds``."""
    for name, s in streams.items():
        t = getattr(s, "t_us", None)
        if t is None or len(t) < 2:
            continue
        t = np.asarray(t)
        if t.dtype.kind == "f" and not np.isfinite(t).all():
            bad = int((~np.isfinite(t)).sum())
            raise LogFormatError(f"{path}: {name}: {bad} of {len(t)} timestamps are not numbers (NaN or infinite)")
        span_s = (int(np.max(t)) - int(np.min(t))) / 1e6
        if span_s > max_seconds:
            raise LogFormatError(f"{path}: {name} spans {span_s:.0f} s, more than --max-seconds {max_seconds:g}")
        if len(t) >= MIN_SAMPLES_FOR_RATE and len(t) > MAX_SAMPLES_PER_S * max(span_s, 1e-6):
            raise LogFormatError(
                f"{path}: {len(t)} {name} samples in {span_s:.3f} s of log time: its messages stop advancing time"
            )
