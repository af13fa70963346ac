"""``propwatch train``: train the CNN on one or more data sets (npz) and save a checkpoint."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from monitor.features import PAPER_FEATURES, check_feature_names
from offline.classifier.train import TrainConfig, save_checkpoint, train
from offline.dataset.records import concat, load_dataset


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="propwatch train", description=__doc__)
    p.add_argument("datasets", nargs="+", type=Path, help="data set .npz files (same vehicle); flights are pooled")
    p.add_argument("--out", type=Path, required=True, help="checkpoint path (.pt)")
    p.add_argument(
        "--features", default=",".join(PAPER_FEATURES), help="comma-separated feature names (default: the paper's ten)"
    )
    p.add_argument("--head", choices=("softmax16", "multilabel4"), default="softmax16")
    p.add_argument("--epochs", type=int, default=TrainConfig.epochs)
    p.add_argument("--train-stride", type=int, default=TrainConfig.train_stride, help="use every k-th window per epoch")
    p.add_argument("--test-fraction", type=float, default=TrainConfig.test_fraction, help="flights held out per label")
    p.add_argument("--channels", type=int, default=TrainConfig.channels)
    p.add_argument("--dense", type=int, default=TrainConfig.dense)
    p.add_argument("--learning-rate", type=float, default=TrainConfig.learning_rate)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=1)
    return p


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    features = tuple(f.strip() for f in a.features.split(",") if f.strip())
    check_feature_names(features)
    parts = [load_dataset(p) for p in a.datasets]
    ds = parts[0] if len(parts) == 1 else concat(parts, "+".join(d.name for d in parts))
    cfg = TrainConfig(
        features=features,
        head=a.head,
        epochs=a.epochs,
        train_stride=a.train_stride,
        test_fraction=a.test_fraction,
        channels=a.channels,
        dense=a.dense,
        learning_rate=a.learning_rate,
        seed=a.seed,
        threads=a.threads,
    )
    m = train(ds, cfg)
    m.training_manifest = {
        "datasets": [str(p) for p in a.datasets],
        "manifests": [d.manifest for d in parts],
        "train_config": {**cfg.__dict__, "features": list(features)},
    }
    save_checkpoint(a.out, m)
    print(
        json.dumps(
            {
                "checkpoint": str(a.out),
                "train_flights": len(m.train_flights),
                "test_flights": len(m.test_flights),
                "final": m.history[-1],
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
