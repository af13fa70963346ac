"""Window-level evaluation of a classifier on fault data sets, beside the paper's figures.

Accuracy is over every valid window (hop given, 1 = the paper's) with the
predicted label = argmax of ``label_probability``. Fault-vs-normal collapses
the 16 labels to two (label 1 = normal, any other = fault), as the paper does
for its precision and recall: positive = fault.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.labels import class_names
from offline.classifier.windows import gather, window_index
from offline.dataset.records import FaultDataset

# Tong et al., Sec. IV-B/C: accuracy, then fault-vs-normal precision / recall (percent).
PAPER_RESULTS: dict[str, tuple[float, float | None, float | None]] = {
    "A": (99.97, None, None),
    "B": (85.66, 96.5, 99.8),
    "C": (80.02, 96.95, 93.6),
}

Predictor = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Result:
    name: str
    windows: int
    accuracy: float
    precision: float
    recall: float
    confusion: np.ndarray  # (16, 16) counts, rows true label, columns predicted
    per_propeller_accuracy: tuple[float, float, float, float]  # thresholded fault_probability vs truth

    def to_dict(self) -> dict:
        key = paper_key(self.name)
        paper = PAPER_RESULTS[key] if key else None
        return {
            "name": self.name,
            "windows": self.windows,
            "accuracy": self.accuracy,
            "fault_precision": self.precision,
            "fault_recall": self.recall,
            "per_propeller_accuracy": list(self.per_propeller_accuracy),
            "confusion": self.confusion.tolist(),
            "paper": None if paper is None else {"accuracy": paper[0], "precision": paper[1], "recall": paper[2]},
        }


def paper_key(name: str) -> str | None:
    """'A', 'B' or 'C' when the data set name starts with one of them ('B-bent' -> 'B')."""
    k = name[:1].upper()
    return k if k in PAPER_RESULTS and (len(name) == 1 or not name[1].isalnum()) else None


def predict_dataset(
    predict: Predictor, feats: np.ndarray, window: int, hop: int = 1, flights=None, batch: int = 1024
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(index (M,2), label_probability (M,16), fault_probability (M,4)) over valid windows."""
    idx = window_index(feats, window, hop, flights)
    lp, fp = [], []
    for i in range(0, len(idx), batch):
        a, b = predict(gather(feats, idx[i : i + batch], window))
        lp.append(a)
        fp.append(b)
    if not lp:
        return idx, np.empty((0, 16), np.float32), np.empty((0, 4), np.float32)
    return idx, np.concatenate(lp), np.concatenate(fp)


def score(name: str, true_label: np.ndarray, true_mask: np.ndarray, label_prob: np.ndarray, fault_prob: np.ndarray) -> Result:
    pred = label_prob.argmax(axis=1) + 1
    conf = np.zeros((16, 16), np.int64)
    np.add.at(conf, (true_label - 1, pred - 1), 1)
    true_fault, pred_fault = true_label != 1, pred != 1
    tp = int(np.sum(true_fault & pred_fault))
    precision = tp / max(int(pred_fault.sum()), 1)
    recall = tp / max(int(true_fault.sum()), 1)
    per_prop = ((fault_prob > 0.5) == true_mask).mean(axis=0) if len(true_mask) else np.zeros(4)
    acc = float(np.mean(pred == true_label)) if len(pred) else float("nan")
    return Result(name, len(pred), acc, precision, recall, conf, tuple(float(v) for v in per_prop))


def evaluate_dataset(
    predict: Predictor, ds: FaultDataset, features, window: int, hop: int = 1, flights=None, name: str | None = None
) -> Result:
    feats = ds.features(features)
    idx, lp, fp = predict_dataset(predict, feats, window, hop, flights)
    return score(name or ds.name, ds.labels[idx[:, 0]], ds.fault_mask[idx[:, 0]], lp, fp)


def format_table(results: list[Result]) -> str:
    """Our figures beside the paper's (percent)."""
    rows = [
        "| data set | windows | accuracy | paper accuracy | precision / recall | paper precision / recall |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        key = paper_key(r.name)
        paper = PAPER_RESULTS.get(key) if key else None
        pa = f"{paper[0]:.2f} %" if paper else "—"
        ppr = f"{paper[1]} / {paper[2]}" if paper and paper[1] is not None else "—"
        rows.append(
            f"| {r.name} | {r.windows} | {100 * r.accuracy:.2f} % | {pa} | "
            f"{100 * r.precision:.2f} / {100 * r.recall:.2f} | {ppr} |"
        )
    return "\n".join(rows)


def plot_confusion(r: Result, path: str | Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = r.confusion.sum(axis=1, keepdims=True)
    frac = r.confusion / np.maximum(rows, 1)
    fig, ax = plt.subplots(figsize=(8, 7))
    im = ax.imshow(100 * frac, cmap="Blues", vmin=0, vmax=100)
    for i in range(16):
        for j in range(16):
            if r.confusion[i, j]:
                ax.text(
                    j,
                    i,
                    f"{100 * frac[i, j]:.0f}",
                    ha="center",
                    va="center",
                    fontsize=6,
                    color="white" if frac[i, j] > 0.5 else "black",
                )
    ticks = np.arange(16)
    ax.set_xticks(ticks, [str(k + 1) for k in ticks])
    ax.set_yticks(ticks, [f"{k + 1} {n}" for k, n in enumerate(class_names())], fontsize=6)
    ax.set_xlabel("predicted label")
    ax.set_ylabel("true label (faulty PX4 rotors)")
    ax.set_title(f"{r.name}: accuracy {100 * r.accuracy:.2f} % over {r.windows} windows (row %)")
    fig.colorbar(im, ax=ax, fraction=0.046, label="share of the true label's windows (%)")
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")  # the long y tick labels must not clip the axis label
    plt.close(fig)
    return path
