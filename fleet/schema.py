"""The fleet database (DuckDB): one row per flight log, keyed by the hash of its content.

Schema version 2 (version 1 stores are migrated in place: vehicle-memory columns added, NULL until judged).
``fleet_meta`` holds ``schema_version``; a database written by
a newer propwatch is refused by its version, one that is not a fleet database
is refused by name. Rows are inserted per batch inside one transaction, so a
run that dies leaves whole batches only, and a re-run does the rest.

``status``: ``ok`` (a verdict), ``no_verdict`` (read, but the model cannot
judge it: ``error`` says why), ``error`` (the log cannot be read: ``error``
says why). Propeller arrays are in PX4 rotor order, 4 values.
"""

from __future__ import annotations

from pathlib import Path

from fleet.errors import FleetError, need

SCHEMA_VERSION = 2

# (name, DuckDB type): the insert order of a row.
COLUMNS: tuple[tuple[str, str], ...] = (
    ("log_hash", "VARCHAR PRIMARY KEY"),  # sha256 of the file's bytes
    ("path", "VARCHAR NOT NULL"),
    ("size_bytes", "BIGINT"),
    ("mtime_ns", "BIGINT"),  # file modification time at ingest: an unchanged (path, size, mtime) is not re-hashed
    ("format", "VARCHAR"),
    ("vehicle_id", "VARCHAR"),
    ("vehicle_id_source", "VARCHAR"),  # ulog:sys_uuid, mavlink:AUTOPILOT_VERSION.uid, dataflash:..., dir:N
    ("start_time_utc", "TIMESTAMP"),  # UTC (naive), first sample of the flight table
    ("start_time_source", "VARCHAR"),  # ulog:gps, dataflash:gps, tlog:receive_time, file:mtime
    ("duration_s", "DOUBLE"),
    ("airborne_s", "DOUBLE"),
    ("status", "VARCHAR NOT NULL"),
    ("error", "VARCHAR"),
    ("verdict_label", "INTEGER"),
    ("faulty_propellers", "INTEGER[]"),
    ("p_faulty", "DOUBLE[]"),
    ("hypotheses", "VARCHAR"),  # JSON [{"faulty_propellers": [...], "probability": p}] or NULL
    ("rotor_effectiveness", "DOUBLE[]"),
    ("rotor_effectiveness_std", "DOUBLE[]"),
    ("windows", "INTEGER"),
    ("warnings", "VARCHAR[]"),
    ("propeller_names", "VARCHAR[]"),
    ("model_id", "VARCHAR"),
    ("model_version", "VARCHAR"),
    ("propwatch_version", "VARCHAR"),
    ("diagnosis", "VARCHAR"),  # the whole `propwatch diagnose --json` object
    ("ingested_at", "TIMESTAMP"),
    ("process_s", "DOUBLE"),  # worker wall-clock seconds spent on this log
    ("process_cpu_s", "DOUBLE"),  # worker CPU seconds (user + system) spent on this log
) + (
    # Vehicle memory (fleet.memory_adapter): each flight judged against its vehicle's healthy flights before it.
    ("confidence", "VARCHAR"),  # the verdict's: confident | ambiguous | suspect | uncertain (NULL: no verdict)
    ("baseline_flights", "INTEGER"),  # healthy flights of this vehicle it was compared with (0: none yet)
    ("compared_with_first", "VARCHAR"),  # their first and last dates (YYYY-MM-DD), NULL where unknown
    ("compared_with_last", "VARCHAR"),
    ("compared_with_logs", "VARCHAR[]"),  # their log hashes
    ("time_known", "BOOLEAN"),  # the log carries its own clock (false: judged against the baseline at ingest)
    ("memory_summary", "VARCHAR"),  # JSON FlightSummary of the flight, with its through-time "marks" (at most 64)
    ("memory", "VARCHAR"),  # JSON: the judgement (monitor.memory.judge) or why there is none
)
# Columns a version-1 store lacks (added by migration).
V2_COLUMNS = COLUMNS[-8:]
COLUMN_NAMES = tuple(c for c, _ in COLUMNS)


def _duckdb():
    return need("duckdb")


def open_db(path: str | Path, read_only: bool = False):
    """Connect to (and, writable, create) a fleet database; refuse a newer or foreign one."""
    duckdb = _duckdb()
    path = Path(path)
    if read_only and not path.is_file():
        raise FleetError(f"{path}: no such fleet database")
    try:
        con = duckdb.connect(str(path), read_only=read_only)
    except duckdb.Error as exc:
        raise FleetError(f"{path}: cannot open as a DuckDB fleet database: {exc}") from exc
    try:
        tables = {r[0] for r in con.execute("SELECT table_name FROM information_schema.tables").fetchall()}
        if "fleet_meta" not in tables:
            if tables:
                raise FleetError(f"{path}: not a propwatch fleet database (tables {sorted(tables)}, no fleet_meta)")
            if read_only:
                raise FleetError(f"{path}: empty database, not a propwatch fleet database")
            _create(con)
        version = check_version(con, path)
    except BaseException:
        con.close()
        raise
    assert version == SCHEMA_VERSION
    return con


