"""What a new user meets in the first hour, beyond issue 39's paper cuts: every command documented, help that reads
as text, the CrazyPAD log told which vehicle to name, the vehicle's own rotor names and percent in messages, Ray
quiet, and the browser tests' need said. Each test here failed before its fix."""

from __future__ import annotations

import contextlib
import io
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from monitor.cli import COMMANDS
from monitor.cli import main as propwatch

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
CRAZYPAD_NORMAL = DATA / "crazypad" / "motor" / "normal_flight" / "E8_log00.csv.gz"
# Subcommands whose own --help a user reaches from the command's.
SUBCOMMANDS = {
    "baseline": ("learn", "show", "note"),
    "fleet": ("ingest", "report"),
    "crazypad": ("analyse", "calibrate", "run"),
    "evaluate": ("classifier", "alerts", "evalsim"),
    "tune": ("sets", "noise", "alerts"),
}
# A module path (monitor.memory.cli) or a source file (offline/sim/assumptions.py); not a file name such as
# monitor.yaml or fleet.duckdb.
MODULE_PATH = re.compile(r"\b(?:monitor|offline|fleet|bench)\.(?!yaml|onnx|json|duckdb|parquet|md\b)[a-z_]+|\b[\w/]+\.py\b")


def help_page(argv: list[str]) -> str:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.suppress(SystemExit):
        propwatch(argv)
    return buf.getvalue()


def test_the_reference_lists_every_command():
    reference = (REPO / "docs" / "REFERENCE.md").read_text()
    missing = [name for name in COMMANDS if f"`propwatch {name}" not in reference]
    assert not missing, f"docs/REFERENCE.md does not list: {missing}"


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_help_reads_as_text_without_markup_or_module_paths(name):
    pages = {name: help_page([name, "--help"])}
    pages |= {f"{name} {sub}": help_page([name, sub, "--help"]) for sub in SUBCOMMANDS.get(name, ())}
    for page, text in pages.items():
        assert "usage: propwatch" in text, (page, text[:300])
        assert "`" not in text, f"propwatch {page} --help shows backquotes:\n{text}"
        assert not MODULE_PATH.findall(text), f"propwatch {page} --help names modules {MODULE_PATH.findall(text)}:\n{text}"


def test_the_module_path_check_finds_paths_and_only_paths():
    assert MODULE_PATH.findall("see offline.tune.sets and offline/sim/assumptions.py") == [
        "offline.tune",
        "offline/sim/assumptions.py",
    ]
    assert MODULE_PATH.findall("deploy/monitor.yaml, fleet.duckdb, fleet.parquet, models/classifier.onnx") == []


def test_crazypad_help_describes_each_subcommand():
    text = help_page(["crazypad", "--help"])
    for sub in SUBCOMMANDS["crazypad"]:
        line = next((x for x in text.splitlines() if x.strip().startswith(sub + " ")), "")
        assert len(line.split()) > 3, f"no description of {sub}:\n{text}"


def test_the_readme_says_the_browser_tests_need_chromium():
    readme = (REPO / "README.md").read_text()
    assert re.search(r"browser tests.{0,80}need Chromium", readme, re.S), "README: say the browser tests need Chromium"


@pytest.mark.realdata
@pytest.mark.skipif(not CRAZYPAD_NORMAL.is_file(), reason=f"CrazyPAD data not found at {CRAZYPAD_NORMAL}")
def test_a_crazypad_log_without_vehicle_is_told_to_add_it(capsys):
    assert propwatch(["diagnose", str(CRAZYPAD_NORMAL), "--format", "crazypad", "--json"]) == 3  # physics alone
    step = json.loads(capsys.readouterr().out)["summary"]["next_step"]
    assert "--vehicle models/crazyflie.yaml" in step and "minute of steady flight" not in step, step


def test_one_propeller_to_inspect_is_one_propeller():
    from monitor.diagnose.verdict import verdict_of

    result = {
        "propellers": [{"name": n} for n in ("M1", "M3", "M4", "M2")],
        "verdict": {"label": 4, "faulty_propellers": [3], "confidence": "suspect", "fault_probability": [0.1, 0.2, 0.9, 0.1]},
        "hypotheses": [{"faulty_propellers": [3], "probability": 1.0}],
    }
    step = verdict_of(result).next_step
    assert step.startswith("Inspect propeller M4 before"), step


def test_a_healthy_flight_refused_names_the_rotor_by_the_vehicles_own_name():
    from test_vehicle_memory import damaged, healthy

    from monitor.memory.learn import HealthyOutlierError, check_outliers
    from monitor.memory.summary import summarize

    summaries = [summarize(healthy(k)) for k in range(3)] + [summarize(damaged(2, 0.15))]
    with pytest.raises(HealthyOutlierError) as err:
        check_outliers(["a", "b", "c", "d"], summaries, ("M1", "M3", "M4", "M2"))
    assert "rotor M3 lies beyond their spread" in str(err.value), err.value


@pytest.mark.slow
def test_fleet_ingest_does_not_print_rays_token_notice(tmp_path):
    pytest.importorskip("ray")
    pytest.importorskip("duckdb")
    from offline.simulate import SimulateSpec, write_flights

    write_flights(tmp_path / "logs", SimulateSpec(duration_s=15.0, propellers="quadratic"))
    r = subprocess.run(
        [sys.executable, "-m", "monitor.cli", "fleet", "ingest", str(tmp_path / "logs"), "--db", str(tmp_path / "f.duckdb"),
         "--ray", "auto", "--workers", "1", "--no-progress", "--json"],
        capture_output=True, text=True, cwd=REPO, timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["new"] == 1
    assert "oken authentication" not in r.stderr + r.stdout, r.stderr
