"""The calibrated vehicle as a cited YAML: the nominal file with the fitted terms written in.

Every value keeps its nominal citation except the fields a chosen term
changed, which cite the calibration run (logs, term, held-out fit quality).
A top-level ``provenance:`` mapping records the logs, the terms, the fit and
the git revision; ``monitor.vehicle.load_vehicle_with_sources`` pops it, so
``simulate``, ``dataset`` and ``train`` read the file through their
``--vehicle`` option like any other vehicle.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import yaml

from monitor.config import to_mapping
from monitor.errors import ConfigError
from monitor.vehicle import load_vehicle_with_sources
from offline.calibrate.calibrate import CalibrationResult
from offline.calibrate.terms import TERMS
from offline.manifest import make_manifest


def calibrated_mapping(result: CalibrationResult, nominal_sources: dict[str, str], nominal_path: str) -> dict:
    sources = dict(nominal_sources)
    logs = ", ".join(Path(s).name for s in result.sources)
    for f in result.findings:
        src = (
            f"calibration: propwatch calibrate on {logs}, term {f['effect']} "
            f"(held-out residual RMS {f['residual_rms_before']:.4g} -> {f['residual_rms_after']:.4g}, "
            f"BIC gain {f['score']:.1f})"
        )
        for name in TERMS[f["effect"]].fields:
            for key in [k for k in list(sources) if k == name or k.startswith(name + ".")] or [name]:
                sources[key] = src
    for f in dataclasses.fields(result.calibrated):
        sources.setdefault(f.name, "neutral default of monitor.vehicle.VehicleConfig (not calibrated)")
    data = to_mapping(result.calibrated, sources)
    data["provenance"] = make_manifest(
        "calibrated-vehicle",
        config={"nominal_vehicle": nominal_path, "candidates": sorted(result.candidates)},
        seed=None,
        logs=list(result.sources),
        terms=[{"effect": f["effect"], "params": f["params"], "std": f["std"], "score": f["score"]} for f in result.findings],
        cause=result.cause,
        fit={
            "heldout_residual_rms_before": result.gain["heldout_residual_rms_before"],
            "heldout_residual_rms_after": result.gain["heldout_residual_rms_after"],
            "heldout_residual_reduction_pct": result.gain["heldout_residual_reduction_pct"],
        },
        not_identifiable={n: c["reason"] for n, c in result.candidates.items() if not c["identifiable"]},
    )
    return data


def write_calibrated(path: str | Path, result: CalibrationResult, nominal_sources: dict[str, str], nominal_path: str) -> Path:
    """Write the YAML, then load it back with the project's loader so a bad file never stays on disk."""
    path = Path(path)
    text = "# Calibrated vehicle written by `propwatch calibrate`; see provenance at the end.\n" + yaml.safe_dump(
        calibrated_mapping(result, nominal_sources, nominal_path), sort_keys=False, default_flow_style=None, width=140
    )
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    try:
        load_vehicle_with_sources(tmp)
    except ConfigError:
        tmp.unlink(missing_ok=True)
        raise
    tmp.replace(path)
    return path
