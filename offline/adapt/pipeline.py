"""``propwatch adapt``: calibrate -> simulate -> train -> export, card, manifest and healthy baseline.

Stages (one progress bar each):

1. **read** every healthy log; refuse, by name, a log of another vehicle type, a log with no
   airborne time, and a log whose per-motor share lies beyond 3 spreads of the others
   (``offline.adapt.checks``);
2. **calibrate** the vehicle on them with the one calibrator, ``offline.calibrate``: its dynamic view
   (equation error on body rates, held-out 5-s blocks; it tells a CG offset from a motor spread) when every
   log carries attitude and body rates, else its steady-state view on the per-motor mean commands (logs with
   an even index fit, odd ones are held out), which says which terms it cannot separate;
3. **simulate** a labelled training set from the calibrated vehicle with a spread around it
   (``TRAINING_SPREAD``, recorded in the manifest);
4. **train** the same small CNN on it, and on the same recipe around the *nominal* vehicle, so the
   card shows what adaptation buys;
5. **export** both to ONNX; **score** both on the held-out healthy logs and on any ``--labelled``
   log; write the **baseline** (vehicle memory, ``monitor.memory``), the calibrated vehicle, the manifest and the
   card (``offline.adapt.card``, from the manifest).

``propwatch diagnose LOG --vehicle DIR`` then uses DIR's vehicle, model and baseline.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.config import to_mapping
from monitor.errors import ConfigError
from monitor.labels import LABEL_TABLE, label_from_mask
from monitor.logs import read_raw
from monitor.logs.raw import to_flight_table
from monitor.memory.cli import describe
from monitor.vehicle import VehicleConfig, load_vehicle_with_sources
from offline.adapt.checks import NotHealthyError, check_airborne, check_consistent, vehicle_type_problem
from offline.adapt.share_rule import SPREAD_FLOOR
from offline.calibrate.terms import TERMS
from offline.manifest import make_manifest, write_manifest

MODEL_FILE = "classifier.onnx"
BASELINE_FILE = "baseline.json"  # read by propwatch diagnose --vehicle DIR
NOMINAL_MODEL_FILE = "nominal-classifier.onnx"
VEHICLE_FILE = "vehicle.yaml"
MANIFEST_FILE = "adapt.manifest.json"
CARD_FILE = "card.md"
MISSIONS = ("random", "crazypad")
RPM_REL = ("rpm_rel_1", "rpm_rel_2", "rpm_rel_3", "rpm_rel_4")
OPTIONAL_FEATURES = ("roll_rate_rad_s", "pitch_rate_rad_s", "yaw_rate_rad_s")
TRAINING_SPREAD = (
    "spread around the calibrated vehicle: for the random mission offline.dataset's options (per vehicle variant, "
    "motor efficiency +-3 measured airframe spreads capped at 10 %, CG +-5 mm); for the crazypad mission the CrazyPAD "
    "recipe's healthy jitter (offline.crazypad.simdata); the assumption register (offline/sim/assumptions.py) is not drawn"
)


@dataclass(frozen=True)
class AdaptConfig:
    mission: str = "random"  # simulated routes: "random" (offline.dataset) or "crazypad" (CrazyPAD's script)
    flights_per_label: int = 4
    duration_s: float = 40.0  # "random" mission only; "crazypad" flies its script
    epochs: int = 4
    window: int = 100
    channels: int = 32
    blocks: int = 3
    dense: int = 64
    vehicle_variants: int = 4
    seed: int = 0

    def __post_init__(self) -> None:
        if self.mission not in MISSIONS:
            raise ConfigError(f"mission: must be one of {MISSIONS}, got {self.mission!r}")
        if self.flights_per_label < 1 or self.epochs < 1 or self.window < 8:
            raise ConfigError("flights_per_label and epochs must be >= 1, window >= 8")


@dataclass
class HealthyLog:
    path: str
    table: object  # FlightTable at 20 Hz


def _progress(total: int, desc: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=f"adapt: {desc}", unit="step", disable=not enabled, leave=True)


def read_healthy(paths: list[str], fmt: str | None, vehicle: VehicleConfig, progress: bool = False) -> list[HealthyLog]:
    """Read and check every log given as healthy; raise NotHealthyError naming the first bad one."""
    out = []
    with _progress(len(paths), "read", progress) as bar:
        for p in paths:
            why = vehicle_type_problem(p, fmt)
            if why:
                raise NotHealthyError(f"{p}: refused: {why}")
            raw = read_raw(p, fmt)
            tab = to_flight_table(raw, esc=vehicle.esc, rate_hz=20.0)
            check_airborne(tab, p)
            out.append(HealthyLog(p, tab))
            bar.update()
    check_consistent([h.table for h in out], [h.path for h in out])
    return out


def healthy_baseline(logs: list[HealthyLog], fmt: str | None, cg_damage_separable: bool | None):
    """The vehicle's normal in vehicle memory's format (``monitor.memory``), from its healthy flights: what
    ``propwatch diagnose LOG --vehicle DIR`` judges a flight against. Fewer than ``MIN_FLIGHTS`` logs give a baseline
    that is not ready yet (diagnose says so and does not compare)."""
    from monitor.diagnose.memory_adapter import log_vehicle_id
    from monitor.memory.baseline import MIN_FLIGHTS, VehicleBaseline
    from monitor.memory.learn import learn_baseline
    from monitor.memory.summary import summarize

    ids = {i for i in (log_vehicle_id(h.path, fmt) for h in logs) if i is not None}
    if len(ids) > 1:
        raise NotHealthyError(f"the healthy logs are of {len(ids)} vehicles ({', '.join(sorted(ids))}): adapt one vehicle")
    vehicle_id = ids.pop() if ids else None
    id_source = "the logs" if vehicle_id else None
    tables, files = [h.table for h in logs], [h.path for h in logs]
    if len(logs) >= MIN_FLIGHTS:
        # check_healthy=False: read_healthy has refused, by name, a log beyond the others' spread (offline.adapt.checks);
        # vehicle memory's own check refuses CrazyPAD's E9_log03 among E9's four healthy logs (statistic 12.8 >= 12).
        return learn_baseline(tables, files, vehicle_id, id_source, cg_damage_separable=cg_damage_separable, check_healthy=False)
    first = summarize(tables[0])
    b = VehicleBaseline(vehicle_id, id_source, tuple(tables[0].motor_names), first.basis)
    for f, t in zip(files, tables):
        b.add(f, None, summarize(t), "declared")
    b.cg_damage_separable = cg_damage_separable
    return b


def share_spread(logs: list[HealthyLog]) -> float:
    """Mean flight-to-flight spread of the rotors' shares (floored at ``SPREAD_FLOOR``): the training set's spread."""
    from monitor.memory.normal import normal_of
    from monitor.memory.summary import summarize

    own = normal_of([summarize(h.table) for h in logs]).own_cov
    return max(float(np.mean(np.sqrt(np.clip(np.diag(own), 0.0, None)))), SPREAD_FLOOR)


def parse_labelled(spec: str) -> tuple[str, int | None]:
    """``LOG=3``, ``LOG=1+2`` (faulty rotors, PX4 order) or ``LOG=healthy`` -> (path, label); plain LOG: no truth."""
    m = re.fullmatch(r"(.+)=(healthy|none|[1-4](?:\+[1-4])*)", spec)
    if not m:
        return spec, None
    rotors = () if m.group(2) in ("healthy", "none") else tuple(sorted({int(r) for r in m.group(2).split("+")}))
    return m.group(1), label_from_mask([i + 1 in rotors for i in range(4)])


def features_for(logs: list[HealthyLog]) -> tuple[str, ...]:
    """Motor shares always; body rates too when every healthy log carries them."""
    extra = []
    for name in OPTIONAL_FEATURES:
        if all(np.isfinite(getattr(h.table, name)[h.table.airborne]).mean() > 0.9 for h in logs):
            extra.append(name)
    return RPM_REL + tuple(extra)


@dataclass
class AirframeCalibration:
    """The calibration stage's result, from the one calibrator (``offline.calibrate``) in either of its views."""

    view: str  # "dynamic" (offline.calibrate.calibrate: equation error on body rates) or "steady-state"
    calibrated: VehicleConfig
    cause: str | None
    fit_files: list[str]
    record: dict  # JSON for the manifest and the card
    result: object = None  # the CalibrationResult (dynamic view), for the cited vehicle writer


