"""The stored form of a fault data set and its checks against a model.

One ``.npz`` per data set holds arrays with a leading flight axis and a JSON
``meta`` string (vehicle, sample rate, name, manifest). Signals are stored
rather than features so a model with any feature list can be evaluated; the
checks below turn every mismatch (vehicle, rate, missing signal) into a
``ModelError`` instead of a silent wrong answer.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from monitor.errors import ModelError
from monitor.features import SAMPLE_RATE_HZ, SIGNALS, compute_features
from monitor.labels import label_from_mask

CONDITION_NAMES = ("normal", "bent", "cracked")
FORMAT_VERSION = 1


@dataclass(frozen=True)
class FaultDataset:
    """Flights of one data set; every array has the flight axis first."""

    name: str
    vehicle_name: str
    sample_rate_hz: float
    signals: dict[str, np.ndarray]  # canonical signals, (B, T) or (B, T, 4) for motor_rpm
    conditions: np.ndarray  # (B, 4) int8, 0 normal / 1 bent / 2 cracked, PX4 rotor order
    payload_kg: np.ndarray  # (B,) extra mass over the vehicle's
    waypoint_set: tuple[str, ...]  # (B,) mission name per flight ("A", "B", "random", ...)
    manifest: dict[str, Any] = field(default_factory=dict)
    # (B,) step at which each flight's faults switch on; 0 = faulty from take-off.
    onset_step: np.ndarray | None = None

    def __post_init__(self) -> None:
        missing = [s for s in SIGNALS if s not in self.signals]
        if missing:
            raise ModelError(f"data set {self.name!r}: signals missing: {missing}")
        n = len(self.conditions)
        rpm = self.signals["motor_rpm"]
        if rpm.ndim != 3 or rpm.shape[0] != n or rpm.shape[2] != 4:
            raise ModelError(f"data set {self.name!r}: motor_rpm must be (flights={n}, T, 4), got {rpm.shape}")
        for s in SIGNALS[1:]:
            if self.signals[s].shape != rpm.shape[:2]:
                raise ModelError(f"data set {self.name!r}: {s} must be {rpm.shape[:2]}, got {self.signals[s].shape}")
        if self.conditions.shape != (n, 4) or not np.isin(self.conditions, (0, 1, 2)).all():
            raise ModelError(f"data set {self.name!r}: conditions must be (flights, 4) in 0/1/2")
        if len(self.payload_kg) != n or len(self.waypoint_set) != n:
            raise ModelError(f"data set {self.name!r}: payload_kg and waypoint_set need one entry per flight")

    @property
    def n_flights(self) -> int:
        return len(self.conditions)

    @property
    def n_steps(self) -> int:
        return self.signals["motor_rpm"].shape[1]

    @property
    def fault_mask(self) -> np.ndarray:
        """(B, 4) bool: propeller i is faulty (bent or cracked)."""
        return self.conditions > 0

    @property
    def labels(self) -> np.ndarray:
        """(B,) the paper's label 1..16 of each flight."""
        return np.array([label_from_mask(m) for m in self.fault_mask], dtype=np.int64)

    def features(self, names: Sequence[str]) -> np.ndarray:
        """(B, T, F) float32 features via the monitor's own module."""
        return compute_features(self.signals, names)

    def subset(self, idx: np.ndarray, name: str | None = None) -> FaultDataset:
        idx = np.asarray(idx)
        return FaultDataset(
            name=name or self.name,
            vehicle_name=self.vehicle_name,
            sample_rate_hz=self.sample_rate_hz,
            signals={k: v[idx] for k, v in self.signals.items()},
            conditions=self.conditions[idx],
            payload_kg=self.payload_kg[idx],
            waypoint_set=tuple(self.waypoint_set[i] for i in idx),
            manifest=self.manifest,
            onset_step=None if self.onset_step is None else self.onset_step[idx],
        )

    def check_model(self, vehicle_name: str, sample_rate_hz: float, features: Sequence[str], where: str = "model") -> None:
        """Raise ModelError naming the mismatch if this data set cannot feed a model with these settings."""
        if vehicle_name != self.vehicle_name:
            raise ModelError(
                f"data set {self.name!r} was simulated for vehicle {self.vehicle_name!r}, "
                f"but {where} was trained for {vehicle_name!r}"
            )
        if abs(float(sample_rate_hz) - self.sample_rate_hz) > 1e-9:
            raise ModelError(
                f"data set {self.name!r} is sampled at {self.sample_rate_hz} Hz, {where} expects {sample_rate_hz} Hz"
            )
        if len(features):
            compute_features({k: v[:1, :1] for k, v in self.signals.items()}, features)  # raises on unknown names


