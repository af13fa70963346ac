"""What the docs, model cards, Makefile and comments cite exists: every ``python -m X`` of ours names a module
in the repository, every repository path (``monitor/...``, ``offline/...``, ``docs/...``) a file or folder, every
backquoted ``make TARGET`` a Makefile target (outside tests/, whose synthetic cards cite made-up ones), and every
dotted name of ours (``offline.tune.sets.measure``) a module, or a name that module mentions. A command cited in a
deprecated form (``propwatch evalsim``, ``propwatch evaluate --flag`` without a suite, ``python -m`` of a module
that only says it is deprecated) counts as stale too, except on a line that says "deprecated".

Generated paths are not checked: ``out/...``, paths with a placeholder (``<model>``, ``{name}``, ``*``, ``$(...)``,
``NAME``) and recorded manifests (``models/*.json`` keep the command that made them). Reads text only; imports
nothing.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("monitor", "offline", "fleet", "bench", "tests")
TOP = (*PACKAGES, "docs", "models", "deploy")
EXTENSIONS = "py|md|yaml|yml|json|onnx|npz|txt|service|cfg|toml|svg|png|csv|tlog|ulg|bin"

PATH = re.compile(rf"(?<![\w./-])((?:{'|'.join(TOP)})/[\w./-]*?(?:\.(?:{EXTENSIONS})\b|/))(?![\w*<{{$-])")
DOTTED = re.compile(rf"(?<![\w./-])((?:{'|'.join(PACKAGES)})(?:\.[A-Za-z_]\w*)+)(?![\w(/-])")
RUN_MODULE = re.compile(r"python3? -m ([A-Za-z_][\w.]*)")
MAKE = re.compile(r"`make((?: [a-z][\w-]*)+)")  # `make a b`: targets up to the first VAR=... or the backtick
FILE_SUFFIXES = {"py", "md", "yaml", "yml", "json", "parquet", "onnx", "npz", "txt", "csv", "duckdb"}
INSTALLED_ONLY = {"monitor.shipped"}  # setup.py maps models/ onto it (monitor/resources.py)
PLACEHOLDER = re.compile(r"\b(?:NAME|DIR|FILE)\b")
SELF = Path(__file__).resolve()


def make_targets() -> set[str]:
    return set(re.findall(r"^([a-z][\w-]*):", (REPO / "Makefile").read_text(encoding="utf-8"), re.M))


TARGETS = make_targets()


def deprecated_commands() -> re.Pattern:
    """``propwatch OLD`` for each former command of monitor/cli.py's DEPRECATED, and ``propwatch evaluate`` given
    a flag or a model where its suite goes (offline/evaluate.py)."""
    table = re.search(r"^DEPRECATED[^{]*\{(.*?)\}$", (REPO / "monitor" / "cli.py").read_text(encoding="utf-8"), re.M | re.S)
    old = re.findall(r'"([\w-]+)":', table.group(1)) if table else []
    return re.compile(rf"\bpropwatch (?:(?:{'|'.join(old) or '(?!)'})\b|evaluate (?:-|\S+\.(?:onnx|pt)\b))")


DEPRECATED_COMMAND = deprecated_commands()


def cited_in() -> list[Path]:
    """The files read: docs, model cards, README files (deploy/ too), the Makefile and our Python sources."""
    files = [
        REPO / "README.md",
        REPO / "Makefile",
        *sorted((REPO / "docs").rglob("*.md")),
        *sorted((REPO / "models").glob("*.md")),
        *sorted((REPO / "deploy").glob("*.md")),
    ]
    for package in PACKAGES:
        files += sorted(p for p in (REPO / package).rglob("*") if p.suffix in (".py", ".md") and "fixtures" not in p.parts)
    return [p for p in files if p.is_file() and p.resolve() != SELF]


def module_file(dotted: str) -> Path | None:
    """The file of module ``dotted`` (a package's ``__init__.py``), or None."""
    base = REPO.joinpath(*dotted.split("."))
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def only_says_deprecated(module: str) -> bool:
    """True when ``module`` is only a former entry point: it says it is deprecated and defines nothing."""
    found = module_file(module)
    text = "" if found is None else found.read_text(encoding="utf-8")
    return "is deprecated: use" in text and re.search(r"^(?:def|class) ", text, re.M) is None


def dotted_missing(dotted: str) -> bool:
    """True when ``dotted`` is neither a module nor a name its longest module prefix mentions as a word."""
    parts = dotted.split(".")
    if parts[-1] in FILE_SUFFIXES or parts[-1].startswith("__") or dotted in INSTALLED_ONLY:
        return False  # a file name (monitor.yaml), a dunder, a package only an install has
    for n in range(len(parts), 0, -1):
        found = module_file(".".join(parts[:n]))
        if found is not None:
            if n == len(parts):
                return False
            return re.search(rf"\b{re.escape(parts[n])}\b", found.read_text(encoding="utf-8")) is None
    return True


def path_missing(cited: str) -> bool:
    return PLACEHOLDER.search(cited) is None and not (REPO / cited.rstrip("/")).exists()


def stale(name: str, text: str) -> list[str]:
    """``name:line: cited`` for each citation in ``text`` that names nothing in the repository."""
    out = []
    for i, line in enumerate(text.splitlines(), 1):
        found = {m for m in RUN_MODULE.findall(line) if m.split(".")[0] in PACKAGES and module_file(m) is None}
        if "deprecated" not in line:
            found |= {f"python -m {m}" for m in RUN_MODULE.findall(line) if only_says_deprecated(m)}
            found |= {m for m in DOTTED.findall(line) if only_says_deprecated(m) and f"python -m {m}" not in found}
            found |= set(DEPRECATED_COMMAND.findall(line))
        found |= {m for m in PATH.findall(line) if path_missing(m)}
        if not name.startswith("tests/"):
            found |= {f"make {t}" for ts in MAKE.findall(line) for t in ts.split() if t not in TARGETS}
        found |= {m.rstrip(".") for m in DOTTED.findall(line) if dotted_missing(m.rstrip("."))}
        out += [f"{name}:{i}: {m}" for m in sorted(found)]
    return out


def test_every_cited_module_and_path_exists():
    problems = [p for f in cited_in() for p in stale(str(f.relative_to(REPO)), f.read_text(encoding="utf-8"))]
    assert not problems, "cited but not in the repository:\n" + "\n".join(problems)


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("run `python -m offline.alerts.nowhere --x`", ["offline.alerts.nowhere"]),
        ("see monitor/baseline_gone.py and docs/NOWHERE.md", ["docs/NOWHERE.md", "monitor/baseline_gone.py"]),
        ("``offline.tune.sets.no_such_name`` fits it", ["offline.tune.sets.no_such_name"]),
        ("python -m offline.tune.sets; offline/tune/sets.py; ``offline.tune.sets.measure``; offline/tune/", []),
        ("run `make tune-alerts evaluate-alerts HOURS=1` or `make nowhere-target`", ["make nowhere-target"]),
        ("out/alerts/alerts.json, models/<model>.sets.json, bench/*.py, models/NAME.yaml, python -m pytest", []),
        ("monitor.yaml, fleet.parquet, monitor.__file__, monitor.shipped", []),
        ("`propwatch evalsim --set paper`, `propwatch evaluate --evalsim`", ["propwatch evalsim", "propwatch evaluate -"]),
        (
            "propwatch evaluate m.onnx d.npz; propwatch evaluate classifier m.onnx; propwatch evaluate SUITE",
            ["propwatch evaluate m.onnx"],
        ),
        ("python -m offline.classifier.conformal --model m.onnx", ["offline.classifier.conformal"]),  # removed
        ("the rule ``offline.classifier.conformal`` fits", ["offline.classifier.conformal"]),
    ],
)
def test_the_check_finds_what_is_gone_and_only_that(line, expected):
    assert [s.split(": ", 1)[1] for s in stale("doc.md", line)] == expected
