"""Train the paper's stacked LSTM propeller model for one condition, and export it for the numpy runtime.

Architecture (Tong et al., Sec. III-B, Fig. 7): two LSTM layers then two dense
layers (tanh, then linear); input the normalised speed, output normalised
thrust and torque. Training as in the paper's Sec. V-A: MSE, batch 32,
learning rate 0.01 (Adam) halved when the validation loss stalls, early
stopping; chronological split, the last ``test_fraction`` (20 %) held out for
the reported figures and the last ``val_fraction`` of the rest for the
schedule.

One deviation, for speed and for the simulator: the network is trained on
windows of ``window_steps`` past samples and scored at *every* position after
``burn_in_steps`` rather than only the last one. Each scored output is still a
prediction from a window of past RPM; one window gives 24 training targets
instead of 1; and the model learns to be right whatever the length of its
history -- which is what lets the simulator step it statefully
(``tests/test_propellers_lstm.py`` checks stateful = windowed).
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from offline.propellers.lstm_runtime import StackedLstm, load_stacked_lstm


@dataclass(frozen=True)
class TrainConfig:
    hidden_size: int = 16
    dense_size: int = 16
    window_steps: int = 32  # 0.8 s at 25 ms
    burn_in_steps: int = 8
    batch_size: int = 32  # paper
    learning_rate: float = 0.01  # paper
    max_epochs: int = 30
    patience_epochs: int = 5
    test_fraction: float = 0.2  # paper: chronological 80/20
    val_fraction: float = 0.1  # of the training part, for the schedule and early stopping
    mape_min_fraction: float = 0.05  # MAPE over samples whose measured value is >= 5 % of full scale
    seed: int = 0


class StackedLstmNet(nn.Module):
    def __init__(self, hidden_size: int, dense_size: int):
        super().__init__()
        self.lstm = nn.LSTM(1, hidden_size, num_layers=2, batch_first=True)
        self.dense0 = nn.Linear(hidden_size, dense_size)
        self.dense1 = nn.Linear(dense_size, 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, T, 1) standardised speed -> (N, T, 2) standardised thrust, torque."""
        h, _ = self.lstm(x)
        return self.dense1(torch.tanh(self.dense0(h)))


@dataclass(frozen=True)
class Normalisation:
    input_mean: float
    input_std: float
    output_mean: tuple[float, float]
    output_std: tuple[float, float]


def split_index(n: int, test_fraction: float) -> int:
    """First index of the chronological test part."""
    return int(round(n * (1.0 - test_fraction)))


def _windows(x: np.ndarray, y: np.ndarray, length: int) -> tuple[torch.Tensor, torch.Tensor]:
    xt = torch.as_tensor(x, dtype=torch.float32).unfold(0, length, 1)[..., None]  # (N, L, 1)
    yt = torch.as_tensor(y, dtype=torch.float32).unfold(0, length, 1).transpose(1, 2)  # (N, L, 2)
    return xt, yt


def train_condition(
    s: np.ndarray, y: np.ndarray, condition: str, sample_period_s: float, cfg: TrainConfig = TrainConfig()
) -> tuple[StackedLstm, dict]:
    """Fit one condition on the first (1 - test_fraction) of the sweep; returns the numpy model and a history."""
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    n_train = split_index(len(s), cfg.test_fraction)
    n_fit = split_index(n_train, cfg.val_fraction)
    norm = Normalisation(
        float(s[:n_fit].mean()),
        float(s[:n_fit].std()),
        tuple(float(v) for v in y[:n_fit].mean(axis=0)),
        tuple(float(v) for v in y[:n_fit].std(axis=0)),
    )
    xs = (s - norm.input_mean) / norm.input_std
    ys = (y - np.array(norm.output_mean)) / np.array(norm.output_std)
    x_fit, y_fit = _windows(xs[:n_fit], ys[:n_fit], cfg.window_steps)
    x_val, y_val = _windows(xs[n_fit:n_train], ys[n_fit:n_train], cfg.window_steps)

    net = StackedLstmNet(cfg.hidden_size, cfg.dense_size)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.5, patience=2)
    b = cfg.burn_in_steps
    best, best_loss, stale, history = copy.deepcopy(net.state_dict()), float("inf"), 0, []
    for epoch in range(cfg.max_epochs):
        net.train()
        order = torch.as_tensor(rng.permutation(len(x_fit)))
        total = 0.0
        for start in range(0, len(order), cfg.batch_size):
            idx = order[start : start + cfg.batch_size]
            loss = nn.functional.mse_loss(net(x_fit[idx])[:, b:], y_fit[idx][:, b:])
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
        net.eval()
        with torch.no_grad():
            val = float(nn.functional.mse_loss(net(x_val)[:, b:], y_val[:, b:]))
        sched.step(val)
        history.append({"epoch": epoch, "train_mse": total / len(x_fit), "val_mse": val, "lr": opt.param_groups[0]["lr"]})
        if val < best_loss - 1e-6:
            best, best_loss, stale = copy.deepcopy(net.state_dict()), val, 0
        else:
            stale += 1
            if stale >= cfg.patience_epochs:
                break
    net.load_state_dict(best)
    return to_numpy(net, norm, condition, sample_period_s, cfg.window_steps), {"epochs": history, "best_val_mse": best_loss}


