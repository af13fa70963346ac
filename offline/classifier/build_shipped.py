"""Build the shipped classifier: ``models/classifier.onnx`` + card + manifest (``make classifier``).

    python -m offline.classifier.build_shipped --out models [--data out/shipped-data] [--reuse]

1. Simulate the training set RN (random routes, payload 0..0.6 kg, bent, cracked or mixed per flight, every
   flight's physics and fault signature drawn from the register of unmeasured assumptions with the airframe
   as its file says = ``make dataset-randomised``) and the paper's evaluation sets A, B, C for each fault.
2. Train the CNN (the ablation row ``SHIPPED_ROW``: relative-RPM features, the yaw-effectiveness
   block), or take that row's checkpoint (``--checkpoint``).
3. Export ONNX, then score it with onnxruntime (what the monitor runs): the
   paper's table, false alarms per healthy flight-hour and detection time
   after an in-flight onset, with the daemon's alert rule.
4. Write the model card and manifest beside the model.
Not run by tests: ~35 minutes on 2 cores (training ~30 of them).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from monitor.config import to_mapping
from monitor.model import Classifier
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle
from offline.classifier.card import ablation_card_table, write_card
from offline.classifier.card_tables import TABLES_FILE, CardTable, load_tables, upsert_table
from offline.classifier.evaluate import Result, evaluate_dataset, format_table
from offline.classifier.experiments import EVAL_SETS, EXPERIMENTS
from offline.classifier.export import export_onnx
from offline.classifier.onboard import DEFAULT_RULE, RULES, ShiftFlights, rule_sweep, simulate_onset
from offline.classifier.train import TrainConfig, load_checkpoint, train
from offline.dataset.generate import PRESETS, DatasetSpec, generate
from offline.dataset.records import load_dataset, save_dataset
from offline.manifest import make_manifest, write_manifest
from offline.propellers import MODELS_DIR

SHIPPED_ROW = "randomised physics x60 +yaw robust dropout"  # the ablation row the shipped model is trained as
SHIPPED = TrainConfig(seed=0, **EXPERIMENTS[SHIPPED_ROW][1])
TRAIN_SET = EXPERIMENTS[SHIPPED_ROW][0][0]


def propeller_kind() -> str:
    """The paper's LSTM propellers when their weights are built, else the analytic fault signatures."""
    return "lstm" if any(Path(MODELS_DIR).glob("*.npz")) else "quadratic"


def training_spec(flights_per_label: int) -> DatasetSpec:
    """= ``make dataset-randomised`` (``--name RN ... --seed 7``; custom sets add 50), so --reuse finds it.
    Randomised physics draws a signature per damaged rotor, which only the analytic propellers apply."""
    return DatasetSpec(
        TRAIN_SET,
        fault=TRAIN_SET.split("-", 1)[1],
        waypoints=("random",),
        payload_kg=(0.0, 0.6),
        flights_per_label=flights_per_label,
        propellers="quadratic",
        physics="randomised",
        airframe="nominal",
        seed=57,
    )


def data_specs(kind: str, flights_per_label: int, eval_flights_per_label: int) -> list[DatasetSpec]:
    specs = [training_spec(flights_per_label)]
    for i, fault in enumerate(("bent", "cracked")):
        for j, s in enumerate(("A", "B", "C")):
            specs.append(
                DatasetSpec(
                    f"{s}-{fault}",
                    fault=fault,
                    flights_per_label=eval_flights_per_label,
                    propellers=kind,
                    seed=100 * i + j,
                    **PRESETS[s],
                )
            )
    return specs


def obtain(spec: DatasetSpec, vehicle, data_dir: Path, reuse: bool):
    path = data_dir / f"{spec.name}.npz"
    if reuse and path.is_file():
        ds = load_dataset(path)
        if ds.manifest.get("config") == to_mapping(spec):
            return ds
        print(f"{path}: made with another spec, regenerating")
    ds = generate(spec, vehicle)
    save_dataset(path, ds)
    write_manifest(data_dir / f"{spec.name}.manifest.json", ds.manifest)
    return ds


