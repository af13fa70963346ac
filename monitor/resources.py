"""Where the shipped models and vehicle configs are, in a checkout and when installed.

The repository keeps them in ``models/`` at its root (where ``make models`` and
``propwatch crazypad --ship`` write them). A wheel installs the same files as
package data of ``monitor.shipped`` (``setup.py`` maps that package onto
``models/``), read through ``importlib.resources``. A checkout, editable or
not, reads ``models/`` itself, so a rebuilt model is used at once.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
REPO_MODELS = REPO_ROOT / "models"
SHIPPED_PACKAGE = "monitor.shipped"


def models_dir() -> Path:
    """The folder holding the shipped artefacts: the checkout's ``models/``, else the installed package data."""
    if (REPO_MODELS / "vehicle.yaml").is_file():
        return REPO_MODELS
    # Not found either way: the installed path, so that the first file opened names it in its error.
    return Path(str(resources.files("monitor") / "shipped"))


def shipped(name: str) -> Path:
    """Path of one shipped artefact (``"classifier.onnx"``, ``"crazyflie.yaml"``, ``"propellers"``)."""
    return models_dir() / name


def display_path(path: Path) -> str:
    """``models/crazyflie.yaml`` in a checkout (what a user types from its root); the full path when installed."""
    try:
        return str(path.relative_to(REPO_ROOT))
    except ValueError:
        return str(path)
