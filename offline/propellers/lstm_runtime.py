"""The stacked LSTM in numpy, stepped statefully inside the batched simulator.

Weights come from ``offline.propellers.lstm_train`` as ``<condition>.npz``
(torch gate order i, f, g, o; the two biases summed). The network maps the
normalised speed ``s = omega / omega_max`` to the normalised mean thrust and
torque ``thrust / (kF·omega_max²)``, ``torque / (kτ·omega_max²)``, so it is
relative to the vehicle it runs on.

Rates. The LSTM was trained on load-cell samples every ``sample_period_s``
(25 ms) and only means something at that rate, while the physics runs at
>= 250 Hz. ``LstmPropeller`` therefore steps the LSTM once per sample period
(a time accumulator: when the physics period does not divide 25 ms a sample
lands on the first physics step at or after it) and holds, between samples,
the LSTM's *departure* from the analytic model, ``Δ = LSTM(t_k) - kF·ω(t_k)²``:

    thrust(t) = kF·ω(t)² + Δ_thrust(t_k)   (same for torque with kτ)

At each sample instant this equals the LSTM output exactly; between samples the
fast part (ω² follows the motor at physics rate) stays instantaneous, and only
the slowly varying fault departure is zero-order held. Holding the whole
thrust instead would add ~12.5 ms of mean delay to every rotor and degrade the
attitude loop, which is not what a propeller does.

Reset. ``reset(omega)`` puts each rotor's LSTM in its steady state at that
speed: it runs the network on a constant input for ``4·window_steps`` samples,
the state a rotor would have after spinning steadily (memory fades within a
window, which the stateful-vs-windowed test checks).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.errors import ModelError
from monitor.vehicle import VehicleConfig
from offline.propellers.vibration import FaultVibration
from offline.sim.faults import CONDITIONS, FaultSignature

State = list[tuple[np.ndarray, np.ndarray]]  # per layer: (h, c), each (H, N): rotors along the fast axis


def _fast_layer(w_ih: np.ndarray, w_hh: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rewrite one layer so that a step costs one matmul and one tanh over all gates.

    sigmoid(z) = (1 + tanh(z/2)) / 2: halving the i, f, o rows of the weights
    lets a single tanh serve all four gates. Rows are reordered (i, f, o, g) and
    the state is stored (H, N), so each gate is a contiguous block of rows.
    float32: the state needs no more.
    """
    hsz = w_hh.shape[1]
    i, f, g, o = (np.arange(k * hsz, (k + 1) * hsz) for k in range(4))  # torch's gate order
    rows = np.concatenate([i, f, o, g])  # sigmoid gates first, contiguous
    half = np.r_[np.full(3 * hsz, 0.5), np.ones(hsz)]
    return (
        (w_ih[rows] * half[:, None]).astype(np.float32),
        (w_hh[rows] * half[:, None]).astype(np.float32),
        (b[rows] * half)[:, None].astype(np.float32),
    )