def to_numpy(net: StackedLstmNet, norm: Normalisation, condition: str, sample_period_s: float, window_steps: int) -> StackedLstm:
    def a(t: torch.Tensor) -> np.ndarray:
        return t.detach().cpu().numpy().astype(np.float64)

    lstm = tuple(
        (
            a(getattr(net.lstm, f"weight_ih_l{k}")),
            a(getattr(net.lstm, f"weight_hh_l{k}")),
            a(getattr(net.lstm, f"bias_ih_l{k}") + getattr(net.lstm, f"bias_hh_l{k}")),
        )
        for k in range(net.lstm.num_layers)
    )
    dense = ((a(net.dense0.weight), a(net.dense0.bias)), (a(net.dense1.weight), a(net.dense1.bias)))
    return StackedLstm(
        lstm,
        dense,
        norm.input_mean,
        norm.input_std,
        np.array(norm.output_mean),
        np.array(norm.output_std),
        sample_period_s,
        window_steps,
        condition,
    )


def save_npz(model: StackedLstm, path: str | Path) -> Path:
    """Float32 weights (a few KB); the runtime computes in float64."""
    arrays: dict[str, np.ndarray] = {"num_lstm_layers": np.array(len(model.lstm))}
    for k, (w_ih, w_hh, b) in enumerate(model.lstm):
        arrays.update({f"lstm{k}_w_ih": w_ih, f"lstm{k}_w_hh": w_hh, f"lstm{k}_b": b})
    for k, (w, b) in enumerate(model.dense):
        arrays.update({f"dense{k}_w": w, f"dense{k}_b": b})
    arrays = {k: v.astype(np.float32) if v.dtype.kind == "f" else v for k, v in arrays.items()}
    arrays.update(
        input_mean=np.array(model.input_mean),
        input_std=np.array(model.input_std),
        output_mean=model.output_mean,
        output_std=model.output_std,
        sample_period_s=np.array(model.sample_period_s),
        window_steps=np.array(model.window_steps),
        condition=np.array(model.condition),
    )
    path = Path(path)
    with path.open("wb") as f:
        np.savez_compressed(f, **arrays)
    return path


def reload_as_shipped(model: StackedLstm, path: str | Path) -> StackedLstm:
    """Save then load, so reported metrics are those of the float32 weights that ship."""
    save_npz(model, path)
    return load_stacked_lstm(path)


def mape_percent(y_true: np.ndarray, y_pred: np.ndarray, mask: np.ndarray) -> float:
    return float(100.0 * np.mean(np.abs(y_pred[mask] - y_true[mask]) / np.abs(y_true[mask])))


def evaluate(model: StackedLstm, s: np.ndarray, y: np.ndarray, cfg: TrainConfig, formula=None) -> dict:
    """Test-split MAPE (%) of the LSTM run statefully over the whole sweep, and of a kF·ω² fit on the same split.

    The quadratic baseline is the paper's Eqs. (2), (3): ``y = k·s²`` per output,
    least squares through the origin on the training part. ``formula`` (a
    ``FaultSignature``, or a callable s -> (T, 2)) is the load cell's own
    noise-free mean map: its MAPE is the floor the chosen noise sets, which an
    LSTM that learned the formula back reaches and cannot beat.
    """
    n_train = split_index(len(s), cfg.test_fraction)
    pred, _ = model.run(s[None, :])
    pred = pred[0]
    test = slice(n_train, None)
    out: dict[str, float] = {}
    for j, name in enumerate(("thrust", "torque")):
        mask = y[test, j] >= cfg.mape_min_fraction
        k = float(np.sum(s[:n_train] ** 2 * y[:n_train, j]) / np.sum(s[:n_train] ** 4))
        out[f"lstm_{name}_mape_pct"] = mape_percent(y[test, j], pred[test, j], mask)
        out[f"quadratic_{name}_mape_pct"] = mape_percent(y[test, j], k * s[test] ** 2, mask)
        out[f"quadratic_{name}_k"] = k
        out[f"n_test_{name}"] = int(mask.sum())
    if formula is not None:
        f = formula(s) if callable(formula) else formula_of(formula, s)
        for j, name in enumerate(("thrust", "torque")):
            mask = y[test, j] >= cfg.mape_min_fraction
            out[f"formula_{name}_mape_pct"] = mape_percent(y[test, j], f[test, j], mask)
    return out


def formula_of(signature, s: np.ndarray) -> np.ndarray:
    """(T, 2) the load cell's noise-free mean map for one signature, in the LSTM's normalised units."""
    s2 = np.square(s)
    return np.stack([s2 * signature.thrust_factor(s), s2 * signature.torque_factor(s)], axis=-1)


def config_dict(cfg: TrainConfig) -> dict:
    return asdict(cfg)
