"""Extra tables of the classifier card, kept as data beside the model (``models/classifier.card-tables.json``).

Every table in the card beyond the shipped model's own figures (its manifest)
is a ``CardTable`` in that tracked file, written by the command named in its
``produced_by`` (all run by ``make card``). The card generator reads only the
manifest and this file, so every figure in the card comes from the repository.
To add a table (e.g. "model x simulator" rows), build a ``CardTable`` and
``upsert_table(path, table)``; tables render in file order.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from monitor.errors import ModelError

TABLES_FILE = "classifier.card-tables.json"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class CardTable:
    key: str  # stable id, e.g. "ablation"
    title: str
    note: str  # what the rows are, in a sentence or a paragraph (markdown)
    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]  # cells already formatted as text
    produced_by: str  # the command that writes this table

    def __post_init__(self) -> None:
        bad = [i for i, r in enumerate(self.rows) if len(r) != len(self.columns)]
        if bad:
            raise ModelError(f"card table {self.key!r}: rows {bad} do not have {len(self.columns)} cells")

    def markdown(self) -> str:
        lines = [f"## {self.title}", ""]
        if self.note:
            lines += [self.note, ""]
        lines.append("| " + " | ".join(self.columns) + " |")
        lines.append("|" + "---|" * len(self.columns))
        lines += ["| " + " | ".join(r) + " |" for r in self.rows]
        lines += ["", f"Produced by: `{self.produced_by}`.", ""]
        return "\n".join(lines)


def load_tables(path: str | Path) -> list[CardTable]:
    path = Path(path)
    if not path.is_file():
        return []
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if doc.get("format_version") != FORMAT_VERSION:
            raise ModelError(f"{path}: unsupported format_version {doc.get('format_version')}")
        return [
            CardTable(t["key"], t["title"], t["note"], tuple(t["columns"]), tuple(tuple(r) for r in t["rows"]), t["produced_by"])
            for t in doc["tables"]
        ]
    except (ValueError, KeyError, TypeError) as exc:
        raise ModelError(f"{path}: not a card tables file: {exc}") from exc


def save_tables(path: str | Path, tables: list[CardTable]) -> Path:
    path = Path(path)
    doc = {"format_version": FORMAT_VERSION, "tables": [asdict(t) for t in tables]}
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(doc, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def upsert_table(path: str | Path, table: CardTable) -> Path:
    """Replace the table with the same key, or append it."""
    tables = load_tables(path)
    keys = [t.key for t in tables]
    if table.key in keys:
        tables[keys.index(table.key)] = table
    else:
        tables.append(table)
    return save_tables(path, tables)
