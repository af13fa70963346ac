"""Wall time of ``propwatch COMMAND --help`` for every command, each in a fresh interpreter.

    python -m bench.bench_help [--repeat 3] [--budget-s 1.0]

A fresh process per call is what a user meets (imports included). Prints the best of
--repeat runs per command and whether it is inside the budget (< 1 s; torch
is imported only where the work needs it). A budget check printed, not a test assertion:
timings depend on the machine.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

from bench import REPO
from monitor.cli import COMMANDS  # noqa: E402


def time_help(argv: list[str], repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "monitor.cli", *argv], cwd=REPO, capture_output=True, check=True)
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs per command; the best is shown (default 3)")
    ap.add_argument("--budget-s", type=float, default=1.0, help="budget per --help (default 1.0 s)")
    a = ap.parse_args()
    over = []
    for argv in [["--help"], ["--version"]] + [[name, "--help"] for name in COMMANDS]:
        s = time_help(argv, a.repeat)
        ok = s < a.budget_s
        over += [] if ok else [" ".join(argv)]
        print(f"  propwatch {' '.join(argv):<28} {s:6.3f} s  {'ok' if ok else 'OVER BUDGET'}")
    print(f"budget {a.budget_s:g} s: " + ("all inside" if not over else f"over: {', '.join(over)}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
