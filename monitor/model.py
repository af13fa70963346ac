"""The classifier as shipped: an ONNX file whose metadata says how to feed it.

Contract (written by ``offline`` export, checked here at load):
- input ``features``: float32 (batch, window, n_features), raw (un-normalised)
  features in the order of metadata ``features``; the graph normalises.
- outputs ``label_probability`` (batch, 16), labels 1..16 in order, and
  ``fault_probability`` (batch, 4), P(propeller i faulty), PX4 rotor order.
- metadata_props (JSON values), key prefix ``propwatch.``:
  ``format_version`` (1), ``features`` (list), ``sample_rate_hz``, ``window``,
  ``normalization`` ({mean, std}), ``class_names``, ``label_table``
  ({"1": [], "2": [1], ...}), ``vehicle`` ({name, esc}), ``training_manifest``.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from monitor.config import from_mapping
from monitor.errors import ConfigError, ModelError
from monitor.esc import PAPER_ESC, EscCurve
from monitor.features import check_feature_names

log = logging.getLogger("propwatch.model")

# onnxruntime 1.32 starts a telemetry thread when it loads that looks up mobile.events.data.microsoft.com
# every few seconds (seen with strace in the daemon): an onboard monitor must not. Read when the library
# loads, so it is set before the lazy import below.
os.environ.setdefault("ORT_DISABLE_TELEMETRY", "1")

META_PREFIX = "propwatch."
REQUIRED_META = ("format_version", "features", "sample_rate_hz", "window", "normalization", "label_table")
INPUT_NAME = "features"
OUTPUT_LABELS = "label_probability"
OUTPUT_FAULTS = "fault_probability"


@dataclass(frozen=True)
class ModelInfo:
    features: tuple[str, ...]
    sample_rate_hz: float
    window: int
    metadata: dict[str, Any]


class Classifier:
    """onnxruntime on the CPU provider with a fixed thread count."""

    def __init__(self, path: str | Path, threads: int = 1):
        import onnxruntime as ort

        self.path = Path(path)
        if not self.path.is_file():
            raise ModelError(f"{self.path}: model file not found")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        opts.inter_op_num_threads = 1
        # With more than one thread, idle pool threads would spin-wait between the 20 Hz inferences.
        opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
        opts.add_session_config_entry("session.inter_op.allow_spinning", "0")
        opts.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(self.path), opts, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types
            raise ModelError(f"{self.path}: not a loadable ONNX model: {exc}") from exc
        self.info = self._read_info()

    def _read_info(self) -> ModelInfo:
        props = self.session.get_modelmeta().custom_metadata_map
        meta: dict[str, Any] = {}
        for k, v in props.items():
            if k.startswith(META_PREFIX):
                try:
                    meta[k[len(META_PREFIX) :]] = json.loads(v)
                except json.JSONDecodeError as exc:
                    raise ModelError(f"{self.path}: metadata {k} is not JSON: {exc}") from exc
        missing = [k for k in REQUIRED_META if k not in meta]
        if missing:
            raise ModelError(
                f"{self.path}: not a propwatch model, metadata missing {', '.join(META_PREFIX + k for k in missing)}"
            )
        if meta["format_version"] != 1:
            raise ModelError(f"{self.path}: unsupported format_version {meta['format_version']}")
        feats = tuple(meta["features"])
        try:
            check_feature_names(feats)
        except ModelError as exc:
            raise ModelError(f"{self.path}: {exc}") from None
        inputs = {i.name: i for i in self.session.get_inputs()}
        outputs = {o.name for o in self.session.get_outputs()}
        if INPUT_NAME not in inputs or not {OUTPUT_LABELS, OUTPUT_FAULTS} <= outputs:
            raise ModelError(f"{self.path}: expected input '{INPUT_NAME}' and outputs '{OUTPUT_LABELS}', '{OUTPUT_FAULTS}'")
        shape = inputs[INPUT_NAME].shape
        if len(shape) != 3 or shape[1] != meta["window"] or shape[2] != len(feats):
            raise ModelError(f"{self.path}: input shape {shape} does not match window {meta['window']} x {len(feats)} features")
        return ModelInfo(feats, float(meta["sample_rate_hz"]), int(meta["window"]), meta)

    def check_compatible(self, features: tuple[str, ...], sample_rate_hz: float, window: int) -> None:
        """Raise ModelError naming the mismatch if the data pipeline differs from the model's."""
        i = self.info
        if tuple(features) != i.features:
            raise ModelError(f"{self.path}: model expects features {list(i.features)}, got {list(features)}")
        if abs(sample_rate_hz - i.sample_rate_hz) > 1e-9:
            raise ModelError(f"{self.path}: model expects {i.sample_rate_hz} Hz, got {sample_rate_hz} Hz")
        if window != i.window:
            raise ModelError(f"{self.path}: model expects window {i.window}, got {window}")

    def predict(self, windows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, window, F) raw features -> (label_probability (N,16), fault_probability (N,4))."""
        x = np.ascontiguousarray(windows, dtype=np.float32)
        if x.ndim != 3 or x.shape[1:] != (self.info.window, len(self.info.features)):
            raise ModelError(f"{self.path}: windows must be (N, {self.info.window}, {len(self.info.features)}), got {x.shape}")
        if len(x) == 0:
            return np.empty((0, 16), np.float32), np.empty((0, 4), np.float32)
        labels, faults = self.session.run([OUTPUT_LABELS, OUTPUT_FAULTS], {INPUT_NAME: x})
        return labels, faults


def choose_esc(classifier: Classifier, vehicle_path: str) -> EscCurve:
    """The ESC curve: a vehicle YAML if given, else the model's training vehicle, else the paper's.

    One rule for the daemon and for diagnose, so both convert motor commands identically.
    """
    if vehicle_path:
        log.info("ESC curve from vehicle file %s", vehicle_path)
        from monitor.vehicle import load_vehicle

        return load_vehicle(vehicle_path).esc
    esc = (classifier.info.metadata.get("vehicle") or {}).get("esc")
    if esc:
        try:
            return from_mapping(EscCurve, esc, origin=f"{classifier.path} metadata propwatch.vehicle.esc")[0]
        except ConfigError as exc:
            raise ModelError(str(exc)) from None
    log.warning("model %s carries no ESC curve; using the paper's fit", classifier.path)
    return PAPER_ESC