@dataclass(frozen=True)
class StackedLstm:
    """2 LSTM layers then 2 dense layers (tanh, linear), with input/output normalisation."""

    lstm: tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]  # (w_ih (4H,in), w_hh (4H,H), b (4H,))
    dense: tuple[tuple[np.ndarray, np.ndarray], ...]  # (w (out,in), b (out,))
    input_mean: float
    input_std: float
    output_mean: np.ndarray  # (2,) normalised thrust, torque
    output_std: np.ndarray
    sample_period_s: float
    window_steps: int
    condition: str

    @property
    def hidden_sizes(self) -> tuple[int, ...]:
        return tuple(w_hh.shape[1] for _, w_hh, _ in self.lstm)

    def __post_init__(self) -> None:
        (w0, b0), (w1, b1) = self.dense
        fast = tuple(_fast_layer(*layer) for layer in self.lstm)
        object.__setattr__(self, "_fast", fast)
        object.__setattr__(
            self,
            "_dense_fast",
            (
                w0.astype(np.float32),
                b0[:, None].astype(np.float32),
                (w1 * self.output_std[:, None]).astype(np.float32),
                (b1 * self.output_std + self.output_mean)[:, None].astype(np.float32),
            ),
        )

    def zero_state(self, n: int) -> State:
        return [(np.zeros((h, n), np.float32), np.zeros((h, n), np.float32)) for h in self.hidden_sizes]

    def step(self, s: np.ndarray, state: State) -> tuple[np.ndarray, State]:
        """One sample for N rotors: ``s`` (N,) normalised speed -> ((N, 2) normalised thrust, torque), new state."""
        x = ((np.asarray(s, dtype=np.float32) - np.float32(self.input_mean)) / np.float32(self.input_std))[None, :]
        new_state: State = []
        for (w_ih, w_hh, b), (h, c) in zip(self._fast, state):
            hs = h.shape[0]
            z = w_hh @ h
            z += w_ih @ x if x.shape[0] > 1 else w_ih * x
            z += b
            np.tanh(z, out=z)
            gates = z[: 3 * hs]  # i, f, o were pre-halved: sigmoid = (1 + tanh) / 2
            gates += 1.0
            gates *= 0.5
            c = c * z[hs : 2 * hs]  # forget
            c += z[:hs] * z[3 * hs :]  # input * candidate
            h = np.tanh(c)
            h *= z[2 * hs : 3 * hs]  # output
            new_state.append((h, c))
            x = h
        w0, b0, w1, b1 = self._dense_fast
        d = w0 @ x
        d += b0
        np.tanh(d, out=d)
        y = w1 @ d
        y += b1
        return y.T.astype(np.float64), new_state

    def run(self, s_seq: np.ndarray, state: State | None = None) -> tuple[np.ndarray, State]:
        """Step through ``s_seq`` (N, T); returns outputs (N, T, 2) and the final state."""
        s_seq = np.atleast_2d(s_seq)
        state = self.zero_state(s_seq.shape[0]) if state is None else state
        out = np.empty(s_seq.shape + (2,))
        for t in range(s_seq.shape[1]):
            out[:, t], state = self.step(s_seq[:, t], state)
        return out, state

    def windowed(self, s_seq: np.ndarray) -> np.ndarray:
        """The paper's sequence-to-one use: output at t from the last ``window_steps`` inputs, zero state.

        Samples before the start of ``s_seq`` repeat its first value. (N, T) -> (N, T, 2).
        """
        s_seq = np.atleast_2d(s_seq)
        n, t_len = s_seq.shape
        L = self.window_steps
        padded = np.concatenate([np.repeat(s_seq[:, :1], L - 1, axis=1), s_seq], axis=1)
        windows = np.lib.stride_tricks.sliding_window_view(padded, L, axis=1)  # (N, T, L)
        out, _ = self.run(windows.reshape(n * t_len, L))
        return out[:, -1].reshape(n, t_len, 2)

    def steady_state(self, s: np.ndarray) -> tuple[np.ndarray, State]:
        s = np.asarray(s, dtype=np.float64)
        out, state = self.run(np.repeat(s[:, None], 4 * self.window_steps, axis=1))
        return out[:, -1], state


def load_stacked_lstm(path: str | Path) -> StackedLstm:
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise ModelError(f"{path}: cannot read propeller model: {exc}") from exc
    try:
        n_layers = int(d["num_lstm_layers"])
        lstm = tuple((d[f"lstm{k}_w_ih"], d[f"lstm{k}_w_hh"], d[f"lstm{k}_b"]) for k in range(n_layers))
        dense = tuple((d[f"dense{k}_w"], d[f"dense{k}_b"]) for k in range(2))
        model = StackedLstm(
            lstm,
            dense,
            float(d["input_mean"]),
            float(d["input_std"]),
            d["output_mean"].astype(np.float64),
            d["output_std"].astype(np.float64),
            float(d["sample_period_s"]),
            int(d["window_steps"]),
            str(d["condition"]),
        )
    except KeyError as exc:
        raise ModelError(f"{path}: propeller model lacks array {exc.args[0]!r}") from None
    if model.dense[-1][0].shape[0] != 2:
        raise ModelError(f"{path}: dense1_w must have 2 outputs (thrust, torque), has {model.dense[-1][0].shape[0]}")
    return model


