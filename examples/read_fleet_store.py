"""Put a folder of flight logs into a fleet store (DuckDB) and read it back: one row per flight.

    python examples/read_fleet_store.py LOG_DIR STORE.duckdb

What ``propwatch fleet ingest`` does (here in this process, without Ray): each log is diagnosed on the same path
as ``propwatch diagnose``, with the vehicle and date read from the log. Needs the ``fleet`` extra.
"""

from __future__ import annotations

import sys
from pathlib import Path

import duckdb

from fleet.ingest import ingest

QUERY = """
SELECT vehicle_id, start_time_utc, path, status, confidence, faulty_propellers
FROM flights ORDER BY vehicle_id, start_time_utc
"""


def run(log_dir: str | Path, store: str | Path) -> list[dict]:
    """Ingest the new logs under ``log_dir`` into ``store``, then every flight stored there, by vehicle and date."""
    summary = ingest([str(log_dir)], store, ray_address="off", progress=False)
    print(f"{store}: {summary.new} new logs, {summary.error} unreadable")
    with duckdb.connect(str(store), read_only=True) as con:
        cursor = con.execute(QUERY)
        names = [c[0] for c in cursor.description]
        rows = [dict(zip(names, r)) for r in cursor.fetchall()]
    for r in rows:
        verdict = f"propellers {r['faulty_propellers']} ({r['confidence']})" if r["faulty_propellers"] else r["status"]
        print(f"  {r['vehicle_id']} {r['start_time_utc']:%Y-%m-%d} {Path(r['path']).name}: {verdict}")
    return rows


if __name__ == "__main__":
    run(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else "fleet.duckdb")
