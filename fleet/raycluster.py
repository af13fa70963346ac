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


# Ray's logger of its token set-up: at a new local instance it logs, on the user's terminal, that token authentication
# is on (and how to turn it off). The instance is this command's own, on this machine, and keeps the token.
TOKEN_SETUP_LOGGER = "ray._private.authentication.authentication_token_setup"


@contextlib.contextmanager
def quiet_token_notice():
    """Ray's token set-up logs only errors while this runs."""
    log = logging.getLogger(TOKEN_SETUP_LOGGER)
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


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
        with quiet_token_notice():
            ray.init(address="local", **kwargs)
        watcher = reaper.start(os.getpid())  # what this instance started goes with this process, even killed
    else:
        join(ray, address, kwargs)
    try:
        yield ray
    finally:
        ray.shutdown()
        if watcher is not None:  # shut down in order: the reaper's work is done
            watcher.terminate()
            watcher.wait()


# Seconds a join may wait for the head's GCS to accept it (Ray's own default is 20 tries a second apart; the
# address already answered check_reachable, so what is left to wait for is the head accepting us).
JOIN_DEADLINE_S = 3  # s: one try without a token, the rest with it


def auth_token_source() -> str | None:
    """Where Ray would read this machine's authentication token from, or None: the ``RAY_AUTH_TOKEN`` variable,
    the file ``RAY_AUTH_TOKEN_PATH`` names, or ``~/.ray/auth_token``."""
    if os.environ.get("RAY_AUTH_TOKEN"):
        return "RAY_AUTH_TOKEN"
    path = os.environ.get("RAY_AUTH_TOKEN_PATH")
    if path:
        return f"RAY_AUTH_TOKEN_PATH ({path})" if os.path.isfile(path) else None
    home = os.path.join(os.path.expanduser("~"), ".ray", "auth_token")
    return home if os.path.isfile(home) else None


def join(ray, address: str, kwargs: dict) -> None:
    """``ray.init`` an existing cluster: as it is, then with token authentication where a token is at hand; within
    about ``JOIN_DEADLINE_S`` in all, a refusal naming the token.

    Ray (2.5x) heads require token authentication by default (where their machine has a token), and Ray sends the
    token for an explicit address only when ``RAY_AUTH_MODE=token`` is set: without it a join is refused and Ray
    retries for 20 s before a bare "cannot connect". Sending a token to a head without authentication breaks its
    workers, so the token is sent only after a join without it was refused."""
    source = auth_token_source()
    tries = [None] + (["token"] if source and "RAY_AUTH_MODE" not in os.environ else [])
    last = None
    for k, mode in enumerate(tries):
        if mode is not None:
            os.environ["RAY_AUTH_MODE"] = mode  # for the whole session: every later call to the cluster sends it
            _reload_ray_config()
        wait_s = 1 if k + 1 < len(tries) else JOIN_DEADLINE_S - (len(tries) - 1)
        saved = os.environ.get("RAY_gcs_server_port_wait_time_s")
        os.environ["RAY_gcs_server_port_wait_time_s"] = str(wait_s)  # Ray's connect tries, one a second
        try:
            ray.init(address=address, **kwargs)
            return
        except Exception as exc:  # noqa: BLE001 - Ray raises ConnectionError, RuntimeError, ... by version
            last = exc
            ray.shutdown()
        finally:
            if saved is None:
                os.environ.pop("RAY_gcs_server_port_wait_time_s", None)
            else:
                os.environ["RAY_gcs_server_port_wait_time_s"] = saved
    if os.environ.get("RAY_AUTH_MODE") == "disabled":
        token = "has RAY_AUTH_MODE=disabled: no token sent"
    elif source:
        token = f"sent the token from {source}; if the head requires one, it is not this one"
    else:
        token = "found no token (RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token) to send"
    raise FleetError(
        f"Ray cluster at {address}: cannot join within {JOIN_DEADLINE_S} s ({last}); Ray heads require token "
        f"authentication by default and this run {token}: `ray get-auth-token` on the head prints its token, "
        "give it as RAY_AUTH_TOKEN"
    ) from last


def _reload_ray_config() -> None:
    """Ray's core reads RAY_AUTH_MODE once, at import: re-read it as Ray's own token set-up does."""
    config = getattr(getattr(__import__("ray"), "_raylet", None), "Config", None)
    if config is not None and hasattr(config, "initialize"):
        config.initialize("")


def cluster_cpus(ray) -> int:
    return max(1, int(ray.cluster_resources().get("CPU", 1)))
