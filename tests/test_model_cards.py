"""Cards come from code and manifests; manifests are strict JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from monitor.vehicle import REPO_ROOT
from offline.manifest import write_manifest

MODELS = REPO_ROOT / "models"


def _strict(text: str):
    def refuse(c):
        raise ValueError(f"bare {c} is not JSON")

    return json.loads(text, parse_constant=refuse)


def test_write_manifest_writes_undefined_figures_as_null(tmp_path):
    path = write_manifest(
        tmp_path / "m.json", {"a": float("nan"), "b": [1.0, float("inf")], "c": np.array([np.nan, 2.0]), "d": np.float64("nan")}
    )
    assert _strict(path.read_text()) == {"a": None, "b": [1.0, None], "c": [None, 2.0], "d": None}


@pytest.mark.parametrize("name", sorted(p.name for p in MODELS.glob("*.manifest.json")))
def test_shipped_manifests_are_strict_json(name):
    _strict((MODELS / name).read_text(encoding="utf-8"))


def test_crazyflie_card_is_the_one_its_manifest_writes():
    from offline.crazypad.card import card_markdown

    manifest = json.loads((MODELS / "crazyflie-classifier.manifest.json").read_text(encoding="utf-8"))
    card = (MODELS / "crazyflie-classifier.card.md").read_text(encoding="utf-8")
    assert card == card_markdown(manifest), "regenerate with offline.crazypad.card.write_card"
    # Spot-check one figure against the manifest: the shipped model's accuracy on all scored flights.
    acc = manifest["shipped"]["table"]["calibrated"]["all"]["accuracy"]
    assert f"{100 * acc:.1f} %" in card