def has_body_rates(logs: list[HealthyLog]) -> bool:
    """The dynamic view needs attitude and body rates through the airborne time of every log."""
    names = ("roll_rad", "pitch_rad", "yaw_rad", *OPTIONAL_FEATURES)
    return all(np.isfinite(getattr(h.table, n)[h.table.airborne]).mean() > 0.9 for h in logs for n in names)


def calibrate_airframe(nominal: VehicleConfig, logs: list[HealthyLog]) -> tuple[AirframeCalibration, list[int]]:
    """Calibrate with ``offline.calibrate``: its dynamic view where the logs carry body rates (it separates a CG
    offset from a motor spread), else its steady-state view, which says which terms it cannot separate. Returns
    the calibration and the indices of the healthy logs scored as held out (odd ones; one log: itself)."""
    held_i = list(range(1, len(logs), 2)) or [0]
    if has_body_rates(logs):
        from offline.calibrate.calibrate import calibrate_vehicle

        r = calibrate_vehicle([h.table for h in logs], nominal)
        rec = {
            "view": "dynamic",
            "why": TERMS[r.cause].why if r.cause else "no term beats the nominal model on the held-out blocks",
            "fit_files": [h.path for h in logs],
            "split": "every healthy log; alternating 5-s blocks fit and score (offline.calibrate.fit.BLOCK_S)",
            **r.to_json(),
        }
        return AirframeCalibration("dynamic", r.calibrated, r.cause, rec["fit_files"], rec, r), held_i
    from offline.calibrate.fit import calibrate_steady

    means = np.array([np.nanmean(h.table.motor_cmd[h.table.airborne], axis=0) for h in logs])
    fit_i = list(range(0, len(logs), 2))
    cal = calibrate_steady(
        "airframe", nominal, means[fit_i], means[held_i], [logs[i].path for i in fit_i], [logs[i].path for i in held_i]
    )
    rec = {"view_why": "the logs carry no body rates: only the per-motor mean commands can be fitted", **cal.to_dict()}
    return AirframeCalibration("steady-state", cal.calibrated, cal.cause, cal.fit_files, rec), held_i


