"""Ray's processes go when the program that started them goes, even by SIGKILL.

A local Ray instance (``ray.init(address="local")``) starts gcs_server, raylet
and Python helpers; the first two share the driver's fate, but raylet's
children (ray::DashboardAgent, ray::RuntimeEnvAgent, ~80 MB each) outlive a
killed driver. ``start(pid)`` runs this module as a small process in its own
session that notes ``pid``'s descendants every ``POLL_S`` and, once ``pid`` is
gone, terminates the ones still running (a reused PID is told from the original
by its start time in /proc), then kills what is left after ``GRACE_S``.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time

POLL_S = 0.5
GRACE_S = 3.0


def start(pid: int) -> subprocess.Popen:
    """The reaper of ``pid``'s descendants, detached from its session and its signals."""
    return subprocess.Popen(
        [sys.executable, "-m", "fleet.reaper", str(pid)],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )


def _stat(pid: int) -> tuple[int, int, str] | None:
    """(parent pid, start time in clock ticks, state) from /proc/PID/stat; None when it is gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            text = fh.read().decode("ascii", "replace")
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()  # the command name may hold spaces and parentheses
    return int(fields[1]), int(fields[19]), fields[0]


def descendants(pid: int) -> dict[int, int]:
    """pid -> start time of every process below ``pid`` (Linux /proc)."""
    parent: dict[int, int] = {}
    started: dict[int, int] = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            st = _stat(int(name))
            if st is not None:
                parent[int(name)], started[int(name)] = st[0], st[1]
    out, todo = {}, [pid]
    while todo:
        p = todo.pop()
        for child, ppid in parent.items():
            if ppid == p and child not in out:
                out[child] = started[child]
                todo.append(child)
    return out


def _running(pid: int, started: int) -> bool:
    st = _stat(pid)
    return st is not None and st[1] == started and st[2] != "Z"  # the same process (not a reused pid), not reaped


def watch(pid: int) -> int:
    first = _stat(pid)
    if first is None:
        return 0
    known: dict[int, int] = {}
    while _running(pid, first[1]):
        known.update(descendants(pid))
        time.sleep(POLL_S)
    known.pop(os.getpid(), None)  # started by ``pid`` too
    for sig, wait_s in ((signal.SIGTERM, GRACE_S), (signal.SIGKILL, 0.0)):
        alive = [p for p, t in known.items() if _running(p, t)]
        for p in alive:
            with contextlib.suppress(OSError):
                os.kill(p, sig)
        t_end = time.monotonic() + wait_s
        while wait_s and time.monotonic() < t_end and any(_running(p, known[p]) for p in alive):
            time.sleep(0.1)
    return 0


if __name__ == "__main__":
    sys.exit(watch(int(sys.argv[1])))
