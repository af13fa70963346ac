"""Ray for the fleet tools: a local instance by default, or an existing cluster by address.

``auto`` starts a new Ray instance on this machine (no setup; ``address="local"``,
so a cluster someone else started here with ``ray start`` is never joined by
accident) or reuses one the calling program already started. An address is checked before Ray is asked to join it: Ray's
own client retries an unreachable GCS for minutes, so a TCP connect and a gRPC
(HTTP/2) handshake with a deadline come first and fail naming the address.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import time

from fleet import reaper
from fleet.errors import FleetError, need

CONNECT_DEADLINE_S = 20.0
HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"
HTTP2_SETTINGS_EMPTY = b"\x00\x00\x00\x04\x00\x00\x00\x00\x00"
HTTP2_SETTINGS_TYPE = 0x04


def split_address(address: str) -> tuple[str, int]:
    """``host:port`` or ``ray://host:port`` -> (host, port); an address without a port is an error."""
    rest = address.split("://", 1)[1] if "://" in address else address
    host, sep, port = rest.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise FleetError(f"--ray {address}: expected HOST:PORT (the head node's GCS port, e.g. 10.0.0.5:6379)")
    return host.strip("[]"), int(port)


def check_reachable(address: str, deadline_s: float = CONNECT_DEADLINE_S) -> None:
    """Raise FleetError naming ``address`` unless a gRPC server answers there within the deadline."""
    host, port = split_address(address)
    t_end = time.monotonic() + deadline_s
    try:
        with socket.create_connection((host, port), timeout=deadline_s) as s:
            s.settimeout(max(0.5, t_end - time.monotonic()))
            s.sendall(HTTP2_PREFACE + HTTP2_SETTINGS_EMPTY)
            head = s.recv(9)
    except OSError as exc:
        raise FleetError(f"Ray cluster at {address} cannot be reached: {exc.strerror or exc}") from None
    if len(head) < 4 or head[3] != HTTP2_SETTINGS_TYPE:
        raise FleetError(f"Ray cluster at {address}: something answers there, but not a Ray (gRPC) head node")


@contextlib.contextmanager
def ray_session(address: str = "auto", workers: int | None = None):
    """Yield the ``ray`` module connected as asked; shut down only what this call started."""
    ray = need("ray")
    if address != "auto":
        check_reachable(address)
    if ray.is_initialized():  # the embedding program (or a test session) already connected
        yield ray
        return
    watcher = None  # fleet.reaper: Ray's helpers go with this process, even when it is killed
    kwargs = dict(include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING)
    if address == "auto":
        if workers:
            kwargs["num_cpus"] = int(workers)
        ray.init(address="local", **kwargs)
        watcher = reaper.start(os.getpid())  # what this instance started goes with this process, even killed
    else:
        try:
            ray.init(address=address, **kwargs)
        except Exception as exc:  # noqa: BLE001 - Ray raises ConnectionError, RuntimeError, ... by version
            raise FleetError(f"Ray cluster at {address}: cannot join: {exc}") from exc
    try:
        yield ray
    finally:
        ray.shutdown()
        if watcher is not None:  # shut down in order: the reaper's work is done
            watcher.terminate()
            watcher.wait()


def cluster_cpus(ray) -> int:
    return max(1, int(ray.cluster_resources().get("CPU", 1)))
