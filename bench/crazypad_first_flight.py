"""Every CrazyPAD flight diagnosed without history, by this checkout and another, side by side.

    python -m bench.crazypad_first_flight [--root ../shared/data/crazypad] [--against /path/to/other/checkout]

Runs ``propwatch diagnose --json --vehicle models/crazyflie.yaml`` (the Crazyflie's own model, format by log type)
over every log in the data set's manifest, in each checkout, and counts per condition kind (healthy, propeller cut,
tape, weight near M3, weight on a string): the verdict's state, whether a propeller is asked for (replace or
inspect), whether that is M3 (PX4 rotor 2, the one the data set damages), and confident-wrong verdicts (a confident
verdict naming a propeller other than M3, or a confident "healthy" on a damaged propeller).
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
from collections import Counter, defaultdict
from pathlib import Path

from bench import REPO

DAMAGED = ("propeller_cut", "tape_on_propeller")
M3_PX4 = 2


def diagnose_all(repo: Path, root: Path, files: list[tuple[str, str]]) -> dict[str, dict]:
    out = {}
    for log_type in ("motor", "controller"):
        paths = [str(root / f) for f, t in files if t == log_type]
        fmt = "crazypad" if log_type == "motor" else "crazypad-controller"
        cmd = [sys.executable, "-m", "monitor.cli", "diagnose", *paths, "--format", fmt, "--json",
               "--vehicle", str(repo / "models" / "crazyflie.yaml")]  # fmt: skip
        r = subprocess.run(cmd, capture_output=True, text=True, cwd=repo, env={"PYTHONPATH": str(repo), "PATH": ""})
        res = json.loads(r.stdout)
        for x in res.get("results", [res]):
            out[x["log"]] = x
    return out


def tally(results: dict[str, dict], kinds: dict[str, str]) -> dict[str, Counter]:
    by: dict[str, Counter] = defaultdict(Counter)
    for path, res in results.items():
        kind = kinds[path]
        s = res.get("summary") or {}
        c = by[kind]
        c["flights"] += 1
        c["state " + s.get("state", "unreadable")] += 1
        asked = set(s.get("replace", [])) | set(s.get("inspect", []))
        c["a propeller asked for"] += bool(asked)
        c["M3 asked for"] += M3_PX4 in asked
        c["another asked for"] += bool(asked - {M3_PX4})
        confident = s.get("confidence") == "confident"
        if confident and s.get("replace") and set(s["replace"]) != {M3_PX4}:
            c["confident wrong"] += 1
        if confident and kind in DAMAGED and s.get("state") == "healthy":
            c["confident wrong"] += 1
    return by


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--root", type=Path, default=REPO.parent / "shared" / "data" / "crazypad")
    p.add_argument("--against", type=Path, default=None, help="another checkout to run beside this one")
    args = p.parse_args(argv)
    rows = list(csv.DictReader((args.root / "manifest.csv").open()))
    files = [(r["file"], r["log_type"]) for r in rows]
    kinds = {str(args.root / r["file"]): r["fault_kind"] for r in rows}
    repos = {"this checkout": REPO} | ({f"{args.against}": args.against} if args.against else {})
    tallies = {name: tally(diagnose_all(repo, args.root, files), kinds) for name, repo in repos.items()}
    keys = ["flights", "state healthy", "state inspect", "state damaged", "state no verdict", "a propeller asked for",
            "M3 asked for", "another asked for", "confident wrong"]  # fmt: skip
    for kind in sorted({k for t in tallies.values() for k in t}):
        print(f"\n## {kind}")
        print("| checkout | " + " | ".join(keys) + " |")
        print("|---" * (len(keys) + 1) + "|")
        for name, t in tallies.items():
            print(f"| {name} | " + " | ".join(str(t[kind][k]) for k in keys) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
