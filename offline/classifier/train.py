"""Train the CNN on fault data sets: flight-level split, seeded, one thread.

Split. The paper (Sec. IV-B) drew 80 % / 20 % of *windows* at random from
16 flights; with hop 1 neighbouring windows share 99 of 100 steps, so its
99.97 % test figure measures memorisation as much as generalisation. Here the
unit of the split is the flight: for each label a fraction of whole flights is
held out, so no test window shares a single sample with a training window.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from monitor.errors import ModelError
from monitor.features import PAPER_FEATURES, SAMPLE_RATE_HZ, WINDOW_STEPS, Normalizer, check_feature_names
from monitor.labels import LABEL_MASKS
from monitor.progress import bar
from offline.classifier.cnn import YAW_EFFECTIVENESS_INPUTS, CnnConfig, FaultCnn
from offline.classifier.windows import gather, window_index
from offline.dataset.records import FaultDataset


@dataclass(frozen=True)
class TrainConfig:
    features: tuple[str, ...] = PAPER_FEATURES
    window: int = WINDOW_STEPS
    head: str = "softmax16"
    channels: int = 32
    blocks: int = 3
    dense: int = 64
    dropout: float = 0.0
    epochs: int = 6
    batch_size: int = 128
    learning_rate: float = 1e-3
    train_stride: int = 8  # windows per flight per epoch = N / stride (random offset each epoch)
    test_fraction: float = 0.2  # of flights per label
    # Loss weight of windows from healthy flights: healthy flight is the common case onboard, so a
    # weight > 1 trades missed all-faulty cases for fewer false alarms.
    healthy_weight: float = 1.0
    # Add the yaw-effectiveness statistics (offline.classifier.cnn.yaw_effectiveness) to the dense layer;
    # the features must then include YAW_EFFECTIVENESS_INPUTS.
    yaw_effectiveness: bool = False
    yaw_robust: bool = False  # median/MAD standardisation of the yaw statistics, clipped (CnnConfig.yaw_robust)
    seed: int = 0
    threads: int = 1

    def __post_init__(self) -> None:
        check_feature_names(self.features)
        missing = [n for n in YAW_EFFECTIVENESS_INPUTS if n not in self.features] if self.yaw_effectiveness else []
        if missing:
            raise ModelError(f"yaw_effectiveness needs the feature(s) {missing} in the feature list")
        if not 0.0 <= self.test_fraction < 1.0:
            raise ValueError(f"test_fraction must be in [0, 1), got {self.test_fraction}")


@dataclass
class TrainedModel:
    """A trained network plus everything export and evaluation need."""

    net: FaultCnn
    config: TrainConfig
    vehicle: dict[str, Any]
    sample_rate_hz: float
    normalizer: Normalizer
    training_manifest: dict[str, Any]
    train_flights: list[int] = field(default_factory=list)
    test_flights: list[int] = field(default_factory=list)
    history: list[dict[str, float]] = field(default_factory=list)
    dataset_name: str = ""  # the data set whose held-out flights are ``test_flights``


def split_flights(labels: np.ndarray, test_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Hold out whole flights, stratified by label: round(fraction * n) per label, at least one when n >= 2."""
    rng = np.random.default_rng(seed)
    train, test = [], []
    for lab in np.unique(labels):
        idx = rng.permutation(np.flatnonzero(labels == lab))
        k = int(round(test_fraction * len(idx)))
        if test_fraction > 0 and len(idx) >= 2:
            k = min(max(k, 1), len(idx) - 1)
        else:
            k = 0
        test += idx[:k].tolist()
        train += idx[k:].tolist()
    return np.array(sorted(train), np.int64), np.array(sorted(test), np.int64)


def targets(ds: FaultDataset, head: str) -> np.ndarray:
    """Per-flight training targets: label index 0..15 (softmax16) or (B, 4) float masks (multilabel4)."""
    if head == "softmax16":
        return ds.labels - 1
    return ds.fault_mask.astype(np.float32)


