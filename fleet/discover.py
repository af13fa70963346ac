"""Find flight logs under folders and globs, and hash their content (the database key)."""

from __future__ import annotations

import glob
import hashlib
from pathlib import Path

from fleet.errors import FleetError

LOG_SUFFIXES = (".tlog", ".ulg", ".bin", ".csv", ".csv.gz")
HASH_CHUNK_BYTES = 1 << 20


def is_log(path: Path) -> bool:
    name = path.name.lower()
    return any(name.endswith(s) for s in LOG_SUFFIXES)


def find_logs(paths: list[str]) -> list[Path]:
    """Log files named by ``paths`` (files, folders walked recursively, or globs), sorted, each once.

    A file named explicitly is taken whatever its suffix (it may be a foreign
    file; ingest records why it cannot be read); inside folders only files with
    a log suffix are taken. A path that matches nothing is an error.
    """
    found: dict[str, Path] = {}
    for p in paths:
        matches = [Path(m) for m in sorted(glob.glob(p, recursive=True))] if glob.has_magic(p) else [Path(p)]
        if not matches or not all(m.exists() for m in matches):
            raise FleetError(f"{p}: no such file or folder")
        for m in matches:
            if m.is_dir():
                files = [f for f in m.rglob("*") if f.is_file() and is_log(f)]
            elif glob.has_magic(p) and not is_log(m):
                continue
            else:
                files = [m]
            for f in files:
                found.setdefault(str(f.resolve()), f.resolve())
    return [found[k] for k in sorted(found)]


def content_hash(path: Path) -> str:
    """sha256 of the file's bytes, hex: the same flight copied elsewhere is the same row."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(HASH_CHUNK_BYTES):
            h.update(chunk)
    return h.hexdigest()
