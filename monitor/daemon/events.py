"""The events file: one JSON line per alert or blind/recovered notice, whatever the disk does.

A write that fails (full disk, ``/dev/full``, a path that cannot be opened,
a read-only remount) never stops the monitor and never delays an alert: the
STATUSTEXT goes out first, then the line is written here. A line that cannot
be written is kept (at most ``backlog`` lines; older ones are dropped and
counted) and retried every ``retry_s`` with the file reopened. ``failing``
and the counters tell the service what to say in STATUS and, once a minute,
to the ground station.
"""

from __future__ import annotations

import json
import logging
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

log = logging.getLogger("propwatch.monitor.events")


class EventWriter:
    def __init__(
        self,
        path: str | Path | None,
        retry_s: float = 5.0,
        backlog: int = 1000,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.path = Path(path) if path else None
        self.retry_s = retry_s
        self.clock = clock
        self._fh: Any = None
        self._pending: deque[str] = deque(maxlen=backlog)
        self._next_try = 0.0
        self.written = 0
        self.failures = 0  # failed attempts (open or write)
        self.dropped = 0  # lines lost because the backlog was full
        self.last_error = ""
        if self.path is not None:
            self._open()

    @property
    def failing(self) -> bool:
        return bool(self._pending)

    @property
    def pending(self) -> int:
        return len(self._pending)

    def write_record(self, record: dict) -> bool:
        if self.path is None:
            return True
        if len(self._pending) == self._pending.maxlen:
            self.dropped += 1
        self._pending.append(json.dumps(record, default=str))
        return self.flush(force=True)

    def retry(self) -> bool:
        """Called from the service's tick: a backlog is retried every ``retry_s``."""
        return self.flush(force=False)

    def flush(self, force: bool) -> bool:
        if not self._pending:
            return True
        now = self.clock()
        if not force and now < self._next_try:
            return False
        if self.failures and now < self._next_try:
            return False  # failing: even a new line waits for the retry period (no busy loop on a full disk)
        if self._fh is None and not self._open():
            return False
        try:
            while self._pending:
                self._fh.write(self._pending[0] + "\n")
                self._fh.flush()  # to the kernel at once: a crash loses nothing already decided
                self._pending.popleft()
                self.written += 1
        except (OSError, ValueError) as exc:
            self._fail(exc)
            return False
        if self.failures:
            log.warning("events file %s writable again (%d lines written late)", self.path, self.written)
            self.failures = 0
            self.last_error = ""
        return True

    def _open(self) -> bool:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._fh = self.path.open("a", encoding="utf-8")
            if self._fh.seekable() and self._fh.tell() > 0 and not _ends_with_newline(self.path):
                self._fh.write("\n")  # a line cut short by a full disk stays alone on its line
            return True
        except OSError as exc:
            self._fail(exc)
            return False

    def _fail(self, exc: Exception) -> None:
        self.failures += 1
        self.last_error = getattr(exc, "strerror", None) or str(exc)
        self._next_try = self.clock() + self.retry_s
        if self._fh is not None:
            try:
                self._fh.close()
            except (OSError, ValueError):
                pass  # closing a file on a full disk fails again on the buffered bytes
            self._fh = None
        if self.failures == 1 or self.failures % 100 == 0:
            log.error(
                "events file %s: %s (%d lines waiting, retry every %.0f s)",
                self.path,
                self.last_error,
                len(self._pending),
                self.retry_s,
            )

    def close(self) -> None:
        self.flush(force=True)
        if self._fh is not None:
            try:
                self._fh.close()
            except (OSError, ValueError):
                pass
            self._fh = None


def _ends_with_newline(path: Path) -> bool:
    with path.open("rb") as fh:
        fh.seek(-1, 2)
        return fh.read(1) == b"\n"
