"""ONNX export to the contract in ``monitor.model`` (input ``features`` raw, batch dynamic).

The graph holds the normalisation and both outputs; the ``propwatch.*``
metadata holds what the monitor needs to feed it (features, rate, window,
normalisation, labels, vehicle, training manifest).
"""

from __future__ import annotations

import json
from pathlib import Path

import onnx
import torch

from monitor.labels import LABEL_TABLE, class_names
from monitor.model import INPUT_NAME, META_PREFIX, OUTPUT_FAULTS, OUTPUT_LABELS
from offline.classifier.cnn import ContractModule
from offline.classifier.train import TrainedModel

OPSET = 18  # the dynamo exporter's lowest supported opset


def metadata(m: TrainedModel) -> dict[str, object]:
    return {
        "format_version": 1,
        "features": list(m.config.features),
        "sample_rate_hz": m.sample_rate_hz,
        "window": m.config.window,
        "normalization": m.normalizer.to_dict(),
        "class_names": class_names(),
        "label_table": {str(k): list(v) for k, v in LABEL_TABLE.items()},
        "vehicle": m.vehicle,
        "head": m.net.cfg.head,
        "training_manifest": m.training_manifest,
        # Which flights of the training data set were held out, so evaluation can score only those.
        "split": {"dataset_name": m.dataset_name, "train_flights": m.train_flights, "test_flights": m.test_flights},
    }


def export_onnx(m: TrainedModel, path: str | Path, extra_metadata: dict | None = None) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    module = ContractModule(m.net).eval()
    example = torch.zeros(2, m.config.window, len(m.config.features))
    # torch's current (dynamo) exporter: torch.export traces the module, onnxscript translates it.
    batch = torch.export.Dim("batch", min=1)
    program = torch.onnx.export(
        module,
        (example,),
        dynamo=True,
        input_names=[INPUT_NAME],
        output_names=[OUTPUT_LABELS, OUTPUT_FAULTS],
        dynamic_shapes=({0: batch},),
        opset_version=OPSET,
        optimize=True,
        verbose=False,
    )
    # One self-contained file (the weights inside, no external data): the monitor loads bytes.
    model = program.model_proto
    meta = {**metadata(m), **(extra_metadata or {})}
    del model.metadata_props[:]
    for k, v in meta.items():
        p = model.metadata_props.add()
        p.key, p.value = META_PREFIX + k, json.dumps(v, sort_keys=True, default=str)
    model.producer_name = "propwatch"
    onnx.checker.check_model(model)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(model.SerializeToString())
    tmp.replace(path)
    return path
