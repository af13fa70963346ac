"""One path from evidence to verdict: ``diagnose``, ``fleet ingest`` and the daemon replaying the same log agree.

A propeller damaged mid-flight on the evaluation-only simulator (set ``onset``, flight 0: rotor 1 from about 25 s).
``fleet ingest`` stores what ``diagnose`` says at the same hop, key for key. The daemon classifies every step, as
``diagnose --hop 1``: the same alerts, level for level and propeller for propeller, within half a second (its live
grid starts at the first message, the log reader's at the log's first sample).
"""

from __future__ import annotations

import json
import subprocess
import sys

import evalsim_flights
import pytest


def _run(*args, **kw):
    return subprocess.run(
        [sys.executable, "-m", "monitor.cli", *map(str, args)], capture_output=True, text=True, timeout=300, **kw
    )


def _onset_spec() -> list:
    from offline.evalsim.sets import build_set

    return build_set("onset", flights=1, seed=0, duration_s=60.0)  # as write_set flies it below


evalsim_flights.declare(__name__, "onset_log", _onset_spec)


@pytest.fixture(scope="module")
def onset_log(tmp_path_factory):
    from offline.evalsim.sets import write_set

    d = tmp_path_factory.mktemp("onset")
    with evalsim_flights.shared():
        write_set("onset", d, flights=1, seed=0, duration_s=60.0)
    return d / "onset_0000.tlog"


def _alerts(decision: dict) -> list[tuple]:
    return [(a["t_boot_s"], a["level"], a["propellers"]) for a in decision["alerts"]]


def test_diagnose_fleet_and_daemon_give_one_verdict(onset_log, tmp_path):
    pytest.importorskip("duckdb")
    import duckdb

    from fleet.ingest import ingest
    from fleet.worker import IngestSettings
    from monitor.diagnose.engine import round_floats

    hop = IngestSettings().hop
    diag = json.loads(_run("diagnose", onset_log, "--json", "--hop", hop).stdout)
    ingest([str(onset_log.parent)], tmp_path / "f.duckdb", ray_address="off", progress=False)
    con = duckdb.connect(str(tmp_path / "f.duckdb"), read_only=True)
    row = round_floats(json.loads(con.execute("SELECT diagnosis FROM flights").fetchone()[0]))  # as --json prints
    con.close()
    for key in ("verdict", "decision", "hypotheses", "propellers"):
        assert row[key] == diag[key], key
    assert diag["verdict"]["faulty_propellers"] == [1]

    every_step = _alerts(json.loads(_run("diagnose", onset_log, "--json", "--hop", 1).stdout)["decision"])
    ev = tmp_path / "events.jsonl"
    r = _run("monitor", "--connect", onset_log, "--tlog-speed", 0, "--events", ev, "--state-dir", "")
    assert r.returncode == 0, r.stderr[-2000:]
    daemon = [
        (e["time_boot_ms"] / 1000, e["level"], e["faulty_propellers"]) for e in map(json.loads, ev.read_text().splitlines())
    ]
    daemon = [a for a in daemon if a[1] in ("suspect", "fault")]
    assert [a[1:] for a in daemon] == [a[1:] for a in every_step] and every_step
    assert all(abs(a[0] - b[0]) <= 0.5 for a, b in zip(daemon, every_step)), (daemon, every_step)
