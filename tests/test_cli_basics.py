"""What every command offers a new user: --version, help text on every option, --help without torch."""

from __future__ import annotations

import contextlib
import io
import re
import subprocess
import sys
from pathlib import Path

import pytest

import monitor
from monitor.cli import COMMANDS, main

REPO = Path(__file__).resolve().parents[1]


def _stdout(argv: list[str]) -> str:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.suppress(SystemExit):
        main(argv)
    return buf.getvalue()


def _options_without_help(text: str) -> list[str]:
    """argparse prints an option's help on its line or indented below; an option alone has none."""
    lines = text.splitlines()
    bad = []
    for i, line in enumerate(lines):
        alone = line.startswith("  -") and not re.search(r"\S {2,}\S", line.strip())
        if alone and not re.match(r"^ {6,}\S", lines[i + 1] if i + 1 < len(lines) else ""):
            bad.append(line.strip())
    return bad


def _help_pages():
    for name in COMMANDS:
        text = _stdout([name, "--help"])
        yield name, text
        if name == "crazypad":
            for sub in ("analyse", "calibrate", "run"):
                yield f"{name} {sub}", _stdout([name, sub, "--help"])


def test_version_everywhere(capsys):
    declared = re.search(r'^version = "([^"]+)"', (REPO / "pyproject.toml").read_text(), re.M).group(1)
    assert monitor.__version__ == declared
    for argv in (["--version"], ["diagnose", "--version"], ["train", "--version"]):
        assert main(argv) == 0
        assert capsys.readouterr().out.strip() == f"propwatch {monitor.version()}"


def test_every_option_has_help_text():
    pages = dict(_help_pages())
    assert set(COMMANDS) <= set(pages)
    missing = {name: bad for name, text in pages.items() if (bad := _options_without_help(text))}
    assert not missing, f"options without help text: {missing}"
    assert _options_without_help("  --seed SEED\n  --out OUT   where\n") == ["--seed SEED"]  # the check itself


@pytest.mark.parametrize(
    "name", ["train", "export", "evaluate", "calibrate", "train-propellers", "dataset", "crazypad", "evalsim"]
)
def test_help_does_not_import_torch(name):
    code = f"import sys; sys.modules['torch'] = None; from monitor.cli import main; sys.exit(main([{name!r}, '--help']))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "usage: propwatch" in r.stdout


def test_microseconds_are_converted_through_one_constant():
    """One ``US_PER_S`` (monitor/resample.py); no inline 1e6 / 1e-6 / 1_000_000 next to a µs quantity."""
    import re as _re

    defs, inline = [], []
    for path in sorted((REPO / "monitor").rglob("*.py")) + sorted((REPO / "offline").rglob("*.py")):
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            code = line.split("#")[0]
            if _re.match(r"\s*US_PER_S\s*=", code):
                defs.append(str(path.relative_to(REPO)))
            if _re.search(r"(_us\b|usec|timestamp)", code) and _re.search(r"\b(1e6|1e-6|1_000_000|1000000)\b", code):
                inline.append(f"{path.relative_to(REPO)}:{n}: {line.strip()}")
    assert defs == ["monitor/resample.py"]
    assert not inline, inline
