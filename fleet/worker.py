"""One log -> one database row: what a Ray worker (or the serial loop) runs.

Reads the log with ``monitor.logs``, picks the classifier whose ESC command unit
matches the log's (so a mixed fleet of PX4 quads and Crazyflies gets each its
model), runs ``monitor.diagnose.engine.diagnose_table``, and adds who flew it
and when (``monitor.logs.identity``). Never raises for a bad log: the row says why.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor import __version__ as PROPWATCH_VERSION
from monitor.diagnose.memory_adapter import boot_clock
from monitor.errors import PropwatchError
from monitor.logs.guards import DEFAULT_MAX_SECONDS
from monitor.logs.identity import identify
from monitor.memory.summary import accumulate
from monitor.memory.through_time import marks_to_json
from monitor.vehicle import REPO_ROOT

SHIPPED_MODELS = (REPO_ROOT / "models" / "classifier.onnx", REPO_ROOT / "models" / "crazyflie-classifier.onnx")


@dataclass(frozen=True)
class IngestSettings:
    """What every worker needs to turn a log into a row (picklable, frozen)."""

    models: tuple[str, ...] = ()  # empty: the shipped models, chosen per log by motor command unit
    vehicle_yaml: str | None = None  # ESC curve for every log (as ``diagnose --vehicle``)
    csv_format: str | None = None  # mapping for .csv/.csv.gz logs (monitor/formats.yaml)
    hop: int = 20
    vehicle_from_dir: int | None = None  # folder level naming the vehicle when the log carries no id
    max_seconds: float = DEFAULT_MAX_SECONDS  # longest log accepted (as ``diagnose --max-seconds``)

    def model_paths(self) -> tuple[Path, ...]:
        if self.models:
            return tuple(Path(m) for m in self.models)
        if self.vehicle_yaml:
            from monitor.diagnose.engine import default_model

            return (default_model(self.vehicle_yaml),)
        return tuple(p for p in SHIPPED_MODELS if p.is_file())


_MODELS: dict[tuple[str, str | None], tuple] = {}  # per worker process: (path, vehicle) -> (clf, esc, id, version)


def model_version(path: Path) -> str:
    """What a row's ``model_version`` holds: 12 hex digits of the SHA-256 of everything shipped that decides its
    verdict: the model file, its set rule beside it (``<model>.sets.json``, when present) and the decision
    calibration when it belongs to this model (``monitor.decision`` uses no other). A recalibrated set rule or
    decision threshold beside the same model makes old rows another version (``fleet ingest``'s ``other_model``)."""
    from monitor.decision.hypotheses import rule_path
    from monitor.decision.thresholds import DEFAULT_CALIBRATION, load_calibration
    from monitor.errors import ConfigError

    h = hashlib.sha256(Path(path).read_bytes())
    model_sha256 = h.hexdigest()  # the model's own digest; h goes on to take its rule and calibration
    sets = rule_path(path)
    if sets.is_file():
        h.update(b"\0sets\0" + sets.read_bytes())
    try:
        cal = load_calibration()
    except ConfigError:
        cal = None  # unreadable: the decision cannot use it either
    if cal is not None and cal.model_sha256 == model_sha256:
        h.update(b"\0decision-calibration\0" + DEFAULT_CALIBRATION.read_bytes())
    return h.hexdigest()[:12]


def _model(path: Path, vehicle_yaml: str | None):
    key = (str(path), vehicle_yaml)
    if key not in _MODELS:
        from monitor.model import Classifier, choose_esc
        from monitor.vehicle import load_vehicle

        clf = Classifier(path)
        esc = choose_esc(clf, vehicle_yaml or "")
        version = model_version(path)
        name = (clf.info.metadata.get("vehicle") or {}).get("name", "")
        vehicle = load_vehicle(vehicle_yaml or vehicle_for_model(path))  # geometry for diagnose's physics evidence
        _MODELS[key] = (clf, esc, f"{path.name}" + (f" ({name})" if name else ""), version, vehicle)
    return _MODELS[key]


def vehicle_for_model(path: Path) -> Path:
    """The vehicle YAML shipped beside a model (``NAME-classifier.onnx`` -> ``models/NAME.yaml``), else the paper quad's."""
    from monitor.vehicle import DEFAULT_VEHICLE

    stem = path.name.removesuffix(".onnx").removesuffix("classifier").rstrip("-")
    own = REPO_ROOT / "models" / f"{stem}.yaml"
    return own if stem and own.is_file() else DEFAULT_VEHICLE


def choose_model(settings: IngestSettings, cmd_unit: str):
    """The first model whose ESC curve takes this command unit, else the first (its envelope check refuses)."""
    loaded = [_model(p, settings.vehicle_yaml) for p in settings.model_paths()]
    if not loaded:
        raise PropwatchError("no classifier model found (give --model)")
    return next((m for m in loaded if m[1].cmd_unit == cmd_unit), loaded[0])


def declared(settings: IngestSettings, clf) -> bool:
    """Whether the log's airframe is declared to be the model's (``diagnose``'s rule: ``--vehicle`` or ``--model``),
    or its motor command unit names the vehicle class a shipped model was trained for (a Crazyflie's); the paper
    quad's PWM names no airframe, and its classifier is then silent."""
    from monitor.diagnose.engine import DEFAULT_MODEL

    return bool(settings.vehicle_yaml or settings.models) or Path(clf.path).resolve() != DEFAULT_MODEL.resolve()


def utc_naive(unix_us: float) -> _dt.datetime:
    """UTC as a naive datetime (the database's TIMESTAMP columns are UTC)."""
    return _dt.datetime.fromtimestamp(unix_us / 1e6, _dt.timezone.utc).replace(tzinfo=None)


def log_format(path: Path, csv_format: str | None) -> str:
    from monitor.logs import detect_format

    name = path.name.lower()
    if name.endswith((".csv", ".csv.gz")):
        if not csv_format:
            raise PropwatchError(f"{path}: CSV logs need --format NAME (a column mapping in monitor/formats.yaml)")
        return csv_format
    return detect_format(path)


def vehicle_from_dir(path: Path, level: int | None) -> str | None:
    if not level:
        return None
    parents = path.resolve().parents
    return parents[level - 1].name if level - 1 < len(parents) else None


def empty_row(path: Path, log_hash: str, size_bytes: int) -> dict:
    from fleet.schema import COLUMN_NAMES

    row = dict.fromkeys(COLUMN_NAMES)
    row.update(log_hash=log_hash, path=str(path), size_bytes=size_bytes, propwatch_version=PROPWATCH_VERSION, warnings=[])
    return row


class LogWorker:
    """One long-lived worker (a Ray actor per CPU): loads the classifiers once, then diagnoses batches of logs.

    Rows come back only when the whole batch is done, so a worker killed mid-batch returns nothing and
    the retried batch gives each of its logs exactly once.
    """

    def __init__(self, settings: IngestSettings):
        self.settings = settings
        try:  # load the models now, not inside the first log's timing; a bad model is reported per log
            for path in settings.model_paths():
                _model(path, settings.vehicle_yaml)
        except Exception:  # noqa: BLE001 - process_log turns the same failure into each log's error row
            pass

    def process_batch(self, jobs: list[tuple[str, str, int]]) -> list[dict]:
        return [process_log(path, log_hash, size, self.settings) for path, log_hash, size in jobs]


def process_log(path: str, log_hash: str, size_bytes: int, settings: IngestSettings) -> dict:
    """The row for one log; a log that cannot be read gives ``status='error'`` and the reason."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    p = Path(path)
    row = empty_row(p, log_hash, size_bytes)
    row["worker_pid"] = os.getpid()  # not stored: lets the driver (and tests) see where it ran
    try:
        _diagnose_into(row, p, settings)
    except PropwatchError as exc:
        row.update(status="error", error=str(exc))
    except Exception as exc:  # noqa: BLE001 - a third-party parser choking on a foreign file is a bad log, not a crash
        row.update(status="error", error=f"{p}: cannot be read ({type(exc).__name__}: {exc})")
    if row["vehicle_id"] is None and (vid := vehicle_from_dir(p, settings.vehicle_from_dir)):
        row.update(vehicle_id=vid, vehicle_id_source=f"dir:{settings.vehicle_from_dir}")
    row["time_known"] = row["start_time_utc"] is not None
    if row["start_time_utc"] is None:
        try:
            row.update(start_time_utc=utc_naive(p.stat().st_mtime * 1e6), start_time_source="file:mtime")
        except OSError:
            pass
    row["ingested_at"] = utc_naive(time.time() * 1e6)
    row["process_s"] = time.perf_counter() - t0
    row["process_cpu_s"] = time.process_time() - cpu0
    return row


def _diagnose_into(row: dict, path: Path, settings: IngestSettings) -> None:
    from monitor.diagnose.engine import diagnose_raw, read_guarded

    if row["size_bytes"] == 0:
        raise PropwatchError(f"{path}: empty file (0 bytes)")
    fmt = log_format(path, settings.csv_format)
    row["format"] = fmt
    raw = read_guarded(path, fmt, settings.max_seconds)  # the guards `propwatch diagnose` applies
    clf, esc, model_id, model_version, vehicle = choose_model(settings, raw.cmd_unit)
    row.update(model_id=model_id, model_version=model_version)
    table, d = diagnose_raw(raw, clf, esc, settings.hop, vehicle, airframe_declared=declared(settings, clf))
    try:
        ident = identify(path, fmt)
    except Exception as exc:  # noqa: BLE001 - the id is extra: a log readable for diagnosis is still diagnosed
        row["warnings"].append(f"vehicle id / clock not read: {type(exc).__name__}: {exc}")
    else:
        row.update(vehicle_id=ident.vehicle_id, vehicle_id_source=ident.vehicle_id_source)
        if ident.utc_minus_boot_us is not None and len(table):
            start_us = int(table.timestamp_us[0]) + ident.utc_minus_boot_us
            row["start_time_utc"] = utc_naive(start_us)
            row["start_time_source"] = ident.time_source
    out = d.to_json()
    row.update(
        duration_s=len(table) / table.rate_hz,
        airborne_s=float(np.sum(table.airborne)) / table.rate_hz,
        status="ok" if d.verdict is not None else "no_verdict",
        error=d.reason,
        windows=d.windows,
        propeller_names=list(table.motor_names),
        diagnosis=json.dumps(out, allow_nan=False),
    )
    row["warnings"] = row["warnings"] + list(d.warnings)
    acc = accumulate(table)
    summary = acc.summary
    # the flight's summary, and the marks it is judged through time from (monitor.memory.through_time)
    trace = summary.to_dict() | {"marks": marks_to_json(acc.marks, summary, boot_clock(table))}
    row["memory_summary"] = json.dumps(trace, allow_nan=False) if summary.n > 0 else None
    if d.verdict is not None:  # PX4 rotor order (the JSON may be in the vehicle's own numbering)
        row.update(
            confidence=str(d.verdict.get("confidence", "confident")),
            verdict_label=int(d.verdict["label"]),
            faulty_propellers=[int(i) for i in d.verdict["faulty_propellers"]],
            # the network's P(faulty) per rotor; NULL where it was silent (a verdict of physics alone)
            p_faulty=[float(x) for x in d.verdict["fault_probability"]] if d.verdict.get("fault_probability") else None,
        )
    # Physics evidence (rotor effectiveness, hypotheses) in PX4 rotor order, as p_faulty: from the Diagnosis
    # itself (the JSON may be renumbered to the vehicle's own numbers); NULL when diagnose gives none.
    # The hypotheses are the verdict's own set (the model's conformal set when it has a rule, else the balance's).
    ev = getattr(d, "physics", None)
    hyp = getattr(d, "hypotheses", None)
    if hyp is None:
        hyp = getattr(ev, "hypotheses", None) if ev is not None else out.get("hypotheses")
    row["hypotheses"] = json.dumps(hyp) if hyp is not None else None
    for key in ("rotor_effectiveness", "rotor_effectiveness_std"):
        v = getattr(ev, key, None) if ev is not None else out.get(key)
        row[key] = [float(x) for x in v] if v is not None else None
