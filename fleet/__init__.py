"""Fleet scale: ingest many flight logs into a propeller-health database, and a static fleet web report.

    propwatch fleet ingest LOGS... --db fleet.duckdb [--ray auto|ADDRESS|off] [--json]
    propwatch fleet report --db fleet.duckdb --out site/

Optional extra ``fleet`` (ray, duckdb, pyarrow). The package calls
``monitor.diagnose``'s library API on each log; it never imports torch or
``offline``. One writer (the driver) owns the database; Ray workers only
return rows.
"""
