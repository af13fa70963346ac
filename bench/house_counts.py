"""The shape of the import graph, counted from the source with ``ast``: ``python -m bench.house_counts``.

Counted over every ``.py`` file of ``monitor``, ``offline``, ``fleet`` and ``bench`` (imports inside functions
included; a ``from a.b import c`` goes to module ``a.b.c`` where that is a module, else to ``a.b``):

* ``monitor root modules``: loose modules directly in ``monitor/`` (not ``__init__`` or ``__main__``).
* ``monitor modules`` and ``monitor arrows``: modules of ``monitor`` and distinct importer -> imported pairs
  between them.
* ``arrows back up``: an import against the layering, ``monitor`` < ``offline``, ``fleet`` < ``bench``
  (``monitor`` imports neither; nothing but ``bench`` imports ``bench``), plus, inside ``monitor``, a library
  module importing a command's module (``APPS``).
* ``arrows across commands``: one command's modules importing another's (``monitor.cli`` and
  ``monitor.__main__`` dispatch to all of them and are not counted).
* ``cycles``: strongly connected groups of more than one module (each listed).

And for ``offline`` by package (a subpackage, or a loose module of ``offline/``'s root, is one package):

* ``offline modules per package``, ``offline package arrows`` (distinct importer -> imported package pairs, each
  with its number of module arrows) and ``offline package cycles``;
* ``offline arrows back up``: a package importing one of a higher layer of ``OFFLINE_LAYERS`` (lowest first),
  each with the module arrows behind it; ``offline packages without a layer`` names any package not placed there.
"""

from __future__ import annotations

import argparse
import ast
import json
from pathlib import Path

from bench import REPO

PACKAGES = ("monitor", "offline", "fleet", "bench")
LAYER = {"monitor": 0, "offline": 1, "fleet": 1, "bench": 2}
APPS = {
    "daemon": ("monitor.daemon",),
    "diagnose": ("monitor.diagnose",),
    "inspect": ("monitor.inspect.cli", "monitor.inspect.log"),
    "replay": ("monitor.mavlink.player",),
}
DISPATCH = ("monitor.cli", "monitor.__main__")
# offline's packages, lowest layer first: shared records; the simulator; its propeller models and fleets; data
# sets and the evaluation-only simulator; the classifier; what is scored or fitted on its outputs; what tunes
# those; the pipelines built on all of it; the commands at offline/'s root.
OFFLINE_LAYERS = (
    ("offline", "offline.manifest", "offline.response_gain", "offline.share_baseline"),
    ("offline.sim",),
    ("offline.propellers",),
    ("offline.fleet_sim",),
    ("offline.dataset", "offline.evalsim"),
    ("offline.classifier",),
    ("offline.alerts", "offline.calibrate"),
    ("offline.tune", "offline.crazypad", "offline.vehicles"),
    ("offline.adapt",),
    ("offline.demo", "offline.evaluate", "offline.simulate"),
)


def module_names(repo: Path) -> dict[str, Path]:
    names = {}
    for package in PACKAGES:
        for path in sorted((repo / package).rglob("*.py")):
            parts = list(path.relative_to(repo).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            names[".".join(parts)] = path
    return names


def imports_of(name: str, path: Path, names: dict[str, Path]) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            bases = [alias.name for alias in node.names]
            targets.update(_known(base, names) for base in bases)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                full = f"{base}.{alias.name}"
                targets.add(full if full in names else _known(base, names))
    targets.discard(name)
    targets.discard("")
    return targets


def _known(dotted: str, names: dict[str, Path]) -> str:
    while dotted and dotted not in names:
        dotted = dotted.rpartition(".")[0]
    return dotted


def _app(name: str) -> str | None:
    return next((app for app, roots in APPS.items() for r in roots if name == r or name.startswith(r + ".")), None)


def back_up(source: str, target: str) -> bool:
    top_source, top_target = source.split(".")[0], target.split(".")[0]
    if LAYER[top_target] > LAYER[top_source]:
        return True
    return top_source == top_target == "monitor" and _app(source) is None and _app(target) is not None


def across(source: str, target: str) -> bool:
    if source in DISPATCH:
        return False
    app_source, app_target = _app(source), _app(target)
    return None not in (app_source, app_target) and app_source != app_target


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            group = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                group.append(member)
                if member == node:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def offline_package(name: str) -> str | None:
    """``offline.sim`` for ``offline.sim.io_tlog``; a loose module of offline/'s root is its own package."""
    parts = name.split(".")
    if parts[0] != "offline":
        return None
    return ".".join(parts[:2])


def offline_counts(graph: dict[str, set[str]]) -> dict:
    pkg = {n: offline_package(n) for n in graph}
    per_package: dict[str, int] = {}
    for p in filter(None, pkg.values()):
        per_package[p] = per_package.get(p, 0) + 1
    arrows: dict[tuple[str, str], list[str]] = {}
    for s in graph:
        for t in graph[s]:
            a, b = pkg[s], pkg.get(t)
            if a is not None and b is not None and a != b:
                arrows.setdefault((a, b), []).append(f"{s} -> {t}")
    layer = {p: i for i, group in enumerate(OFFLINE_LAYERS) for p in group}
    up = [
        f"{a} -> {b}: " + ", ".join(sorted(mods))
        for (a, b), mods in sorted(arrows.items())
        if a in layer and b in layer and layer[b] > layer[a]
    ]
    package_graph: dict[str, set[str]] = {p: set() for p in per_package}
    for a, b in arrows:
        package_graph[a].add(b)
    return {
        "offline packages": len(per_package),
        "offline modules": sum(per_package.values()),
        "offline modules per package": dict(sorted(per_package.items(), key=lambda kv: (-kv[1], kv[0]))),
        "offline package arrows": [f"{a} -> {b} ({len(m)})" for (a, b), m in sorted(arrows.items())],
        "offline package cycles": cycles(package_graph),
        "offline arrows back up": up,
        "offline packages without a layer": sorted(p for p in per_package if p not in layer),
    }


def counts(repo: Path = REPO) -> dict:
    names = module_names(repo)
    graph = {name: {t for t in imports_of(name, path, names) if t in names} for name, path in names.items()}
    monitor = {n for n in names if n == "monitor" or n.startswith("monitor.")}
    root = [n for n in monitor if n.count(".") == 1 and names[n].name not in ("__init__.py", "__main__.py")]
    root = [n for n in root if names[n].parent == repo / "monitor"]
    monitor_arrows = [(s, t) for s in monitor for t in graph[s] if t in monitor]
    up = sorted(f"{s} -> {t}" for s in graph for t in graph[s] if back_up(s, t) and s not in DISPATCH)
    sideways = sorted(f"{s} -> {t}" for s in graph for t in graph[s] if across(s, t))
    return {
        "monitor root modules": len(root),
        "monitor modules": len(monitor),
        "monitor arrows": len(monitor_arrows),
        "all modules": len(names),
        "all arrows": sum(len(t) for t in graph.values()),
        "arrows back up": up,
        "arrows across commands": sideways,
        "cycles": cycles(graph),
        **offline_counts(graph),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print the counts as JSON")
    parser.add_argument("--repo", type=Path, default=REPO, help="the tree to count (default: this one)")
    args = parser.parse_args(argv)
    result = counts(args.repo)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    for key, value in result.items():
        if isinstance(value, list):
            print(f"{key}: {len(value)}")
            for item in value:
                print(f"  {item if isinstance(item, str) else ' <-> '.join(item)}")
        elif isinstance(value, dict):
            print(f"{key}: " + ", ".join(f"{k} {v}" for k, v in value.items()))
        else:
            print(f"{key}: {value}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