def training_set(vehicle: VehicleConfig, cfg: AdaptConfig, spread: float, name: str, on_step=None):
    """The labelled simulated set around ``vehicle``; ``spread``: the airframe's share spread."""
    if cfg.mission == "crazypad":
        from offline.crazypad.simdata import Recipe
        from offline.crazypad.simdata import training_set as crazypad_set

        recipe = Recipe(flights_per_label=cfg.flights_per_label, healthy_jitter=max(0.01, float(spread)), seed=cfg.seed)
        ds = crazypad_set([vehicle], recipe, name)
        if on_step:
            on_step()
        return ds, {"recipe": "offline.crazypad.simdata", **dataclasses.asdict(recipe)}
    from offline.dataset.generate import DatasetSpec, generate

    spec = DatasetSpec(
        name=name,
        fault="varied",
        waypoints=("random",),
        flights_per_label=cfg.flights_per_label,
        duration_s=cfg.duration_s,
        propellers="quadratic",
        motor_efficiency_spread=min(0.1, 3.0 * float(spread)),
        cg_offset_max_m=0.005,
        vehicle_variants=cfg.vehicle_variants,
        seed=cfg.seed,
    )
    ds = generate(spec, vehicle, log=lambda s: on_step() if on_step else None)
    return ds, {"recipe": "offline.dataset.generate", **to_mapping(spec)}


def score(model_path: Path, items: list[tuple[str, object, int | None]], esc) -> list[dict]:
    from monitor.diagnose.engine import diagnose_table
    from monitor.model import Classifier

    clf = Classifier(model_path)
    rows = []
    for path, table, truth in items:
        d = diagnose_table(table, clf, hop=1, esc=esc)
        label = d.verdict["label"] if d.verdict else None
        rows.append(
            {
                "log": path,
                "truth_label": truth,
                "label": label,
                "faulty_propellers": list(LABEL_TABLE[label]) if label else None,
                "correct": None if truth is None or label is None else bool(label == truth),
                "reason": d.reason,
            }
        )
    return rows


def summary(rows: list[dict]) -> dict:
    scored = [r for r in rows if r["correct"] is not None]
    healthy = [r for r in scored if r["truth_label"] == 1]
    return {
        "logs": len(rows),
        "scored": len(scored),
        "exact": sum(r["correct"] for r in scored),
        "healthy_false_alarms": sum(1 for r in healthy if r["label"] != 1),
        "healthy": len(healthy),
    }


def write_vehicle(cal: AirframeCalibration, sources: dict, path: Path, nominal_path: str) -> Path:
    """The calibrated vehicle, cited; the dynamic view through ``offline.calibrate.writer`` (as ``propwatch calibrate``)."""
    if cal.result is not None:
        from offline.calibrate.writer import write_calibrated

        return write_calibrated(path, cal.result, sources, nominal_path)
    import yaml

    from monitor.vehicle import load_vehicle_with_sources as reload

    src = dict(sources)
    why = f"propwatch adapt: steady-state calibration on {', '.join(Path(f).name for f in cal.fit_files)}"
    for name in ("motor_efficiency", "cg_offset_frd_m", "mass_kg", "esc"):
        src[name] = why
    for f in dataclasses.fields(cal.calibrated):
        src.setdefault(f.name, "neutral default of monitor.vehicle.VehicleConfig (not calibrated)")
    data = to_mapping(cal.calibrated, src)
    data["provenance"] = make_manifest("adapt-calibrated-vehicle", cal.record, None)
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    reload(path)  # the project's loader must read back what was written
    return path


