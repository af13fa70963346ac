"""The README is a front door and ``diagnose --help`` fits a screen: what a new user reads first stays short."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_readme_is_short_and_every_link_leads_somewhere():
    text = (REPO / "README.md").read_text()
    assert len(text.splitlines()) <= 120
    assert "make demo" in text and "make test" in text
    for command in ("propwatch diagnose", "propwatch fleet ingest", "propwatch monitor"):
        assert f"$ {command}" in text, command  # each everyday command with an example of what it prints
    links = re.findall(r"\]\(([^)#]+)\)", text)
    assert len(links) >= 6 and all((REPO / link).is_file() for link in links), links


def test_measured_figures_moved_not_lost():
    """The evaluation tables live in docs/EVALUATION.md now: the headline figures are still there."""
    evaluation = (REPO / "docs" / "EVALUATION.md").read_text()
    for figure in ("0.24/0.41 %", "33.6 % exact label", "moves **0.5**", "75.0 %"):
        assert figure in evaluation, figure


def test_diagnose_help_fits_in_25_lines():
    env = {**os.environ, "COLUMNS": "80"}
    r = subprocess.run([sys.executable, "-m", "monitor.cli", "diagnose", "--help"], capture_output=True, text=True, env=env)
    assert r.returncode == 0 and len(r.stdout.splitlines()) <= 25, r.stdout
    assert "docs/diagnose-json.md" in r.stdout
