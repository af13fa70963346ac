"""The paper's CNN (Tong et al., Fig. 14) with the normalisation inside the graph.

A window (window, F) is a one-channel image. Each block is a 3x3 convolution
(32 channels, doubling per block), ReLU and 2x2 max-pooling; then flatten,
one dense layer and the output layer. Two heads:

- ``softmax16``: the paper's 16-way softmax over labels; P(propeller i faulty)
  is the sum of the label probabilities whose mask contains i.
- ``multilabel4``: one sigmoid per propeller (our change for generalisation);
  the 16 label probabilities are the product of independent Bernoullis.

``forward`` returns logits for training; ``probabilities`` returns the two
outputs of the ONNX contract (``monitor.model``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from monitor.labels import LABEL_MASKS

HEADS = ("softmax16", "multilabel4")


@dataclass(frozen=True)
class CnnConfig:
    window: int = 100
    n_features: int = 10
    blocks: int = 3
    channels: int = 32  # first block; doubles per block (paper)
    dense: int = 64
    head: str = "softmax16"
    dropout: float = 0.0

    def __post_init__(self) -> None:
        if self.head not in HEADS:
            raise ValueError(f"head must be one of {HEADS}, got {self.head!r}")


def _pooled(n: int, blocks: int) -> int:
    # Pool only while the axis is at least 2 long: a 10-feature axis stops at 1.
    for _ in range(blocks):
        n = n // 2 if n >= 2 else n
    return n


class FaultCnn(nn.Module):
    def __init__(self, cfg: CnnConfig, mean=None, std=None):
        super().__init__()
        self.cfg = cfg
        f = cfg.n_features
        self.register_buffer("mean", torch.zeros(f) if mean is None else torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.ones(f) if std is None else torch.as_tensor(std, dtype=torch.float32))
        self.register_buffer("masks", torch.as_tensor(LABEL_MASKS))
        layers: list[nn.Module] = []
        c_in, h, w = 1, cfg.window, f
        for b in range(cfg.blocks):
            c_out = cfg.channels * 2**b
            kh, kw = (2 if h >= 2 else 1), (2 if w >= 2 else 1)
            layers += [nn.Conv2d(c_in, c_out, 3, padding=1), nn.ReLU(), nn.MaxPool2d((kh, kw))]
            c_in, h, w = c_out, h // kh, w // kw
        self.features = nn.Sequential(*layers)
        n_out = 16 if cfg.head == "softmax16" else 4
        self.head = nn.Sequential(
            nn.Flatten(), nn.Linear(c_in * h * w, cfg.dense), nn.ReLU(), nn.Dropout(cfg.dropout), nn.Linear(cfg.dense, n_out)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, window, F) raw features -> logits (N, 16) or (N, 4)."""
        z = (x - self.mean) / self.std
        return self.head(self.features(z.unsqueeze(1)))

    def probabilities(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(label_probability (N,16), fault_probability (N,4)) as in the ONNX contract."""
        logits = self.forward(x)
        if self.cfg.head == "softmax16":
            labels = torch.softmax(logits, dim=-1)
            return labels, labels @ self.masks
        p = torch.sigmoid(logits)  # (N, 4)
        m = self.masks  # (16, 4)
        labels = torch.prod(m * p.unsqueeze(1) + (1 - m) * (1 - p.unsqueeze(1)), dim=-1)
        return labels, p


class ContractModule(nn.Module):
    """Wraps a FaultCnn so that ``forward`` returns the two contract outputs (for export)."""

    def __init__(self, net: FaultCnn):
        super().__init__()
        self.net = net

    def forward(self, features: torch.Tensor):
        return self.net.probabilities(features)