def vehicle_info(ds: FaultDataset) -> dict[str, Any]:
    v = ds.manifest.get("vehicle") if isinstance(ds.manifest, dict) else None
    if isinstance(v, dict) and "name" in v:
        return {"name": v["name"], "esc": v.get("esc", {})}
    return {"name": ds.vehicle_name, "esc": {}}


def train(ds: FaultDataset, cfg: TrainConfig, log=print) -> TrainedModel:
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    if abs(ds.sample_rate_hz - SAMPLE_RATE_HZ) > 1e-9:
        raise ModelError(f"data set {ds.name!r} is at {ds.sample_rate_hz} Hz; the classifier works at {SAMPLE_RATE_HZ} Hz")
    feats = ds.features(cfg.features)
    train_f, test_f = split_flights(ds.labels, cfg.test_fraction, cfg.seed)
    norm = Normalizer.fit(feats[train_f])
    yaw_idx = tuple(cfg.features.index(n) for n in YAW_EFFECTIVENESS_INPUTS) if cfg.yaw_effectiveness else None
    net = FaultCnn(
        CnnConfig(
            window=cfg.window,
            n_features=len(cfg.features),
            blocks=cfg.blocks,
            channels=cfg.channels,
            dense=cfg.dense,
            head=cfg.head,
            dropout=cfg.dropout,
            yaw_effectiveness=yaw_idx,
            yaw_robust=cfg.yaw_robust,
        ),
        mean=norm.mean,
        std=norm.std,
    )
    if yaw_idx is not None:
        sample = window_index(feats, cfg.window, max(1, cfg.train_stride // 2), train_f)
        sample = sample[rng.permutation(len(sample))[:20000]]
        net.fit_yaw_stats(torch.from_numpy(gather(feats, sample, cfg.window)))
    y_flight = targets(ds, cfg.head)
    label_index = ds.labels - 1  # per flight, computed once
    loss_fn = nn.CrossEntropyLoss(reduction="none") if cfg.head == "softmax16" else nn.BCEWithLogitsLoss(reduction="none")
    flight_weight = np.where(ds.labels == 1, cfg.healthy_weight, 1.0).astype(np.float32)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate)
    history = []
    n_batches_total = None
    for epoch in range(cfg.epochs):
        idx = window_index(feats, cfg.window, cfg.train_stride, train_f, offset=int(rng.integers(cfg.train_stride)))
        if len(idx) == 0:
            raise ModelError(f"data set {ds.name!r}: no valid {cfg.window}-step windows to train on")
        idx = idx[rng.permutation(len(idx))]
        n_batches = math.ceil(len(idx) / cfg.batch_size)
        if n_batches_total is None:
            n_batches_total = n_batches * cfg.epochs
            sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.learning_rate, total_steps=n_batches_total + cfg.epochs)
        net.train()
        tot, correct, count = 0.0, 0, 0
        progress = bar(n_batches, "batch", f"epoch {epoch + 1}/{cfg.epochs}")  # rate and ETA inside the epoch
        for b in range(n_batches):
            bi = idx[b * cfg.batch_size : (b + 1) * cfg.batch_size]
            x = torch.from_numpy(gather(feats, bi, cfg.window))
            y = torch.as_tensor(y_flight[bi[:, 0]])
            opt.zero_grad()
            logits = net(x)
            per = loss_fn(logits, y)
            w = torch.from_numpy(flight_weight[bi[:, 0]])
            loss = (per.reshape(len(bi), -1).mean(dim=1) * w).sum() / w.sum()
            loss.backward()
            opt.step()
            step_schedule(sched)
            tot += loss.item() * len(bi)
            count += len(bi)
            correct += int((_predicted_labels(net, logits) == label_index[bi[:, 0]]).sum())
            progress.update()
        progress.close()
        row = {"epoch": epoch + 1, "loss": tot / count, "train_accuracy": correct / count, "windows": count}
        history.append(row)
        log(
            f"epoch {epoch + 1}/{cfg.epochs}: loss {row['loss']:.4f}, train accuracy {100 * row['train_accuracy']:.2f} % on {count} windows"
        )
    net.eval()
    return TrainedModel(
        net, cfg, vehicle_info(ds), ds.sample_rate_hz, norm, ds.manifest, train_f.tolist(), test_f.tolist(), history, ds.name
    )


