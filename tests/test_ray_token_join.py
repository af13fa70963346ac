"""Joining a Ray cluster by address when its head requires token authentication (Ray's default where the head's
machine has a token): ``fleet ingest --ray HOST:PORT`` joins with the token it finds, or fails in under 5 s
naming the token, and still joins a head without authentication. Two real heads (``ray start --head``), each in
its own temporary folder; the test stops exactly the processes whose command line names that folder."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("ray")
pytest.importorskip("duckdb")

RAY = Path(sys.executable).with_name("ray")
TOKEN = "0f1e2d3c4b5a69788796a5b4c3d2e1f0"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(folder: Path) -> None:
    """SIGTERM, then SIGKILL, every process whose command line names ``folder`` (the head this test started)."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        pids = []
        for p in Path("/proc").iterdir():
            if p.name.isdigit():
                try:
                    if str(folder).encode() in (p / "cmdline").read_bytes():
                        pids.append(int(p.name))
                except OSError:
                    pass
        for pid in pids:
            try:
                os.kill(pid, sig)
            except ProcessLookupError:
                pass
        time.sleep(1.0)


@pytest.fixture(scope="module")
def heads(tmp_path_factory):
    if not RAY.is_file():
        pytest.skip("the ray command is not installed")
    started = {}
    for auth in ("token", "disabled"):
        folder = tmp_path_factory.mktemp(f"ray-{auth}")
        port = _free_port()
        env = {**os.environ, "RAY_AUTH_MODE": auth, "RAY_AUTH_TOKEN": TOKEN, "HOME": str(folder)}
        r = subprocess.run(
            [str(RAY), "start", "--head", f"--port={port}", f"--temp-dir={folder}", "--num-cpus=1",
             "--include-dashboard=false", "--disable-usage-stats"],
            env=env, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        started[auth] = (f"127.0.0.1:{port}", folder)
        if r.returncode != 0:
            for _, f in started.values():
                _stop(f)
            pytest.skip(f"ray start failed here: {r.stderr[-500:]}")
    yield {k: v[0] for k, v in started.items()}
    for _, folder in started.values():
        _stop(folder)
    for _, folder in started.values():
        shutil.rmtree(folder, ignore_errors=True)


def _ingest(address: str, logs: Path, db: Path, home: Path, **env) -> tuple[int, str, float]:
    """``fleet ingest`` against ``address`` with HOME (where ~/.ray/auth_token lives) and the given variables."""
    clean = {k: v for k, v in os.environ.items() if not k.startswith("RAY_AUTH")}
    t0 = time.monotonic()
    r = subprocess.run(
        [sys.executable, "-m", "monitor.cli", "fleet", "ingest", str(logs), "--db", str(db), "--ray", address,
         "--no-progress"],
        env={**clean, "HOME": str(home), **env}, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    return r.returncode, r.stdout + r.stderr, time.monotonic() - t0


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> Path:
    from test_diagnose_fixtures import write_tlog

    d = tmp_path_factory.mktemp("logs")
    write_tlog(d / "f.tlog", duration_s=12.0, faulty=None, seed=1)
    return d


def test_a_token_head_is_joined_with_the_token_found_here(heads, logs, tmp_path):
    home = tmp_path / "home"
    (home / ".ray").mkdir(parents=True)
    (home / ".ray" / "auth_token").write_text(TOKEN)  # as `ray start` leaves it on the head's machine
    code, out, _ = _ingest(heads["token"], logs, tmp_path / "a.duckdb", home)
    assert code in (0, 1) and "1 new" in out and "0 errors" in out, out
    code, out, _ = _ingest(heads["token"], logs, tmp_path / "b.duckdb", tmp_path, RAY_AUTH_TOKEN=TOKEN)
    assert code in (0, 1) and "1 new" in out and "0 errors" in out, out


def test_a_wrong_or_missing_token_fails_fast_and_says_so(heads, logs, tmp_path):
    code, out, took = _ingest(heads["token"], logs, tmp_path / "c.duckdb", tmp_path, RAY_AUTH_TOKEN="f" * 32)
    assert code == 2 and took < 5.0 + 3.0, (took, out)  # 5 s to fail, plus the interpreter's start
    assert "sent the token from RAY_AUTH_TOKEN" in out and "ray get-auth-token" in out, out
    code, out, took = _ingest(heads["token"], logs, tmp_path / "d.duckdb", tmp_path)
    assert code == 2 and "found no token" in out and took < 5.0 + 3.0, (took, out)
    assert not (tmp_path / "c.duckdb").exists() and not (tmp_path / "d.duckdb").exists()  # no empty store


def test_a_head_without_authentication_is_joined_without_a_token(heads, logs, tmp_path):
    home = tmp_path / "home"
    (home / ".ray").mkdir(parents=True)
    (home / ".ray" / "auth_token").write_text(TOKEN)  # a token at hand must not be forced on such a head
    code, out, _ = _ingest(heads["disabled"], logs, tmp_path / "e.duckdb", home)
    assert code in (0, 1) and "1 new" in out and "0 errors" in out, out
