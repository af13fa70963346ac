"""Score a predictor on an evalsim set folder (written by ``sets.write_set``).

A *predictor* is a callable ``FlightTable -> dict`` returning at least
``faulty_propellers`` (PX4 numbers), optionally ``hypotheses``
(``[{"faulty_propellers": [...], "probability": p}, ...]``) and
``fault_probability`` (4 floats). Tables are read from the .tlog by
``monitor.logs`` exactly as ``propwatch diagnose`` reads a log.

Two predictors are included: ``classifier_predictor`` (the shipped ONNX
through ``monitor.diagnose``) and ``share_predictor`` (the ω²-share baseline,
``offline.share_baseline``), optionally with per-airframe healthy shares.
"""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError
from monitor.esc import PAPER_ESC
from monitor.flight import FlightTable
from monitor.labels import label_for
from monitor.logs import read_log
from offline.share_baseline import omega2_shares, share_baseline

Predictor = Callable[[FlightTable], dict]


@dataclass
class SetScore:
    name: str
    flights: int = 0
    exact: int = 0
    single_flights: int = 0
    single_exact: int = 0
    by_label: dict = field(default_factory=dict)  # label -> [right, total]
    in_set: int = 0
    set_sizes: list = field(default_factory=list)
    healthy_p: list = field(default_factory=list)  # fault_probability rows of healthy flights
    failed: list = field(default_factory=list)  # (file, reason)
    per_flight: list = field(default_factory=list)

    def summary(self) -> dict:
        hp = np.asarray(self.healthy_p, dtype=np.float64)
        return {
            "predictor": self.name,
            "flights": self.flights,
            "exact_accuracy": self.exact / self.flights if self.flights else None,
            "single_flights": self.single_flights,
            "single_accuracy": self.single_exact / self.single_flights if self.single_flights else None,
            "by_label": {str(k): v[0] / v[1] for k, v in sorted(self.by_label.items())},
            "truth_in_hypotheses": self.in_set / self.flights if self.set_sizes else None,
            "mean_set_size": float(np.mean(self.set_sizes)) if self.set_sizes else None,
            "healthy_mean_p_faulty": hp.mean(axis=0).tolist() if hp.size else None,
            "failed": self.failed,
        }


def load_set(folder: str | Path) -> tuple[dict, list[dict]]:
    """(manifest, truths) of a set folder; refuses a folder that is not an evalsim set."""
    folder = Path(folder)
    mpath = folder / "manifest.json"
    if not mpath.exists():
        raise LogFormatError(f"{folder}: no manifest.json: not an evalsim set folder")
    manifest = json.loads(mpath.read_text(encoding="utf-8"))
    if manifest.get("kind") != "propwatch-evalsim-set":
        raise LogFormatError(f"{mpath}: kind {manifest.get('kind')!r}, expected 'propwatch-evalsim-set'")
    truths = [json.loads((folder / f["truth"]).read_text(encoding="utf-8")) for f in manifest["flights"]]
    return manifest, truths


def read_tables(folder: str | Path) -> list[tuple[dict, FlightTable]]:
    manifest, truths = load_set(folder)
    return [(t, read_log(Path(folder) / t["file"], esc=PAPER_ESC, rate_hz=20.0, extras=True)) for t in truths]


def score(tables: list[tuple[dict, FlightTable]], predictor: Predictor, name: str) -> SetScore:
    s = SetScore(name)
    for truth, table in tables:
        try:
            out = predictor(table)
        except Exception as exc:  # a refusal is a result to report, not a crash of the harness
            s.failed.append((truth["file"], f"{type(exc).__name__}: {exc}"))
            out = None
        true = sorted(truth["faulty_propellers"])
        pred = sorted(out["faulty_propellers"]) if out else None
        s.flights += 1
        ok = pred == true
        s.exact += ok
        if len(true) == 1:
            s.single_flights += 1
            s.single_exact += ok
        lab = s.by_label.setdefault(label_for(true), [0, 0])
        lab[0] += ok
        lab[1] += 1
        if out and out.get("hypotheses") is not None:
            sets = [sorted(h["faulty_propellers"]) for h in out["hypotheses"]]
            s.in_set += true in sets
            s.set_sizes.append(len(sets))
        if not true and out and out.get("fault_probability") is not None:
            s.healthy_p.append(list(out["fault_probability"]))
        s.per_flight.append({"file": truth["file"], "truth": true, "predicted": pred})
    return s