def _create(con) -> None:
    cols = ",\n  ".join(f"{n} {t}" for n, t in COLUMNS)
    con.execute("BEGIN TRANSACTION")
    con.execute("CREATE TABLE fleet_meta (key VARCHAR PRIMARY KEY, value VARCHAR NOT NULL)")
    con.execute("INSERT INTO fleet_meta VALUES ('schema_version', ?)", [str(SCHEMA_VERSION)])
    con.execute(f"CREATE TABLE flights (\n  {cols}\n)")
    con.execute("COMMIT")


def check_version(con, path) -> int:
    row = con.execute("SELECT value FROM fleet_meta WHERE key = 'schema_version'").fetchone()
    if row is None:
        raise FleetError(f"{path}: fleet_meta has no schema_version")
    try:
        version = int(row[0])
    except ValueError:
        raise FleetError(f"{path}: schema_version {row[0]!r} is not a number") from None
    if version > SCHEMA_VERSION:
        raise FleetError(
            f"{path}: fleet database schema version {version} is newer than this propwatch's {SCHEMA_VERSION}; "
            "use the propwatch that wrote it (or a newer one)"
        )
    if version == 1 and SCHEMA_VERSION == 2:
        if con.execute("SELECT current_setting('access_mode')").fetchone()[0] == "read_only":
            raise FleetError(f"{path}: fleet database schema version 1: open it once writable (fleet ingest) to migrate it")
        con.execute("BEGIN TRANSACTION")
        for name, typ in V2_COLUMNS:
            con.execute(f"ALTER TABLE flights ADD COLUMN {name} {typ}")
        con.execute("UPDATE fleet_meta SET value = '2' WHERE key = 'schema_version'")
        con.execute("COMMIT")
        return SCHEMA_VERSION
    if version < SCHEMA_VERSION:
        raise FleetError(f"{path}: fleet database schema version {version} is older than {SCHEMA_VERSION} and cannot be read")
    return version


def model_versions(con) -> dict[str, str | None]:
    """log_hash -> the model_version that made its row (None: no model ran, e.g. an unreadable log)."""
    return dict(con.execute("SELECT log_hash, model_version FROM flights").fetchall())


def known_files(con) -> dict[str, tuple[int, int, str]]:
    """path -> (size_bytes, mtime_ns, log_hash) of the rows' files as they were at ingest."""
    rows = con.execute("SELECT path, size_bytes, mtime_ns, log_hash FROM flights WHERE mtime_ns IS NOT NULL").fetchall()
    return {p: (size, mtime, h) for p, size, mtime, h in rows}


def update_mtimes(con, mtime_hash: list[tuple[int, str]]) -> None:
    """Record new modification times of files whose bytes are unchanged (one transaction)."""
    if mtime_hash:
        con.execute("BEGIN TRANSACTION")
        con.executemany("UPDATE flights SET mtime_ns = ? WHERE log_hash = ?", [list(x) for x in mtime_hash])
        con.execute("COMMIT")


def forget_errors(con, hashes: set[str]) -> int:
    """Delete error rows of these hashes (``--retry-errors``); returns how many."""
    rows = [r[0] for r in con.execute("SELECT log_hash FROM flights WHERE status = 'error'").fetchall() if r[0] in hashes]
    if rows:
        con.execute("BEGIN TRANSACTION")
        con.executemany("DELETE FROM flights WHERE log_hash = ?", [[h] for h in rows])
        con.execute("COMMIT")
    return len(rows)


def insert_rows(con, rows: list[dict], replace: bool = False) -> None:
    """Insert ``rows`` (dicts with every column) in one transaction: all of them or none. ``replace``: the
    rows of the same log hashes are deleted in that transaction first (a re-diagnosis: old row or new, never
    neither)."""
    if not rows:
        return
    for r in rows:
        missing = [c for c in COLUMN_NAMES if c not in r]
        if missing:
            raise FleetError(f"row for {r.get('path')}: missing column(s) {missing}")
    placeholders = ", ".join("?" for _ in COLUMN_NAMES)
    con.execute("BEGIN TRANSACTION")
    try:
        if replace:
            con.executemany("DELETE FROM flights WHERE log_hash = ?", [[r["log_hash"]] for r in rows])
        con.executemany(
            f"INSERT INTO flights ({', '.join(COLUMN_NAMES)}) VALUES ({placeholders})",
            [[r[c] for c in COLUMN_NAMES] for r in rows],
        )
        con.execute("COMMIT")
    except BaseException:
        con.execute("ROLLBACK")
        raise


def export_parquet(con, out: str | Path) -> Path:
    """Write the flights table to a Parquet file (temp file, then rename)."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    quoted = str(tmp).replace("'", "''")
    con.execute(f"COPY (SELECT * FROM flights ORDER BY vehicle_id, start_time_utc, path) TO '{quoted}' (FORMAT PARQUET)")
    tmp.replace(out)
    return out
