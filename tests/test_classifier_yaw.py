"""The yaw-effectiveness block: its least squares, its physics in the simulator, and its path to ONNX."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from monitor.errors import ModelError  # noqa: E402
from monitor.features import compute_features  # noqa: E402
from monitor.model import Classifier  # noqa: E402
from offline.classifier.cnn import YAW_EFFECTIVENESS_INPUTS, yaw_effectiveness  # noqa: E402
from offline.classifier.experiments import YAW_FEATURES  # noqa: E402
from offline.classifier.export import export_onnx  # noqa: E402
from offline.classifier.train import TrainConfig, load_checkpoint, predict_probabilities, save_checkpoint, train  # noqa: E402
from offline.classifier.windows import gather, window_index  # noqa: E402
from offline.dataset.synthetic import synthetic_dataset  # noqa: E402

IDX = (0, 1, 2)  # yaw moment, collective, yaw rate in the hand-made windows below


def _window(g: float, h: float, n: int = 100, seed: int = 0) -> np.ndarray:
    """One window whose yaw-rate changes follow g*m + h*c + 0.3 exactly."""
    rng = np.random.default_rng(seed)
    m = rng.normal(0.0, 2.0, n)
    c = 130.0 + rng.normal(0.0, 8.0, n)
    r = np.zeros(n)
    r[1:] = np.cumsum(g * m[:-1] + h * c[:-1] + 0.3)
    return np.stack([m, c, r], axis=1)[None]


def test_least_squares_recovers_known_gains():
    x = torch.from_numpy(_window(0.0041, -1.5e-4))
    g, h, log_m, log_c = yaw_effectiveness(x, IDX)[0].tolist()
    assert g == pytest.approx(0.0041, rel=1e-5) and h == pytest.approx(-1.5e-4, rel=1e-5)  # 1e-6 ridge
    m = x[0, :-1, 0].numpy()
    assert log_m == pytest.approx(np.log(np.sum((m - m.mean()) ** 2)), rel=1e-6)
    # float32 (what the model runs) still resolves a 1 % change in g
    x32 = x.float()
    assert yaw_effectiveness(x32, IDX)[0, 0].item() == pytest.approx(0.0041, rel=1e-4)


def test_a_window_without_yaw_activity_gives_finite_statistics():
    x = torch.zeros(2, 100, 3)
    x[:, :, 1] = 130.0
    assert torch.isfinite(yaw_effectiveness(x, IDX)).all()


def _yaw_stats_of(conditions, payload_kg, seed=3):
    """Median (g, h) over 5 s windows of 30 s simulated flights on one random route."""
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
    from offline.propellers import build_propellers
    from offline.sim.mission import random_waypoints
    from offline.sim.simulator import SimConfig, simulate

    vehicle = load_vehicle(DEFAULT_VEHICLE)
    cond = np.asarray(conditions, np.int8)
    wps = np.repeat(random_waypoints(1, seed=seed), len(cond), axis=0)
    log = simulate(
        vehicle,
        wps,
        build_propellers(vehicle, cond, kind="quadratic", rng_seed=seed),
        SimConfig(duration_s=30.0, log_rate_hz=20),
        payload_kg=np.asarray(payload_kg),
        seed=seed,
    )
    f = compute_features(log.signals(), YAW_EFFECTIVENESS_INPUTS)
    f = f[:, 40:]  # after take-off
    out = []
    for k in range(len(cond)):
        w = gather(f[k : k + 1], window_index(f[k : k + 1], 100, 10), 100)
        out.append(np.median(yaw_effectiveness(torch.from_numpy(w).double(), IDX).numpy()[:, :2], axis=0))
    return np.array(out)


def test_simulated_damage_moves_yaw_effectiveness_and_payload_does_not():
    """All four bent must not look like a heavier healthy vehicle; same-spin pairs show up in h with opposite signs."""
    bent = 1
    conds = [(0, 0, 0, 0), (0, 0, 0, 0), (bent,) * 4, (bent, bent, 0, 0), (0, 0, bent, bent)]
    s = _yaw_stats_of(conds, [0.0, 0.45, 0.0, 0.0, 0.0])
    g, h = s[:, 0], s[:, 1]
    assert abs(g[1] / g[0] - 1.0) < 0.01, g  # 30 % more mass: yaw effectiveness unchanged
    assert g[2] / g[0] > 1.05, g  # bent blades drag more: +5..10 % torque per RPM^2
    assert g[0] < g[3] < g[2] and g[0] < g[4] < g[2], g
    # h: zero for equal spin groups; CCW pair (1, 2) damaged > 0 > CW pair (3, 4) damaged
    scale = abs(h[3] - h[4])
    assert h[3] > 0.0 > h[4], h
    assert abs(h[0]) < 0.25 * scale and abs(h[1]) < 0.25 * scale and abs(h[2]) < 0.25 * scale, h


def test_robust_scaling_ignores_wild_windows_and_clips_them():
    from offline.classifier.cnn import YAW_CLIP, CnnConfig, FaultCnn

    rng = np.random.default_rng(4)
    gains = np.where(rng.random(400) < 0.05, 0.05, 0.004 + 1e-4 * rng.standard_normal(400))  # 5 % wild windows
    x = torch.from_numpy(np.concatenate([_window(g, 0.0, seed=i) for i, g in enumerate(gains)]))
    nets = {r: FaultCnn(CnnConfig(n_features=3, channels=4, dense=8, yaw_effectiveness=IDX, yaw_robust=r)) for r in (False, True)}
    for net in nets.values():
        net.fit_yaw_stats(x)
    assert nets[True].yaw_std[0] < 2e-4 < nets[False].yaw_std[0]  # the MAD sees the 1e-4 spread, the std the outliers
    assert abs(nets[True].yaw_mean[0].item() - 0.004) < 3e-5
    with torch.no_grad():  # a wild window lies beyond the clip, so the clamp in forward is what bounds it
        z = (nets[True].yaw_stats(x[gains > 0.01][:1]) - nets[True].yaw_mean) / nets[True].yaw_std
    assert z[0, 0] > YAW_CLIP


def test_yaw_block_needs_its_features():
    with pytest.raises(ModelError, match="collective_krpm2"):
        TrainConfig(yaw_effectiveness=True, features=("rpm_1", "yaw_moment_krpm2", "yaw_rate_rad_s"))


@pytest.mark.parametrize("head,robust", [("multilabel4", False), ("softmax16", True)])
def test_yaw_model_exports_with_torch_parity_and_round_trips(tmp_path, head, robust):
    data = synthetic_dataset(flights_per_label=2, n_steps=200, seed=2)
    cfg = TrainConfig(
        features=YAW_FEATURES,
        head=head,
        yaw_effectiveness=True,
        yaw_robust=robust,
        channels=8,
        dense=16,
        epochs=1,
        train_stride=4,
        test_fraction=0.0,
    )
    m = train(data, cfg, log=lambda *_: None)
    assert m.net.yaw_std.min() > 0 and torch.isfinite(m.net.yaw_mean).all()
    f = data.features(YAW_FEATURES)
    w = gather(f, window_index(f, 100, 7), 100)
    clf = Classifier(export_onnx(m, tmp_path / "y.onnx"))
    assert clf.info.features == YAW_FEATURES
    lo, fo = clf.predict(w)
    lt, ft = predict_probabilities(m, w)
    np.testing.assert_allclose(lo, lt, atol=1e-4)
    np.testing.assert_allclose(fo, ft, atol=1e-4)
    m2 = load_checkpoint(save_checkpoint(tmp_path / "y.pt", m))
    assert m2.net.cfg == m.net.cfg
    np.testing.assert_array_equal(predict_probabilities(m2, w)[1], ft)
