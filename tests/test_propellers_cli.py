"""``propwatch train-propellers``: writes loadable weights and a manifest; training is deterministic by seed."""

import json
from pathlib import Path

import numpy as np
import pytest

from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.propellers import CONDITIONS, build_propellers

torch = pytest.importorskip("torch")

from offline.propellers import cli  # noqa: E402
from offline.propellers.loadcell import LoadCellConfig, run_load_cell  # noqa: E402
from offline.propellers.lstm_train import TrainConfig, train_condition  # noqa: E402

VEHICLE = load_vehicle(DEFAULT_VEHICLE)
DANTONIO = Path(__file__).resolve().parents[2] / "shared" / "data" / "thrust_rcbench1580_dantonio" / "datasets"


def test_train_writes_models_and_manifest(tmp_path, capsys):
    assert cli.main(["--out", str(tmp_path), "--epochs", "1", "--seed", "3"]) == 0
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["seed"] == 3 and manifest["git_revision"]
    assert manifest["config"]["training"]["max_epochs"] == 1
    assert manifest["config"]["load_cell"]["sample_period_s"] == 0.025
    for c in CONDITIONS:
        assert (tmp_path / f"{c}.npz").stat().st_size < 200_000
        m = manifest["metrics"][c]
        assert m["lstm_thrust_mape_pct"] > 0 and m["paper_thrust_mape_pct"] > 0
    prop = build_propellers(VEHICLE, np.array([[0, 1, 2, 0]]), kind="lstm", models_dir=tmp_path)
    prop.reset(np.full((1, 4), 600.0))
    thrust, _ = prop(np.full((1, 4), 600.0), 0.0025)
    assert np.all(thrust > 0)
    assert "thrust MAPE" in capsys.readouterr().out
    assert (tmp_path / "metrics.md").read_text().count("| bent |") == 1


def test_training_is_deterministic_by_seed():
    s, y = run_load_cell(VEHICLE, "bent", LoadCellConfig(duration_s=40.0, seed=2)).normalised(VEHICLE)
    cfg = TrainConfig(max_epochs=1, seed=5)
    a, _ = train_condition(s, y, "bent", 0.025, cfg)
    b, _ = train_condition(s, y, "bent", 0.025, cfg)
    c, _ = train_condition(s, y, "bent", 0.025, TrainConfig(max_epochs=1, seed=6))
    for (wa, _, _), (wb, _, _), (wc, _, _) in zip(a.lstm, b.lstm, c.lstm):
        np.testing.assert_array_equal(wa, wb)
        assert not np.array_equal(wa, wc)


@pytest.mark.realdata
@pytest.mark.skipif(not DANTONIO.is_dir(), reason=f"real thrust-stand data absent: {DANTONIO}")
def test_fit_stand_json(capsys):
    files = [str(DANTONIO / "StepsTest_2020-06-16_212137.csv"), str(DANTONIO / "StepsTest20230624_2023-06-24_190243.csv")]
    assert cli.main(["--fit-stand", *files, "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows[0]["kf_n_per_rad_s2"]["r2"] > 0.99 and rows[0]["ktau_nm_per_rad_s2"]["n_points"] > 10
    assert "no RPM" in rows[1]["skipped"]


def test_bad_file_is_exit_code_2_through_propwatch(tmp_path, capsys):
    from monitor.cli import main as propwatch

    bad = tmp_path / "bad.csv"
    bad.write_text("Time (s),ESC signal (µs)\n0,1000\n1,1100\n", encoding="utf-8")
    assert propwatch(["train-propellers", "--fit-stand", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and "'Thrust'" in err
