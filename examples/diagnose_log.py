"""Diagnose one flight log in Python: which propeller is damaged, and how sure.

    python examples/diagnose_log.py LOG [--format NAME]

The same path from a log to its verdict as ``propwatch diagnose``, ``propwatch fleet ingest`` and the offline
evaluations (``monitor.diagnose.engine.diagnose_file``): the shipped classifier, its vehicle's ESC curve and
geometry, and the reader's guards against damaged files.
"""

from __future__ import annotations

import sys

from monitor.diagnose.engine import default_model, diagnose_file
from monitor.diagnose.verdict import verdict_of
from monitor.model import Classifier, choose_esc
from monitor.vehicle import DEFAULT_VEHICLE, load_vehicle


def run(log: str, fmt: str | None = None, vehicle_yaml: str | None = None, hop: int = 20) -> dict:
    """The log's ``--json`` object (docs/diagnose-json.md) with its plain-words ``summary``."""
    clf = Classifier(default_model(vehicle_yaml))
    esc = choose_esc(clf, vehicle_yaml or "")  # the vehicle's ESC curve, else the model's own
    vehicle = load_vehicle(vehicle_yaml or DEFAULT_VEHICLE)  # geometry for the moment-balance evidence
    table, diagnosis = diagnose_file(log, clf, esc, fmt, hop, vehicle)
    result = diagnosis.to_json()
    result["summary"] = verdict_of(result).to_json()
    print(f"{log}: {len(table) / table.rate_hz:.0f} s read, {diagnosis.windows} windows classified")
    print(f"  {result['summary']['headline']}")
    return result


if __name__ == "__main__":
    args = sys.argv[1:]
    fmt = args[args.index("--format") + 1] if "--format" in args else None
    run(args[0], fmt)
