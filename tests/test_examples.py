"""Every script in examples/ runs: each ``run(...)`` on a small simulated fleet (2 vehicles x 3 flights of 25 s,
the second vehicle's propeller 3 bent from its second flight on), as a user would call it."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from monitor.vehicle import REPO_ROOT

EXAMPLES = REPO_ROOT / "examples"


def example(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> list[Path]:
    return example("simulate_flights").run(tmp_path_factory.mktemp("fleet"), vehicles=2, flights=3, duration_s=25.0)


def test_every_example_is_run_here():
    tested = {"simulate_flights", "diagnose_log", "learn_baseline", "read_fleet_store", "monitor_tlog"}
    assert {p.stem for p in EXAMPLES.glob("*.py")} == tested


def test_simulate_flights_writes_each_vehicles_logs(fleet):
    assert [(p.parent.name, p.name) for p in fleet] == [
        (f"vehicle_{v}", f"flight_{k:02d}.tlog") for v in (1, 2) for k in (1, 2, 3)
    ]


def test_diagnose_log_gives_the_diagnose_json_with_its_summary(fleet):
    result = example("diagnose_log").run(str(fleet[0]))
    assert result["log"] == str(fleet[0]) and result["windows"] > 0
    assert result["verdict"] is not None and result["summary"]["headline"]


def test_learn_baseline_learns_one_vehicle_and_judges_its_next_flight(fleet, tmp_path):
    from monitor.memory.baseline import BaselineError

    ex = example("learn_baseline")
    out = tmp_path / "baseline.json"
    baseline = ex.run(out, [str(p) for p in fleet[:3]])
    assert out.is_file() and len(baseline.active()) == 3 and baseline.vehicle_id
    verdict = ex.judge(out, str(fleet[2]))
    assert len(verdict["deviation_sigma"]) == 4
    with pytest.raises(BaselineError):  # the other vehicle's flight
        ex.judge(out, str(fleet[3]))


def test_read_fleet_store_gives_one_row_per_flight_by_vehicle(fleet, tmp_path):
    pytest.importorskip("duckdb")
    ex = example("read_fleet_store")
    rows = ex.run(fleet[0].parent.parent, tmp_path / "fleet.duckdb")
    assert len(rows) == 6 and len({r["vehicle_id"] for r in rows}) == 2
    assert all(r["status"] in ("ok", "no_verdict") for r in rows)
    assert len(ex.run(fleet[0].parent.parent, tmp_path / "fleet.duckdb")) == 6  # nothing ingested twice


def test_monitor_tlog_replays_the_flight_through_the_daemon(fleet, tmp_path):
    result = example("monitor_tlog").run(fleet[-1], tmp_path / "monitor")
    assert result["report"]["messages"] > 1000 and result["report"]["internal_errors"] == 0
    assert sum(e["event"] == "alert" for e in result["events"]) == result["report"]["alerts"]
