"""``propwatch calibrate`` end to end: a .tlog in, the JSON contract, the calibrated YAML, the report.

The calibrated YAML must load with the project's loader (provenance popped,
every value cited) and drive the simulator through its ``--vehicle`` option.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle, load_vehicle_with_sources
from offline.calibrate import cli
from offline.sim.io_tlog import write_tlog
from offline.sim.mission import random_waypoints
from offline.sim.propeller import QuadraticPropeller
from offline.sim.simulator import SimConfig, simulate

NOM = load_vehicle(DEFAULT_VEHICLE)
HIDDEN_CG = (-0.012, 0.022, 0.0)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("calibrate")
    true = dataclasses.replace(NOM, cg_offset_frd_m=HIDDEN_CG)
    log = simulate(
        true, random_waypoints(1, 5, seed=21), QuadraticPropeller.for_vehicle(true), SimConfig(duration_s=50.0), seed=21
    )
    tlog = write_tlog(tmp / "measured.tlog", log, 0)
    out, report = tmp / "calibrated.yaml", tmp / "report"
    return tmp, tlog, out, report


def test_json_contract_names_the_hidden_cg_offset(run, capsys):
    tmp, tlog, out, report = run
    rc = cli.main([str(tlog), "--vehicle", str(DEFAULT_VEHICLE), "--json", "--out", str(out), "--report", str(report)])
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["cause"] == "cg_offset"
    first = doc["findings"][0]
    assert set(first) >= {"effect", "params", "residual_rms_before", "residual_rms_after", "score"}
    fit = np.array([first["params"]["cg_x_m"], first["params"]["cg_y_m"]])
    assert np.linalg.norm(fit - np.array(HIDDEN_CG[:2])) <= 0.25 * np.linalg.norm(HIDDEN_CG[:2])
    assert first["residual_rms_after"] < first["residual_rms_before"] and first["score"] > 0
    assert doc["gain"]["heldout_residual_rms_after"] < doc["gain"]["heldout_residual_rms_before"]
    assert doc["gain"]["classifier"]["done"] is False  # these flights carry no labels: said, not faked
    assert "roll_accel_rad_s2" in doc["residuals_by_phase"]["nominal"]["all"]


def test_calibrated_yaml_loads_cites_the_calibration_and_drives_the_simulator(run):
    tmp, tlog, out, report = run
    loaded = load_vehicle_with_sources(out)
    assert loaded.provenance["kind"] == "calibrated-vehicle"
    assert loaded.provenance["logs"] == [str(tlog)]
    assert loaded.provenance["cause"] == "cg_offset"
    assert loaded.sources["cg_offset_frd_m"].startswith("calibration: propwatch calibrate on measured.tlog")
    assert loaded.sources["mass_kg"] == load_vehicle_with_sources(DEFAULT_VEHICLE).sources["mass_kg"]
    assert np.linalg.norm(np.array(loaded.config.cg_offset_frd_m) - HIDDEN_CG) < 0.25 * np.linalg.norm(HIDDEN_CG)

    from offline import simulate as sim_cli

    rc = sim_cli.main(
        ["--out", str(tmp / "sim"), "--vehicle", str(out), "--duration-s", "2", "--propellers", "quadratic", "--format", "npz"]
    )
    assert rc == 0 and (tmp / "sim" / "flights.npz").is_file()


def test_report_has_plots_and_tables(run):
    _, _, _, report = run
    for name in ("residuals_timeseries.png", "residuals_by_phase.png", "candidates.png", "report.md", "calibration.json"):
        assert (report / name).stat().st_size > 0, name
    text = (report / "report.md").read_text()
    assert "Cause: cg_offset" in text and "unbalance ratio" in text


def test_unknown_term_is_refused(run, capsys):
    _, tlog, _, _ = run
    assert cli.main([str(tlog), "--terms", "cg_offset,warp_drive"]) == 2
    assert "warp_drive" in capsys.readouterr().err