def adapt_vehicle(
    healthy: list[str],
    vehicle_path: str | Path,
    out: str | Path,
    fmt: str | None = None,
    labelled: list[str] = (),
    cfg: AdaptConfig = AdaptConfig(),
    progress: bool = False,
) -> dict:
    from offline.classifier.export import export_onnx
    from offline.classifier.train import TrainConfig, train

    if not healthy:
        raise ConfigError("adapt: give at least one --healthy log")
    out = Path(out)
    loaded = load_vehicle_with_sources(vehicle_path)
    nominal = loaded.config
    logs = read_healthy(list(healthy), fmt, nominal, progress)
    # Every input is read before anything is simulated or written: bad input fails fast, nothing half-written.
    items = [(logs[i].path, logs[i].table, 1) for i in range(1, len(logs), 2)]
    for spec in labelled:
        path, truth = parse_labelled(spec)
        items.append((path, to_flight_table(read_raw(path, fmt), esc=nominal.esc, rate_hz=20.0), truth))
    separable = evidence = None
    if cfg.mission == "crazypad":  # measured on the shared CrazyPAD flights: CG offset and damage look alike
        from offline.crazypad.evidence import CG_DAMAGE_EVIDENCE, CG_DAMAGE_SEPARABLE

        separable, evidence = CG_DAMAGE_SEPARABLE, CG_DAMAGE_EVIDENCE
    baseline = healthy_baseline(logs, fmt, separable)
    spread = share_spread(logs)
    with _progress(1, "calibrate", progress) as bar:
        cal, held_i = calibrate_airframe(nominal, logs)
        bar.update()
    features = features_for(logs)
    tcfg = TrainConfig(
        features=features,
        window=cfg.window,
        epochs=cfg.epochs,
        channels=cfg.channels,
        blocks=cfg.blocks,
        dense=cfg.dense,
        train_stride=4,
        test_fraction=0.2,
        seed=cfg.seed,
    )
    out.mkdir(parents=True, exist_ok=True)
    models, recipes, histories = {}, {}, {}
    for kind, veh, fname in (("adapted", cal.calibrated, MODEL_FILE), ("nominal", nominal, NOMINAL_MODEL_FILE)):
        steps = cfg.vehicle_variants * 16 if cfg.mission == "random" else 1
        with _progress(steps, f"simulate ({kind})", progress) as bar:
            ds, recipes[kind] = training_set(veh, cfg, spread, f"adapt-{kind}", on_step=bar.update)
        with _progress(cfg.epochs, f"train ({kind})", progress) as bar:
            m = train(ds, tcfg, log=lambda s, bar=bar: bar.update())
        histories[kind] = m.history
        with _progress(1, f"export ({kind})", progress) as bar:
            models[kind] = export_onnx(m, out / fname, extra_metadata={"adapt": {"trained_on": kind}})
            bar.update()
    with _progress(2, "score", progress) as bar:
        scores = {}
        for kind in ("nominal", "adapted"):
            rows = score(models[kind], items, nominal.esc)
            scores[kind] = {"summary": summary(rows), "logs": rows}
            bar.update()
    baseline.save(out / BASELINE_FILE)
    write_vehicle(cal, loaded.sources, out / VEHICLE_FILE, str(vehicle_path))
    manifest = make_manifest(
        "adapt",
        {**dataclasses.asdict(cfg), "features": list(features), "format": fmt, "vehicle": str(vehicle_path)},
        cfg.seed,
        healthy=[h.path for h in logs],
        labelled=list(labelled),
        held_out_healthy=[logs[i].path for i in held_i] if len(logs) > 1 else [],
        calibration=cal.record,
        baseline=describe(baseline) | {"cg_damage_separable": baseline.cg_damage_separable, "cg_damage_evidence": evidence},
        assumptions=TRAINING_SPREAD,
        training={k: {"recipe": recipes[k], "history": histories[k]} for k in recipes},
        scores=scores,
        files={"model": MODEL_FILE, "nominal_model": NOMINAL_MODEL_FILE, "vehicle": VEHICLE_FILE, "baseline": BASELINE_FILE},
    )
    write_manifest(out / MANIFEST_FILE, manifest)
    from offline.adapt.card import write_card

    card = write_card(out / MANIFEST_FILE, out / CARD_FILE)
    return {
        "out": str(out),
        "model": str(out / MODEL_FILE),
        "vehicle": str(out / VEHICLE_FILE),
        "baseline": str(out / BASELINE_FILE),
        "card": str(card),
        "manifest": str(out / MANIFEST_FILE),
        "calibration": {
            "view": cal.view,
            "cause": cal.cause,
            "unexplained_residual": cal.record.get("unexplained_residual"),
            # the damaged-propeller caveat (offline.calibrate.calibrate.inspect_rotor): the baseline written here
            # learnt these flights as healthy, so a damaged propeller in them is the vehicle's normal until inspected
            "inspect_rotor": cal.record.get("inspect_rotor"),
        },
        "features": list(features),
        "scores": {k: v["summary"] for k, v in scores.items()},
    }