def load_condition_models(models_dir: str | Path) -> dict[str, StackedLstm]:
    models_dir = Path(models_dir)
    out = {}
    for name in CONDITIONS:
        path = models_dir / f"{name}.npz"
        if not path.exists():
            raise ModelError(f"{path}: no trained '{name}' propeller model (run `propwatch train-propellers`)")
        out[name] = load_stacked_lstm(path)
        if out[name].condition != name:
            raise ModelError(f"{path}: holds a '{out[name].condition}' model, expected '{name}'")
    periods = {m.sample_period_s for m in out.values()}
    if len(periods) != 1:
        raise ModelError(f"{models_dir}: propeller models disagree on sample_period_s: {sorted(periods)}")
    return out


class LstmPropeller:
    """Batched ``PropellerModel``: each rotor runs its condition's LSTM; groups are fixed at build time."""

    def __init__(
        self,
        vehicle: VehicleConfig,
        conditions: np.ndarray,
        models_dir: Path,
        signatures: tuple[FaultSignature, ...],
        rng: np.random.Generator,
        vibration: bool = True,
    ):
        self.conditions = np.asarray(conditions, dtype=np.int64)
        models = load_condition_models(models_dir)
        self.kf = vehicle.kf_n_per_rad_s2
        self.ktau = vehicle.ktau_nm_per_rad_s2
        self.omega_max_rad_s = vehicle.omega_max_rad_s
        self._scale = np.array([self.kf, self.ktau]) * self.omega_max_rad_s**2
        flat = self.conditions.reshape(-1)
        self._groups = [(models[name], np.flatnonzero(flat == code)) for code, name in enumerate(CONDITIONS)]
        self._groups = [(m, idx) for m, idx in self._groups if idx.size]
        self.sample_period_s = next(iter(models.values())).sample_period_s
        self._states: list[State] = [m.zero_state(idx.size) for m, idx in self._groups]
        self._delta_thrust = np.zeros(self.conditions.shape)  # held departure from kF·ω²
        self._delta_torque = np.zeros(self.conditions.shape)  # ... and from kτ·ω²
        self._clock_s = 0.0
        vib = FaultVibration(self.conditions, signatures, vehicle.omega_max_rad_s, rng)
        self._vibration = vib if (vibration and vib.active) else None

    def _set_delta(self, omega: np.ndarray, steady: bool) -> None:
        s_flat = (omega / self.omega_max_rad_s).reshape(-1)
        y = np.empty((s_flat.size, 2))
        for g, (model, idx) in enumerate(self._groups):
            if steady:
                y[idx], self._states[g] = model.steady_state(s_flat[idx])
            else:
                y[idx], self._states[g] = model.step(s_flat[idx], self._states[g])
        w2 = np.square(omega)
        self._delta_thrust = (y[:, 0] * self._scale[0]).reshape(w2.shape) - self.kf * w2
        self._delta_torque = (y[:, 1] * self._scale[1]).reshape(w2.shape) - self.ktau * w2

    def reset(self, omega_rad_s: np.ndarray) -> None:
        omega = np.maximum(np.asarray(omega_rad_s, dtype=np.float64), 0.0)
        self._set_delta(omega, steady=True)
        self._clock_s = 0.0
        if self._vibration is not None:
            self._vibration.reset()

    def __call__(self, omega_rad_s: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        omega = np.maximum(np.asarray(omega_rad_s, dtype=np.float64), 0.0)
        self._clock_s += dt_s
        if self._clock_s >= self.sample_period_s - 1e-9:
            self._clock_s -= self.sample_period_s
            self._set_delta(omega, steady=False)
        w2 = np.square(omega)
        thrust = self.kf * w2 + self._delta_thrust
        torque = self.ktau * w2 + self._delta_torque
        if self._vibration is not None:
            ft, fq = self._vibration.step(omega, dt_s)
            thrust, torque = thrust * ft, torque * fq
        return np.maximum(thrust, 0.0), np.maximum(torque, 0.0)
