"""CNN training, ONNX export and evaluation on a small synthetic data set (seconds)."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from monitor.errors import ModelError  # noqa: E402
from monitor.features import PAPER_FEATURES  # noqa: E402
from monitor.labels import LABEL_MASKS  # noqa: E402
from monitor.model import Classifier  # noqa: E402
from offline.classifier.evaluate import evaluate_dataset, score  # noqa: E402
from offline.classifier.export import export_onnx  # noqa: E402
from offline.classifier.train import (  # noqa: E402
    TrainConfig,
    load_checkpoint,
    predict_probabilities,
    save_checkpoint,
    split_flights,
    train,
)
from offline.classifier.windows import gather, window_index  # noqa: E402
from offline.dataset.synthetic import synthetic_dataset  # noqa: E402

SMALL = dict(channels=8, dense=32, epochs=6, train_stride=2, learning_rate=3e-3)


@pytest.fixture(scope="module")
def data():
    return synthetic_dataset(flights_per_label=3, n_steps=260, seed=1)


@pytest.fixture(scope="module", params=["softmax16", "multilabel4"])
def trained(request, data):
    return train(data, TrainConfig(head=request.param, **SMALL), log=lambda *_: None)


def test_split_holds_out_whole_flights_per_label(data):
    tr, te = split_flights(data.labels, 0.34, seed=0)
    assert not set(tr) & set(te)
    assert sorted(set(tr) | set(te)) == list(range(data.n_flights))
    # every label keeps training flights and gives one test flight
    assert sorted(data.labels[te]) == list(range(1, 17))


def test_training_is_deterministic_by_seed(data):
    cfg = TrainConfig(epochs=1, **{k: v for k, v in SMALL.items() if k != "epochs"})
    a = train(data, cfg, log=lambda *_: None)
    b = train(data, cfg, log=lambda *_: None)
    for (ka, va), (kb, vb) in zip(a.net.state_dict().items(), b.net.state_dict().items()):
        assert ka == kb and torch.equal(va, vb)


def test_learns_the_toy_signature_on_held_out_flights(trained, data):
    r = evaluate_dataset(
        lambda w: predict_probabilities(trained, w),
        data,
        trained.config.features,
        100,
        hop=10,
        flights=np.array(trained.test_flights),
    )
    assert r.windows > 0
    assert r.accuracy > 0.6, r.accuracy  # chance is 1/16


def test_label_probabilities_are_a_distribution_consistent_with_fault_marginals(trained, data):
    f = data.features(PAPER_FEATURES)
    w = gather(f, window_index(f, 100, 37), 100)
    lp, fp = predict_probabilities(trained, w)
    np.testing.assert_allclose(lp.sum(axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(lp @ LABEL_MASKS, fp, atol=1e-5)


def test_onnx_matches_torch_on_real_windows(trained, data, tmp_path):
    path = export_onnx(trained, tmp_path / "m.onnx")
    clf = Classifier(path)
    assert clf.info.features == PAPER_FEATURES and clf.info.window == 100 and clf.info.sample_rate_hz == 20.0
    meta = clf.info.metadata
    assert meta["label_table"]["13"] == [1, 2, 4] and meta["vehicle"]["name"] == data.vehicle_name
    np.testing.assert_allclose(meta["normalization"]["mean"], trained.normalizer.mean, rtol=1e-6)
    f = data.features(PAPER_FEATURES)
    for n in (1, 7, 300):  # dynamic batch
        w = gather(f, window_index(f, 100, 1)[::3][:n], 100)
        lo, fo = clf.predict(w)
        lt, ft = predict_probabilities(trained, w)
        assert lo.shape == (n, 16) and fo.shape == (n, 4)
        np.testing.assert_allclose(lo, lt, atol=1e-4)
        np.testing.assert_allclose(fo, ft, atol=1e-4)


def test_checkpoint_round_trip(trained, data, tmp_path):
    m2 = load_checkpoint(save_checkpoint(tmp_path / "m.pt", trained))
    f = data.features(PAPER_FEATURES)
    w = gather(f, window_index(f, 100, 50), 100)
    np.testing.assert_array_equal(predict_probabilities(m2, w)[0], predict_probabilities(trained, w)[0])
    assert m2.test_flights == trained.test_flights and m2.config == trained.config


def test_score_counts_fault_precision_and_recall():
    true = np.array([1, 1, 2, 5, 16, 16])
    pred = np.array([1, 3, 2, 1, 16, 15])  # one false alarm, one missed fault, one wrong-but-faulty
    lp = np.eye(16)[pred - 1]
    r = score("B", true, LABEL_MASKS[true - 1] > 0, lp, lp @ LABEL_MASKS)
    assert r.accuracy == pytest.approx(3 / 6)
    assert r.precision == pytest.approx(3 / 4)  # predicted faulty: 3,2,16,15 -> true faulty 2,16,15
    assert r.recall == pytest.approx(3 / 4)  # true faulty 2,5,16,16 -> found 2,16,15
    assert r.confusion.sum() == 6 and r.confusion[4, 0] == 1
    assert r.to_dict()["paper"]["accuracy"] == 85.66


def test_data_set_from_another_vehicle_is_refused(trained, tmp_path):
    other = synthetic_dataset(1, 150, vehicle_name="crazyflie-2.1")
    with pytest.raises(ModelError, match="crazyflie"):
        other.check_model(trained.vehicle["name"], 20.0, trained.config.features)


def test_cli_train_export_evaluate(tmp_path, data, capsys):
    from offline.classifier import evaluate_cli, export_cli, train_cli
    from offline.dataset.records import save_dataset

    save_dataset(tmp_path / "A.npz", data)
    ck = tmp_path / "m.pt"
    assert (
        train_cli.main(
            [
                str(tmp_path / "A.npz"),
                "--out",
                str(ck),
                "--epochs",
                "1",
                "--channels",
                "8",
                "--dense",
                "16",
                "--test-fraction",
                "0.34",
            ]
        )
        == 0
    )
    assert export_cli.main([str(ck), "--out", str(tmp_path / "m.onnx")]) == 0
    capsys.readouterr()
    assert (
        evaluate_cli.main(
            [str(tmp_path / "m.onnx"), str(tmp_path / "A.npz"), "--hop", "20", "--json", "--out", str(tmp_path / "ev")]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    (res,) = out["results"]
    assert res["name"] == "synthetic (test split)"
    assert res["windows"] == 16 * 9  # 16 held-out flights, starts 0,20,..,160
    assert (tmp_path / "ev" / "confusion_synthetic.png").stat().st_size > 1000


def test_shipped_build_reuses_what_the_dataset_cli_makes():
    # build_shipped --reuse only reuses a data set made with the identical spec; keep the two in step.
    from monitor.config import to_mapping
    from offline.classifier.build_shipped import data_specs
    from offline.dataset.cli import build_parser, specs_from_args

    cli = specs_from_args(
        build_parser().parse_args(
            ["--sets", "A,B,C", "--fault", "bent,cracked", "--flights-per-label", "5", "--propellers", "quadratic"]
        )
    )
    # = `make dataset-randomised` (Makefile): the training set, physics drawn from the register
    cli += specs_from_args(
        build_parser().parse_args(
            "--name RN --waypoints random --payload 0,0.6 --fault varied --physics randomised --airframe nominal "
            "--propellers quadratic --flights-per-label 60 --duration 80 --seed 7".split()
        )
    )
    shipped = data_specs("quadratic", 60, 5)
    assert sorted(map(str, map(to_mapping, cli))) == sorted(map(str, map(to_mapping, shipped)))


def test_shipped_configuration_is_the_ablations_last_row():
    import dataclasses

    from offline.classifier.build_shipped import SHIPPED, SHIPPED_ROW
    from offline.classifier.experiments import EXPERIMENTS

    sets, changes = EXPERIMENTS[SHIPPED_ROW]
    assert sets == ("RN-varied",) and dataclasses.replace(TrainConfig(), **changes) == SHIPPED
    assert list(EXPERIMENTS)[-1] == SHIPPED_ROW


def test_a_spent_learning_rate_schedule_holds_its_last_rate_instead_of_raising():
    # A later epoch may hold more windows than the first (random window offset), so the OneCycle schedule sized
    # from the first epoch can run out; stepping on must hold the final rate, not raise.
    import torch

    from offline.classifier.train import step_schedule

    opt = torch.optim.Adam([torch.nn.Parameter(torch.zeros(1))], lr=1e-3)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=1e-3, total_steps=4)
    rates = []
    for _ in range(7):
        opt.step()
        step_schedule(sched)
        rates.append(opt.param_groups[0]["lr"])
    assert sched.last_epoch == 4 and rates[4:] == [rates[3]] * 3  # spent after its 4 steps: the last rate is held
    assert rates[0] > rates[2]  # the schedule itself ran (annealed toward its floor)
    with pytest.raises(ValueError):
        sched.step()  # what step_schedule guards against
