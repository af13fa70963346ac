"""propwatch train: train the CNN on one or more data sets (npz) and save a checkpoint.

torch is imported when training starts, not to parse arguments (--help stays fast); options left out take
the training configuration's defaults (TrainConfig).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from monitor.features import PAPER_FEATURES, check_feature_names

DEFAULT = "default: TrainConfig's"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="propwatch train", description=__doc__)
    p.add_argument("datasets", nargs="+", type=Path, help="data set .npz files (same vehicle); flights are pooled")
    p.add_argument("--out", type=Path, required=True, help="checkpoint path (.pt)")
    p.add_argument(
        "--features", default=",".join(PAPER_FEATURES), help="comma-separated feature names (default: the paper's ten)"
    )
    p.add_argument(
        "--head",
        choices=("softmax16", "multilabel4"),
        default="softmax16",
        help="softmax16: one of the 16 labels; multilabel4: independent P(faulty) per propeller (default softmax16)",
    )
    p.add_argument("--epochs", type=int, default=None, help=f"passes over the training windows ({DEFAULT})")
    p.add_argument("--train-stride", type=int, default=None, help=f"use every k-th window per epoch ({DEFAULT})")
    p.add_argument("--test-fraction", type=float, default=None, help=f"flights held out per label ({DEFAULT})")
    p.add_argument("--channels", type=int, default=None, help=f"convolution channels per block ({DEFAULT})")
    p.add_argument("--dense", type=int, default=None, help=f"width of the dense layer ({DEFAULT})")
    p.add_argument("--learning-rate", type=float, default=None, help=f"Adam learning rate ({DEFAULT})")
    p.add_argument("--seed", type=int, default=0, help="seed for the split, initialisation and batches (default 0)")
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads (default 1)")
    return p


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    from offline.classifier.train import TrainConfig, save_checkpoint, train
    from offline.dataset.records import concat, load_dataset

    features = tuple(f.strip() for f in a.features.split(",") if f.strip())
    check_feature_names(features)
    parts = [load_dataset(p) for p in a.datasets]
    ds = parts[0] if len(parts) == 1 else concat(parts, "+".join(d.name for d in parts))
    given = {
        k: getattr(a, k)
        for k in ("epochs", "train_stride", "test_fraction", "channels", "dense", "learning_rate")
        if getattr(a, k) is not None
    }
    cfg = TrainConfig(features=features, head=a.head, seed=a.seed, threads=a.threads, **given)
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
