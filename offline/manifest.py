"""Provenance for every generated artefact: config, seed, git revision, time."""

from __future__ import annotations

import datetime as _dt
import json
import math
import platform
import subprocess
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parent.parent


def git_revision() -> str:
    """HEAD commit, with '+dirty' when the tree has uncommitted changes; 'unknown' outside git."""
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO_ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
        return rev + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def make_manifest(kind: str, config: dict[str, Any], seed: int | None, **extra: Any) -> dict[str, Any]:
    return {
        "kind": kind,
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "git_revision": git_revision(),
        "python": platform.python_version(),
        "seed": seed,
        "config": config,
        **extra,
    }


def write_manifest(path: str | Path, manifest: dict[str, Any]) -> Path:
    """Write JSON atomically (temp file then rename) so a crash never leaves half a manifest."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    # Strict JSON: NaN/inf are not JSON (other parsers reject them); an undefined figure is null.
    text = json.dumps(_finite(manifest), indent=2, sort_keys=True, default=_jsonable, allow_nan=False)
    tmp.write_text(text + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def _finite(o: Any) -> Any:
    """A copy with every non-finite float (NaN, inf) replaced by None."""
    if o is not None and not isinstance(o, (dict, list, tuple, str, int, float)):
        o = _jsonable(o)  # numpy arrays and scalars, paths, dataclasses
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite(v) for v in o]
    return o


def _jsonable(o: Any) -> Any:
    try:
        import numpy as np

        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, np.generic):
            return o.item()
    except ImportError:
        pass
    if isinstance(o, Path):
        return str(o)
    if hasattr(o, "__dataclass_fields__"):
        import dataclasses

        return dataclasses.asdict(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
