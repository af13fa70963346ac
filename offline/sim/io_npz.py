"""Compact flight files: a ``FlightLog`` and its JSON sidecar in one compressed .npz.

The sidecar (ground truth, config, seed, git revision) is stored inside the
archive as UTF-8 JSON under ``SIDECAR_KEY``. Files are written to a
temporary name and renamed, so a crash never leaves half a file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from monitor.errors import LogFormatError
from offline.manifest import _jsonable
from offline.sim.log import FlightLog

SIDECAR_KEY = "__sidecar_json__"
FORMAT_KEY = "__format__"
FORMAT = "propwatch-sim-npz-1"


def write_npz(path: str | Path, log: FlightLog, sidecar: dict | None = None) -> Path:
    path = Path(path)
    arrays = {name: getattr(log, name) for name in log.array_fields()}
    arrays["log_rate_hz"] = np.array(log.log_rate_hz)
    arrays[SIDECAR_KEY] = np.array(json.dumps(sidecar or {}, default=_jsonable, sort_keys=True))
    arrays[FORMAT_KEY] = np.array(FORMAT)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def read_npz(path: str | Path) -> tuple[FlightLog, dict]:
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            if FORMAT_KEY not in z.files or str(z[FORMAT_KEY]) != FORMAT:
                raise LogFormatError(f"{path}: not a propwatch simulator file (no {FORMAT_KEY} = {FORMAT})")
            names = [f for f in FlightLog.__dataclass_fields__ if f != "log_rate_hz"]
            missing = [n for n in names if n not in z.files]
            if missing:
                raise LogFormatError(f"{path}: missing arrays {missing}")
            log = FlightLog(log_rate_hz=float(z["log_rate_hz"]), **{n: z[n] for n in names})
            sidecar = json.loads(str(z[SIDECAR_KEY]))
    except (OSError, ValueError) as exc:
        raise LogFormatError(f"{path}: cannot read simulator file: {exc}") from exc
    return log, sidecar
