"""The paper's CNN (Tong et al., Fig. 14) with the normalisation inside the graph.

A window (window, F) is a one-channel image. Each block is a 3x3 convolution
(32 channels, doubling per block), ReLU and 2x2 max-pooling; then flatten,
one dense layer and the output layer. Two heads:

- ``softmax16``: the paper's 16-way softmax over labels; P(propeller i faulty)
  is the sum of the label probabilities whose mask contains i.
- ``multilabel4``: one sigmoid per propeller (our change for generalisation);
  the 16 label probabilities are the product of independent Bernoullis.

Optionally (``yaw_effectiveness``) a physics block adds four window statistics
to the dense layer's input; see ``yaw_effectiveness``. It has no weights and
is part of the exported graph, so the monitor feeds the same raw features.

``forward`` returns logits for training; ``probabilities`` returns the two
outputs of the ONNX contract (``monitor.model``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from monitor.labels import LABEL_MASKS

HEADS = ("softmax16", "multilabel4")
# The features the yaw-effectiveness block reads, in this order (``CnnConfig.yaw_effectiveness`` holds their indices).
YAW_EFFECTIVENESS_INPUTS = ("yaw_moment_krpm2", "collective_krpm2", "yaw_rate_rad_s")
N_YAW_STATS = 4
YAW_CLIP = 8.0


@dataclass(frozen=True)
class CnnConfig:
    window: int = 100
    n_features: int = 10
    blocks: int = 3
    channels: int = 32  # first block; doubles per block (paper)
    dense: int = 64
    head: str = "softmax16"
    dropout: float = 0.0
    # Indices of YAW_EFFECTIVENESS_INPUTS in the feature list, or None for the paper's CNN alone.
    yaw_effectiveness: tuple[int, int, int] | None = None
    # Standardise the yaw statistics by median and MAD and clip to +-YAW_CLIP (else mean and std, unclipped):
    # a few windows with almost no yaw activity give wild g, h that inflate the std and hide the faults' shift.
    yaw_robust: bool = False

    def __post_init__(self) -> None:
        if self.head not in HEADS:
            raise ValueError(f"head must be one of {HEADS}, got {self.head!r}")
        if self.yaw_effectiveness is not None:
            idx = tuple(int(i) for i in self.yaw_effectiveness)  # a checkpoint stores a list
            if len(idx) != 3 or not all(0 <= i < self.n_features for i in idx):
                raise ValueError(f"yaw_effectiveness: need 3 feature indices below {self.n_features}, got {idx}")
            object.__setattr__(self, "yaw_effectiveness", idx)


def yaw_effectiveness(x: torch.Tensor, idx: tuple[int, int, int]) -> torch.Tensor:
    """(N, window, F) raw features -> (N, 4): g, h, log excitation of m and of c, per window.

    Least squares over the window's steps of the yaw-rate change on what the
    rotors were asked for:  r[t+1] - r[t] = g*m[t] + h*c[t] + const, with
    m = yaw_moment_krpm2 and c = collective_krpm2 (both in (kRPM)^2).

    - g is yaw acceleration per unit of commanded yaw moment: it grows with
      every propeller whose drag torque per (RPM)^2 grows (a damaged blade),
      and a payload at the CG leaves it alone (a point mass adds no inertia
      about z), which is what tells "all four damaged" from "heavier".
    - h is yaw acceleration per unit of collective: zero when CCW and CW
      rotors have equal torque coefficients; its sign says which spin
      direction carries more damaged propellers (the same-spin pairs 1+2
      and 3+4, which relative RPM hardly shows).
    - the two log excitations tell the network how much the fit can be trusted.
    """
    im, ic, ir = idx
    m = x[:, :-1, im]
    c = x[:, :-1, ic]
    a = x[:, 1:, ir] - x[:, :-1, ir]
    m = m - m.mean(dim=1, keepdim=True)
    c = c - c.mean(dim=1, keepdim=True)
    a = a - a.mean(dim=1, keepdim=True)
    smm, scc, smc = (m * m).sum(1), (c * c).sum(1), (m * c).sum(1)
    sam, sac = (a * m).sum(1), (a * c).sum(1)
    tiny = 1e-6
    det = smm * scc - smc * smc + tiny * (smm * scc + tiny)
    g = (sam * scc - sac * smc) / det
    h = (sac * smm - sam * smc) / det
    return torch.stack([g, h, torch.log(smm + tiny), torch.log(scc + tiny)], dim=1)


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
        if cfg.yaw_effectiveness is not None:
            # Standardisation of the yaw statistics (set from training windows by ``fit_yaw_stats``).
            self.register_buffer("yaw_mean", torch.zeros(N_YAW_STATS))
            self.register_buffer("yaw_std", torch.ones(N_YAW_STATS))
        layers: list[nn.Module] = []
        c_in, h, w = 1, cfg.window, f
        for b in range(cfg.blocks):
            c_out = cfg.channels * 2**b
            kh, kw = (2 if h >= 2 else 1), (2 if w >= 2 else 1)
            layers += [nn.Conv2d(c_in, c_out, 3, padding=1), nn.ReLU(), nn.MaxPool2d((kh, kw))]
            c_in, h, w = c_out, h // kh, w // kw
        self.features = nn.Sequential(*layers)
        n_out = 16 if cfg.head == "softmax16" else 4
        n_extra = N_YAW_STATS if cfg.yaw_effectiveness is not None else 0
        self.head = nn.Sequential(  # the Flatten is a no-op on the (N, D) input; kept so checkpoints keep their keys
            nn.Flatten(),
            nn.Linear(c_in * h * w + n_extra, cfg.dense),
            nn.ReLU(),
            nn.Dropout(cfg.dropout),
            nn.Linear(cfg.dense, n_out),
        )

    def yaw_stats(self, x: torch.Tensor) -> torch.Tensor:
        """(N, window, F) raw -> (N, 4) raw yaw statistics (``yaw_effectiveness``)."""
        return yaw_effectiveness(x, self.cfg.yaw_effectiveness)

    def fit_yaw_stats(self, x: torch.Tensor) -> None:
        """Set the yaw statistics' standardisation from raw training windows."""
        with torch.no_grad():
            s = self.yaw_stats(x).double()
            s = s[torch.isfinite(s).all(dim=1)]
            if self.cfg.yaw_robust:
                centre = s.median(dim=0).values
                scale = 1.4826 * (s - centre).abs().median(dim=0).values
            else:
                centre, scale = s.mean(dim=0), s.std(dim=0)
            self.yaw_mean.copy_(centre.float())
            self.yaw_std.copy_(torch.where(scale > 1e-12, scale, torch.ones_like(scale)).float())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, window, F) raw features -> logits (N, 16) or (N, 4)."""
        z = (x - self.mean) / self.std
        flat = self.features(z.unsqueeze(1)).flatten(1)
        if self.cfg.yaw_effectiveness is not None:
            z_yaw = (self.yaw_stats(x) - self.yaw_mean) / self.yaw_std
            if self.cfg.yaw_robust:
                z_yaw = torch.clamp(z_yaw, -YAW_CLIP, YAW_CLIP)
            flat = torch.cat([flat, z_yaw], dim=1)
        return self.head(flat)

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