def concat(datasets: Sequence[FaultDataset], name: str) -> FaultDataset:
    """Join data sets of one vehicle and grid into one (flights appended)."""
    first = datasets[0]
    for d in datasets[1:]:
        d.check_model(first.vehicle_name, first.sample_rate_hz, (), where=f"data set {first.name!r}")
        if d.n_steps != first.n_steps:
            raise ModelError(f"data set {d.name!r} has {d.n_steps} steps per flight, {first.name!r} has {first.n_steps}")
    onset = None
    if any(d.onset_step is not None for d in datasets):
        onset = np.concatenate([d.onset_step if d.onset_step is not None else np.zeros(d.n_flights, np.int64) for d in datasets])
    return FaultDataset(
        name=name,
        vehicle_name=first.vehicle_name,
        sample_rate_hz=first.sample_rate_hz,
        signals={k: np.concatenate([d.signals[k] for d in datasets]) for k in SIGNALS},
        conditions=np.concatenate([d.conditions for d in datasets]),
        payload_kg=np.concatenate([d.payload_kg for d in datasets]),
        waypoint_set=tuple(w for d in datasets for w in d.waypoint_set),
        manifest={"kind": "concat", "parts": [d.manifest for d in datasets]},
        onset_step=onset,
    )


def save_dataset(path: str | Path, ds: FaultDataset) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        "format_version": FORMAT_VERSION,
        "name": ds.name,
        "vehicle_name": ds.vehicle_name,
        "sample_rate_hz": ds.sample_rate_hz,
        "waypoint_set": list(ds.waypoint_set),
        "manifest": ds.manifest,
    }
    arrays = {f"signal_{k}": np.asarray(v, np.float32) for k, v in ds.signals.items()}
    arrays["conditions"] = ds.conditions.astype(np.int8)
    arrays["labels"] = ds.labels  # redundant with conditions, kept for readers that only want the label
    arrays["payload_kg"] = ds.payload_kg.astype(np.float64)
    if ds.onset_step is not None:
        arrays["onset_step"] = ds.onset_step.astype(np.int64)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, meta=np.array(json.dumps(meta, default=str)), **arrays)
    tmp.replace(path)
    return path


def load_dataset(path: str | Path) -> FaultDataset:
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"{path}: data set file not found")
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            signals = {k[len("signal_") :]: z[k] for k in z.files if k.startswith("signal_")}
            conditions = z["conditions"].astype(np.int8)
            payload = z["payload_kg"]
            onset = z["onset_step"] if "onset_step" in z.files else None
    except (OSError, ValueError, KeyError) as exc:
        raise ModelError(f"{path}: not a propwatch data set: {exc}") from exc
    if meta.get("format_version") != FORMAT_VERSION:
        raise ModelError(f"{path}: unsupported data set format_version {meta.get('format_version')}")
    return FaultDataset(
        name=meta["name"],
        vehicle_name=meta["vehicle_name"],
        sample_rate_hz=float(meta["sample_rate_hz"]),
        signals=signals,
        conditions=conditions,
        payload_kg=payload,
        waypoint_set=tuple(meta["waypoint_set"]),
        manifest=meta.get("manifest", {}),
        onset_step=onset,
    )


__all__ = ["FaultDataset", "concat", "save_dataset", "load_dataset", "CONDITION_NAMES", "SAMPLE_RATE_HZ"]
