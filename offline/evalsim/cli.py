"""propwatch evaluate evalsim: write a named evaluation-only set (tlog + truth JSON per flight + manifest).

NEVER for training or model selection.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from offline.evalsim.names import DEFAULT_DURATION_S, SET_NAMES


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="propwatch evaluate evalsim", description=__doc__)
    p.add_argument("--set", required=True, choices=SET_NAMES, help="named set")
    p.add_argument("--out", required=True, type=Path, help="output folder")
    p.add_argument("--flights", type=int, default=None, help="number of flights (default: one cycle of the set's labels)")
    p.add_argument("--seed", type=int, default=0, help="seed of the set's routes, noise and damage (default 0)")
    p.add_argument(
        "--duration-s", type=float, default=DEFAULT_DURATION_S, help=f"seconds per flight (default {DEFAULT_DURATION_S:g})"
    )
    a = p.parse_args(argv)
    from tqdm import tqdm

    from offline.evalsim.catalog import build_set, write_set  # the simulator (rotorpy, torch): only for work

    n = len(build_set(a.set, a.flights, a.seed, a.duration_s))
    with tqdm(total=n, unit="flight", desc=f"evalsim {a.set}") as bar:
        write_set(a.set, a.out, a.flights, a.seed, a.duration_s, progress=bar.update)
    print(f"wrote {n} flights of set {a.set!r} to {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