def classifier_predictor(model_path: str | Path | None = None) -> Predictor:
    """The classifier through ``monitor.diagnose`` as the CLI runs it (with the paper vehicle's geometry for the
    moment balance): the verdict's propellers, P(faulty) and its hypothesis set (the conformal set when the
    model has a rule, else the moment balance's credible set, as ``diagnose --json`` gives them)."""
    from monitor.diagnose.engine import diagnose_table
    from monitor.model import Classifier
    from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle

    clf = Classifier(model_path or Path(__file__).resolve().parents[2] / "models" / "classifier.onnx")
    vehicle = load_vehicle(DEFAULT_VEHICLE)

    def predict(table: FlightTable) -> dict:
        d = diagnose_table(table, clf, hop=1, esc=PAPER_ESC, vehicle=vehicle)
        if d.verdict is None:
            raise ValueError(d.reason or "no verdict")
        return {**d.verdict, "hypotheses": d.to_json()["hypotheses"]}

    return predict


def share_predictor(healthy_shares: dict[str, np.ndarray] | None = None, airframe_of=None) -> Predictor:
    """The ω²-share baseline; with ``healthy_shares`` (airframe id -> shares) and
    ``airframe_of`` (table -> airframe id) the airframe's healthy shares are subtracted."""

    def predict(table: FlightTable) -> dict:
        sh = omega2_shares(table.motor_cmd, table.airborne)
        ref = healthy_shares.get(airframe_of(table)) if healthy_shares and airframe_of else None
        return {"faulty_propellers": [share_baseline(sh, ref)]}

    return predict


def healthy_shares_by_airframe(tables: list[tuple[dict, FlightTable]]) -> dict[str, np.ndarray]:
    """Mean ω² shares of each airframe's healthy flights (the calibration a user would fly)."""
    acc = defaultdict(list)
    for truth, table in tables:
        if not truth["faulty_propellers"] and truth.get("airframe_id"):
            acc[truth["airframe_id"]].append(omega2_shares(table.motor_cmd, table.airborne))
    return {k: np.mean(v, axis=0) for k, v in acc.items()}


def format_rows(rows: list[dict], set_name: str) -> str:
    """A plain table: one row per predictor."""

    def pct(x):
        return "-" if x is None else f"{100 * x:5.1f} %"

    head = f"{'set':<14} {'predictor':<26} {'flights':>7} {'exact':>8} {'single':>8} {'in-set':>8} {'size':>5}  healthy mean P(faulty) 1..4"
    lines = [head]
    for r in rows:
        hp = r["healthy_mean_p_faulty"]
        hp_s = "-" if hp is None else " ".join(f"{x:.2f}" for x in hp)
        size = "-" if r["mean_set_size"] is None else f"{r['mean_set_size']:.2f}"
        lines.append(
            f"{set_name:<14} {r['predictor']:<26} {r['flights']:>7} {pct(r['exact_accuracy']):>8} "
            f"{pct(r['single_accuracy']):>8} {pct(r['truth_in_hypotheses']):>8} {size:>5}  {hp_s}"
        )
    return "\n".join(lines)


def score_folder(folder: str | Path, model_path: str | Path | None = None) -> tuple[str, list[dict]]:
    """Classifier and baseline (and, for a set with airframes, the subtracted baseline) on one folder."""
    manifest, _ = load_set(folder)
    tables = read_tables(folder)
    rows = [score(tables, classifier_predictor(model_path), "classifier").summary()]
    rows.append(score(tables, share_predictor(), "ω²-share baseline").summary())
    ref = healthy_shares_by_airframe(tables)
    if ref:
        by_table = {id(tb): t["airframe_id"] for t, tb in tables}
        rows.append(score(tables, share_predictor(ref, lambda tb: by_table[id(tb)]), "ω²-share − airframe healthy").summary())
    return manifest["config"]["set"], rows
