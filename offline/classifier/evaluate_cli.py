"""propwatch evaluate classifier: accuracy, confusion matrix PNG and fault precision/recall per data set, beside
the paper.

The model is an ONNX file (what ships) or a torch checkpoint (.pt). For a data
set the model was trained on, only its held-out flights are scored (--split test).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from monitor.errors import ModelError
from monitor.model import Classifier
from offline.classifier.evaluate import evaluate_dataset, format_table, plot_confusion
from offline.dataset.records import load_dataset


class LoadedModel:
    """ONNX or checkpoint behind one predict(windows) and the settings a data set must match."""

    def __init__(self, path: Path):
        if path.suffix == ".onnx":
            c = Classifier(path)
            self.features, self.window, self.rate = c.info.features, c.info.window, c.info.sample_rate_hz
            self.vehicle = c.info.metadata.get("vehicle", {}).get("name", "")
            split = c.info.metadata.get("split", {})
            self.dataset_name, self.test_flights = split.get("dataset_name", ""), split.get("test_flights")
            self.predict = c.predict
        else:
            from offline.classifier.train import load_checkpoint, predict_probabilities  # torch only for a .pt

            m = load_checkpoint(path)
            self.features, self.window, self.rate = m.config.features, m.config.window, m.sample_rate_hz
            self.vehicle = m.vehicle.get("name", "")
            self.dataset_name, self.test_flights = m.dataset_name, m.test_flights
            self.predict = lambda w: predict_probabilities(m, w)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="propwatch evaluate classifier", description=__doc__)
    p.add_argument("model", type=Path, help=".onnx or .pt")
    p.add_argument("datasets", nargs="*", type=Path, help="data set .npz files")
    p.add_argument("--out", type=Path, default=Path("out/evaluate"), help="folder for PNGs and results.json")
    p.add_argument("--hop", type=int, default=1, help="window hop (1 = every window, as the paper)")
    p.add_argument("--test-flights", default="", help="comma-separated flight indices to score (e.g. the held-out flights of A)")
    p.add_argument("--json", action="store_true", help="print results as JSON instead of the table")
    p.add_argument(
        "--evalsim",
        action="append",
        default=[],
        type=Path,
        help="an evaluation-only set folder from 'propwatch evaluate evalsim' (repeatable; .onnx models; the ω²-share baseline is a row)",
    )
    a = p.parse_args(argv)
    if not a.datasets and not a.evalsim:
        p.error("give data set .npz files and/or --evalsim folders")
    if a.evalsim and a.model.suffix != ".onnx":
        p.error("--evalsim scores the model as shipped: give an .onnx model")
    model = LoadedModel(a.model)
    results = []
    for path in a.datasets:
        ds = load_dataset(path)
        ds.check_model(model.vehicle, model.rate, model.features, where=str(a.model))
        flights = None
        name = ds.name
        if ds.name == model.dataset_name and model.test_flights is not None:
            # The training data set: score only the flights the model never saw.
            flights, name = np.array(model.test_flights, np.int64), f"{ds.name} (test split)"
        if a.test_flights:
            flights = np.array([int(s) for s in a.test_flights.split(",")])
            if flights.max() >= ds.n_flights:
                raise ModelError(f"--test-flights: {path} has only {ds.n_flights} flights")
        r = evaluate_dataset(model.predict, ds, model.features, model.window, a.hop, flights, name)
        plot_confusion(r, a.out / f"confusion_{ds.name}.png")
        results.append(r)
    evalsim = []
    if a.evalsim:
        from offline.evalsim.score import score_folder

        evalsim = [dict(zip(("set", "rows"), score_folder(d, a.model), strict=True), folder=str(d)) for d in a.evalsim]
    a.out.mkdir(parents=True, exist_ok=True)
    payload = {"model": str(a.model), "hop": a.hop, "results": [r.to_dict() for r in results], "evalsim": evalsim}
    (a.out / "results.json").write_text(json.dumps(payload, indent=2) + "\n", encoding="utf-8")
    if a.json:
        print(json.dumps(payload))
    else:
        if results:
            print(format_table(results))
        if evalsim:
            from offline.evalsim.score import format_rows

            print("\nevaluation-only simulator (offline/evalsim; never used for training):")
            for e in evalsim:
                print(format_rows(e["rows"], e["set"]))
        print(f"confusion matrices and results.json in {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
