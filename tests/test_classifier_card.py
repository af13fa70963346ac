"""The classifier card is a function of tracked files only, quotes the paper once per set, and takes extra tables."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from monitor.errors import ModelError
from offline.classifier.build_shipped import result_from_dict, write_card_from
from offline.classifier.card_tables import TABLES_FILE, CardTable, load_tables, upsert_table

MODELS = Path(__file__).resolve().parents[1] / "models"


def _copy_models(tmp_path: Path) -> tuple[dict, list]:
    for name in ("classifier.manifest.json", TABLES_FILE):
        shutil.copy(MODELS / name, tmp_path / name)
    manifest = json.loads((tmp_path / "classifier.manifest.json").read_text(encoding="utf-8"))
    return manifest, [result_from_dict(r) for r in manifest["figures"]["results"]]


def test_the_shipped_card_is_regenerated_from_tracked_files_alone(tmp_path):
    manifest, results = _copy_models(tmp_path)
    card = write_card_from(tmp_path, manifest, results, None).read_text(encoding="utf-8")
    assert card == (MODELS / "classifier.card.md").read_text(encoding="utf-8")  # `make card-text` output is committed


def test_the_paper_figure_is_quoted_once_per_set(tmp_path):
    manifest, results = _copy_models(tmp_path)
    card = write_card_from(tmp_path, manifest, results, None).read_text(encoding="utf-8")
    for figure in ("99.97 %", "85.66 %", "80.02 %"):
        assert card.count(figure) == 1, figure
    row = next(line for line in card.splitlines() if line.startswith("| B: "))
    assert "85.66" in row and row.count("%") >= 3  # paper once, then bent and cracked accuracies


def test_extra_tables_render_in_order_and_replace_by_key(tmp_path):
    manifest, results = _copy_models(tmp_path)
    table = CardTable(
        "model_x_simulator",
        "Model x simulator (exact label %)",
        "Each shipped model on each simulator's sets.",
        ("model", "own sim", "evaluation sim"),
        (("today", "99.0", "62.5"),),
        "make evaluate-sims",
    )
    before = [t.key for t in load_tables(tmp_path / TABLES_FILE)]
    upsert_table(tmp_path / TABLES_FILE, table)
    upsert_table(tmp_path / TABLES_FILE, CardTable(**{**table.__dict__, "rows": (("today", "99.0", "63.0"),)}))
    tables = load_tables(tmp_path / TABLES_FILE)
    assert before[0] == "ablation" and [t.key for t in tables] == before + ["model_x_simulator"]
    card = write_card_from(tmp_path, manifest, results, None).read_text(encoding="utf-8")
    assert "| today | 99.0 | 63.0 |" in card and "| today | 99.0 | 62.5 |" not in card
    assert card.index("## Ablation") < card.index("## Model x simulator") < card.index("## Limits")
    assert "Produced by: `make evaluate-sims`." in card


def test_a_malformed_table_is_refused_by_name(tmp_path):
    with pytest.raises(ModelError, match="bad"):
        CardTable("bad", "t", "", ("a", "b"), (("only one",),), "make x")
    (tmp_path / TABLES_FILE).write_text('{"format_version": 1, "tables": [{"key": "k"}]}', encoding="utf-8")
    with pytest.raises(ModelError, match=TABLES_FILE):
        load_tables(tmp_path / TABLES_FILE)


def test_an_experiments_folder_with_one_row_adds_it_and_keeps_the_tracked_rows(tmp_path):
    from offline.classifier.experiments import EVAL_SETS, EXPERIMENTS

    manifest, results = _copy_models(tmp_path)
    before = next(t for t in load_tables(tmp_path / TABLES_FILE) if t.key == "ablation")
    name = list(EXPERIMENTS)[-1]
    row = {"name": name, "results": [{"name": f"{e} (x)", "accuracy": 0.5} for e in EVAL_SETS]}
    folder = tmp_path / "experiments"
    folder.mkdir()
    (folder / f"{name}.json").write_text(json.dumps(row))
    write_card_from(tmp_path, manifest, results, folder)
    after = next(t for t in load_tables(tmp_path / TABLES_FILE) if t.key == "ablation")
    kept = [r for r in before.rows if r[0] != name]
    assert [r for r in after.rows if r[0] != name] == kept and len(kept) >= 5
    assert after.rows[-1] == (name, *("50.00",) * len(EVAL_SETS))


def test_the_card_states_the_torque_range_its_manifest_records_for_the_training_data(tmp_path):
    manifest, results = _copy_models(tmp_path)
    torque = manifest["config"]["training_assumptions"]["bent_torque_per_thrust_change_low_frac"]
    assert torque["low"] == -torque["high"] < 0  # the shipped model: either sign alike
    card = write_card_from(tmp_path, manifest, results, None).read_text(encoding="utf-8")
    assert f"drawn from {100 * torque['low']:+.0f}..{100 * torque['high']:+.0f} %, either sign alike" in card
    manifest["config"]["training_assumptions"]["bent_torque_per_thrust_change_low_frac"] |= {"low": -0.10, "high": 0.30}
    card = write_card_from(tmp_path, manifest, results, None).read_text(encoding="utf-8")
    assert "drawn from -10..+30 % (nobody" in card  # a range centred on a rise is not called sign-neutral
    del manifest["config"]["training_assumptions"]
    card = write_card_from(tmp_path, manifest, results, None).read_text(encoding="utf-8")
    assert "range not in this manifest" in card