def step_schedule(sched) -> None:
    """Step a OneCycleLR schedule, holding its last rate once it is spent.

    Its length is fixed from the first epoch's batches; with a random window offset per epoch a later epoch
    can hold a few more windows (pooled sets: 39744 then 41472 at stride 64), and stepping past the end raises.
    Runs whose epochs fit are stepped exactly as before."""
    if sched.last_epoch < sched.total_steps:
        sched.step()


def _predicted_labels(net: FaultCnn, logits: torch.Tensor) -> np.ndarray:
    """Label index 0..15 predicted from logits (multilabel: the most probable mask)."""
    with torch.no_grad():
        if net.cfg.head == "softmax16":
            return logits.argmax(-1).numpy()
        return _mask_to_index((torch.sigmoid(logits) > 0.5).numpy())


_MASK_CODE = (LABEL_MASKS @ np.array([1, 2, 4, 8])).astype(np.int64)
_CODE_TO_INDEX = np.zeros(16, np.int64)
_CODE_TO_INDEX[_MASK_CODE] = np.arange(16)


def _mask_to_index(mask: np.ndarray) -> np.ndarray:
    return _CODE_TO_INDEX[(mask.astype(np.int64) @ np.array([1, 2, 4, 8]))]


def predict_probabilities(model: TrainedModel | FaultCnn, windows: np.ndarray, batch: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """Torch inference: (N, window, F) raw -> (label_probability (N,16), fault_probability (N,4))."""
    net = model.net if isinstance(model, TrainedModel) else model
    net.eval()
    outs_l, outs_f = [], []
    with torch.no_grad():
        for i in range(0, len(windows), batch):
            lp, fp = net.probabilities(torch.from_numpy(np.ascontiguousarray(windows[i : i + batch], np.float32)))
            outs_l.append(lp.numpy())
            outs_f.append(fp.numpy())
    if not outs_l:
        return np.empty((0, 16), np.float32), np.empty((0, 4), np.float32)
    return np.concatenate(outs_l), np.concatenate(outs_f)


# --- checkpoint (torch) -----------------------------------------------------------------


def save_checkpoint(path: str | Path, m: TrainedModel) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(
        {
            "format": "propwatch-cnn-1",
            "state_dict": m.net.state_dict(),
            "cnn_config": asdict(m.net.cfg),
            "train_config": {**asdict(m.config), "features": list(m.config.features)},
            "vehicle": m.vehicle,
            "sample_rate_hz": m.sample_rate_hz,
            "normalization": m.normalizer.to_dict(),
            "training_manifest": m.training_manifest,
            "train_flights": m.train_flights,
            "test_flights": m.test_flights,
            "history": m.history,
            "dataset_name": m.dataset_name,
        },
        path,
    )
    return path


def load_checkpoint(path: str | Path) -> TrainedModel:
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"{path}: checkpoint not found")
    try:
        d = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a bad file
        raise ModelError(f"{path}: not a propwatch checkpoint: {exc}") from exc
    if not isinstance(d, dict) or d.get("format") != "propwatch-cnn-1":
        raise ModelError(f"{path}: not a propwatch CNN checkpoint")
    tc = dict(d["train_config"])
    tc["features"] = tuple(tc["features"])
    norm = Normalizer.from_dict(d["normalization"])
    net = FaultCnn(CnnConfig(**d["cnn_config"]), mean=norm.mean, std=norm.std)
    net.load_state_dict(d["state_dict"])
    net.eval()
    return TrainedModel(
        net,
        TrainConfig(**tc),
        d["vehicle"],
        float(d["sample_rate_hz"]),
        norm,
        d["training_manifest"],
        d["train_flights"],
        d["test_flights"],
        d["history"],
        d.get("dataset_name", ""),
    )