def result_from_dict(d: dict) -> Result:
    return Result(
        d["name"],
        d["windows"],
        d["accuracy"],
        d["fault_precision"],
        d["fault_recall"],
        np.zeros((16, 16), np.int64),
        tuple(d["per_propeller_accuracy"]),
    )


def ablation_from(folder: Path, tracked: CardTable | None = None) -> CardTable | None:
    """The ablation card table from a folder of experiments JSON, None when empty. Rows of ``tracked`` (the
    card's table so far) that the folder does not hold are kept: a folder with one new row adds that row."""
    rows = []
    for name in EXPERIMENTS:
        f = folder / f"{name}.json"
        if f.is_file():
            rows.append(json.loads(f.read_text(encoding="utf-8")))
    if not rows:
        return None
    table = ablation_card_table(rows, EVAL_SETS)
    if tracked is None or tracked.columns != table.columns:
        return table
    by_name = {r[0]: r for r in tracked.rows} | {r[0]: r for r in table.rows}
    order = [n for n in EXPERIMENTS if n in by_name] + [n for n in by_name if n not in EXPERIMENTS]
    return dataclasses.replace(table, rows=tuple(by_name[n] for n in order))


def write_card_from(out: Path, manifest: dict, results: list[Result], ablation_dir: Path | None) -> Path:
    """Refresh the ablation table from ``ablation_dir`` (when given and not empty), then write the card from the
    manifest and the tracked tables file only."""
    tables_path = out / TABLES_FILE
    tracked = next((t for t in load_tables(tables_path) if t.key == "ablation"), None) if tables_path.is_file() else None
    table = ablation_from(ablation_dir, tracked) if ablation_dir is not None else None
    if table is not None:
        upsert_table(tables_path, table)
    return write_card(out / "classifier.card.md", manifest, results, load_tables(tables_path))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m offline.classifier.build_shipped",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", type=Path, default=Path("models"))
    p.add_argument("--data", type=Path, default=Path("out/shipped-data"))
    p.add_argument("--reuse", action="store_true", help="reuse data sets in --data made with the same spec")
    p.add_argument("--flights-per-label", type=int, default=60, help=f"training set {TRAIN_SET}")
    p.add_argument("--eval-flights-per-label", type=int, default=5)
    p.add_argument("--epochs", type=int, default=SHIPPED.epochs)
    p.add_argument("--hop", type=int, default=10, help="evaluation window hop (10: every 0.5 s; 1 is 10x the time)")
    p.add_argument("--onboard-flights", type=int, default=32)
    p.add_argument("--vehicle", type=Path, default=DEFAULT_VEHICLE)
    p.add_argument(
        "--ablation",
        type=Path,
        default=None,
        help="folder of experiments JSON (python -m offline.classifier.experiments): refreshes the ablation table in "
        f"{TABLES_FILE}; the build also records the shipped row there (default out/experiments)",
    )
    p.add_argument(
        "--checkpoint",
        type=Path,
        help="ship this checkpoint of the shipped row (python -m offline.classifier.experiments --only ROW writes "
        "out/experiments/ROW.pt) instead of training it again; its config and training data must match",
    )
    p.add_argument(
        "--card-only",
        action="store_true",
        help=f"rewrite the card from the existing manifest and {TABLES_FILE} only (plus --ablation when given)",
    )
    a = p.parse_args(argv)
    if a.card_only:
        manifest = json.loads((a.out / "classifier.manifest.json").read_text(encoding="utf-8"))
        results = [result_from_dict(r) for r in manifest["figures"]["results"]]
        write_card_from(a.out, manifest, results, a.ablation)
        print(f"rewrote {a.out / 'classifier.card.md'}")
        return 0
    if a.ablation is None:
        a.ablation = Path("out/experiments")
    t0 = time.time()
    vehicle = load_vehicle(a.vehicle)
    kind = propeller_kind()
    specs = data_specs(kind, a.flights_per_label, a.eval_flights_per_label)
    data = {s.name: obtain(s, vehicle, a.data, a.reuse) for s in specs}
    cfg = dataclasses.replace(SHIPPED, epochs=a.epochs)
    if a.checkpoint:
        m = load_checkpoint(a.checkpoint)
        if m.config != cfg:
            raise SystemExit(f"{a.checkpoint}: trained with {m.config}, not the shipped {cfg}")
        if m.training_manifest.get("config") != data[TRAIN_SET].manifest.get("config"):
            raise SystemExit(f"{a.checkpoint}: trained on another data set than {TRAIN_SET} of this build")
    else:
        m = train(data[TRAIN_SET], cfg)
    m.training_manifest = {
        "train_config": {**dataclasses.asdict(cfg), "features": list(cfg.features)},
        "data": data[TRAIN_SET].manifest,
        "propellers": data[TRAIN_SET].manifest["config"]["propellers"],
    }
    onnx_path = export_onnx(m, a.out / "classifier.onnx")
    clf = Classifier(onnx_path)
    results = []
    for name, ds in data.items():
        if name == TRAIN_SET:
            results.append(
                evaluate_dataset(clf.predict, ds, cfg.features, cfg.window, a.hop, m.test_flights, f"{name} (test split)")
            )
        else:
            ds.check_model(clf.info.metadata["vehicle"]["name"], clf.info.sample_rate_hz, clf.info.features)
            results.append(evaluate_dataset(clf.predict, ds, cfg.features, cfg.window, a.hop))
    print(format_table(results))
    # The shipped configuration is the ablation's last row: record it there instead of training it twice.
    a.ablation.mkdir(parents=True, exist_ok=True)
    row = {
        "name": SHIPPED_ROW,
        "train_sets": [TRAIN_SET],
        "config": m.training_manifest["train_config"],
        "history": m.history,
        "results": [{k: v for k, v in r.to_dict().items() if k != "confusion"} for r in results],
    }
    (a.ablation / f"{SHIPPED_ROW}.json").write_text(json.dumps(row, indent=2) + "\n", encoding="utf-8")
    onboard_cfg = ShiftFlights(n_flights=a.onboard_flights, propellers=kind)
    sweep = rule_sweep(
        clf.predict,
        simulate_onset(vehicle, onboard_cfg, healthy=True),
        simulate_onset(vehicle, onboard_cfg, healthy=False),
        cfg.features,
        cfg.window,
        RULES,
    )
    alarms, detect = sweep["default"]["false_alarms"], sweep["default"]["detection"]
    print(json.dumps(sweep, indent=1))
    figures = {
        "results": [{k: v for k, v in r.to_dict().items() if k != "confusion"} for r in results],
        "hop": a.hop,
        "false_alarms": alarms,
        "detection": detect,
        "alert_rule": dataclasses.asdict(DEFAULT_RULE),
        "rule_sweep": sweep,
        "onboard_flights": dataclasses.asdict(onboard_cfg),
    }
    manifest = make_manifest(
        "classifier",
        {
            "train": m.training_manifest["train_config"],
            "propellers": m.training_manifest["propellers"],
            "evaluation_propellers": kind,
            "data_specs": [to_mapping(s) for s in specs],
            # the register ranges the training flights were drawn from (None for fixed physics)
            "training_assumptions": data[TRAIN_SET].manifest.get("assumptions"),
        },
        cfg.seed,
        model=str(onnx_path),
        history=m.history,
        figures=figures,
        trained_by="checkpoint " + str(a.checkpoint) if a.checkpoint else "this build",
        build_seconds=round(time.time() - t0, 1),
    )
    write_manifest(a.out / "classifier.manifest.json", manifest)
    write_card_from(a.out, manifest, results, a.ablation)
    print(f"wrote {onnx_path}, classifier.card.md, classifier.manifest.json in {time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
