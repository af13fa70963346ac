"""Benchmarks and measurement scripts: each runs as ``python -m bench.<name>`` from the repository root.

``REPO`` is the repository root, for scripts that read shipped models or write under ``out/``.
"""

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
