"""A killed ``fleet ingest`` leaves no Ray process behind (docs/SECURITY.md, fleet.reaper).

The child starts Ray as ``fleet ingest --ray auto`` does (``fleet.raycluster.ray_session``), runs one task,
lists every process it started, and is killed with SIGKILL: no chance to shut anything down itself.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

from fleet.reaper import _running

CHILD = """
import json, os, sys, time
from fleet.raycluster import ray_session
from fleet.reaper import descendants
with ray_session("auto", workers=1) as ray:
    print(ray.get(ray.remote(lambda: os.getpid()).remote()) > 0, file=sys.stderr)
    time.sleep(1.0)  # raylet's agents are up by now
    kids = [(p, t, open(f"/proc/{p}/cmdline", "rb").read()[:80].decode("ascii", "replace")) for p, t in descendants(os.getpid()).items()]
    print(json.dumps(kids), flush=True)
    time.sleep(600)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fleet.reaper reads /proc")
def test_a_killed_ingest_leaves_no_ray_process():
    pytest.importorskip("ray")
    child = subprocess.Popen([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True)
    try:
        line = child.stdout.readline()
        assert line, "the child never started Ray"
        started = json.loads(line)
        assert any("raylet" in cmd for _, _, cmd in started), started
        child.send_signal(signal.SIGKILL)
        child.wait(10)
        t_end = time.monotonic() + 20.0
        while True:
            left = [c for c in started if _running(*c[:2])]
            if not left or time.monotonic() > t_end:
                break
            time.sleep(0.5)
        assert not left, left
    finally:
        if child.poll() is None:
            child.kill()
