"""propwatch fleet ingest|report: a fleet's logs into a propeller-health database, and its web report.

    propwatch fleet ingest LOG_OR_DIR... --db fleet.duckdb [--ray auto|ADDRESS|off] [--workers N]
                           [--format crazypad] [--vehicle YAML] [--model ONNX ...]
                           [--vehicle-from-dir N] [--export fleet.parquet] [--json]
    propwatch fleet report --db fleet.duckdb --out site/

ingest --json prints {"db", "found", "already_known", "other_model", "new", "ok", "no_verdict", "error",
"logs_per_s", "mb_per_s", "ray_start_s", "process_s", "total_s", ...}. Exit code 0 when every
new log was read (with or without a verdict), 1 when some log became an error row, 2 on bad
arguments, an unusable database or an unreachable cluster.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _positive(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="propwatch fleet", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    i = sub.add_parser("ingest", help="diagnose new logs into the fleet database")
    i.add_argument("paths", nargs="+", metavar="PATH", help="log files, folders (walked) or globs: .tlog .ulg .bin .csv[.gz]")
    i.add_argument("--db", required=True, help="DuckDB file (created)")
    i.add_argument(
        "--ray",
        default="auto",
        metavar="auto|ADDRESS|off",
        help="auto: start Ray on this machine (default); HOST:PORT: join that cluster; off: no Ray, one process",
    )
    i.add_argument("--workers", type=_positive, default=None, help="local Ray: worker processes (default: every core)")
    i.add_argument(
        "--format", dest="fmt", default=None, help="CSV mapping for .csv/.csv.gz logs (monitor/formats.yaml, e.g. crazypad)"
    )
    i.add_argument("--vehicle", default=None, help="vehicle YAML for every log (its ESC curve and shipped model, as diagnose)")
    i.add_argument(
        "--model",
        action="append",
        default=None,
        help="classifier ONNX (repeatable: each log gets the first whose ESC command unit matches it); "
        "default: the shipped models",
    )
    i.add_argument("--hop", type=_positive, default=20, help="classify one window every HOP steps (default 20 = 1 s)")
    i.add_argument(
        "--vehicle-from-dir",
        type=_positive,
        default=None,
        metavar="N",
        help="vehicle id = name of the log's N-th parent folder (1 = the folder holding it) when the log carries no id",
    )
    i.add_argument("--batch", type=_positive, default=32, help="rows per database transaction (default 32)")
    i.add_argument("--retry-errors", action="store_true", help="re-run logs whose earlier attempt is an error row")
    i.add_argument(
        "--rediagnose",
        action="store_true",
        help="run every found log again, known or not, replacing its row (after upgrading propwatch or a model)",
    )
    i.add_argument(
        "--rehash",
        action="store_true",
        help="hash every file again (default: a path with the size and mtime of its row is known)",
    )
    i.add_argument("--export", default=None, metavar="PARQUET", help="also write the whole table to this Parquet file")
    i.add_argument("--json", action="store_true", help="print the summary as JSON")
    i.add_argument("--no-progress", action="store_true", help="no progress bar")
    r = sub.add_parser("report", help="write the static fleet web site")
    r.add_argument("--db", required=True)
    r.add_argument("--out", required=True, help="folder for index.html, flights.html, vehicles/")
    r.add_argument(
        "--pictures",
        choices=("action", "latest", "all", "none"),
        default="action",
        help="flights drawn as diagnose --report draws them, from their logs: those to act on (default), "
        "those and each vehicle's latest, all, none",
    )
    r.add_argument("--json", action="store_true", help="print {index, vehicles, flights} as JSON")
    return p


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    if a.command == "ingest":
        return _ingest(a)
    from fleet.report import write_site

    res = write_site(a.db, a.out, a.pictures)
    if a.json:
        json.dump(res, sys.stdout)
        sys.stdout.write("\n")
    else:
        print(f"fleet report: {res['index']} ({res['vehicles']} vehicles, {res['flights']} flights, {res['pictures']} drawn)")
    return 0


def drop_if_empty(db: Path) -> None:
    """Remove a database this run created and filled with no flight (a run that failed before its first batch):
    a later run, or a reader, should not find an empty store that looks like a fleet with no logs."""
    if not db.is_file():
        return
    from fleet.errors import need

    try:
        con = need("duckdb").connect(str(db), read_only=True)
        try:
            n = con.execute("SELECT count(*) FROM flights").fetchone()[0]
        finally:
            con.close()
    except Exception:  # noqa: BLE001 - no flights table (created half-way): nothing worth keeping
        n = 0
    if n == 0:
        for p in (db, db.with_name(db.name + ".wal")):
            p.unlink(missing_ok=True)


def _ingest(a: argparse.Namespace) -> int:
    from fleet.ingest import ingest
    from fleet.worker import IngestSettings

    settings = IngestSettings(
        models=tuple(a.model or ()), vehicle_yaml=a.vehicle, csv_format=a.fmt, hop=a.hop, vehicle_from_dir=a.vehicle_from_dir
    )
    fresh = not Path(a.db).exists()
    try:
        s = ingest(
            a.paths,
            a.db,
            settings,
            ray_address=a.ray,
            workers=a.workers,
            batch_rows=a.batch,
            progress=not a.no_progress,
            export=a.export,
            retry_errors=a.retry_errors,
            rehash=a.rehash,
            rediagnose=a.rediagnose,
        )
    except BaseException:
        if fresh:
            drop_if_empty(Path(a.db))
        raise
    if a.json:
        json.dump(s.to_json(), sys.stdout)
        sys.stdout.write("\n")
    else:
        rate = f", {s.to_json()['logs_per_s']} logs/s" if s.process_s > 0 else ""
        print(
            f"{s.db}: {s.found} logs found, {s.already_known} already known, {s.new} new "
            f"({s.ok} verdicts, {s.no_verdict} no verdict, {s.error} errors){rate}"
        )
        if s.other_model:
            print(f"{s.other_model} known logs were diagnosed by another model than this run's: --rediagnose to refresh them")
        if s.export:
            print(f"exported {s.export}")
    return 1 if s.error else 0
