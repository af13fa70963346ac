"""propwatch tune: fit what sits beside a shipped model to its outputs on our simulator's flights.

    propwatch tune sets [ARGS]    the conformal set rule (<model>.sets.json)
    propwatch tune noise [ARGS]   the moment balance's credible-set coverage (its noise inflation)
    propwatch tune alerts [ARGS]  the decision thresholds (models/decision-calibration.json): a tail fit, then
                                  the thresholds scored on independent flights (propwatch evaluate alerts,
                                  whose options it takes)

'propwatch tune WHAT --help' lists that tool's options. None changes the simulator or the model: fitting the
simulator to measured flights is 'propwatch calibrate'.
"""

from __future__ import annotations

import argparse
import importlib

# what -> (module with main(argv), one line)
TOOLS = {
    "sets": ("offline.tune.sets", "set coverage: the conformal rule beside the model"),
    "noise": ("offline.tune.noise", "set coverage of the moment balance alone: its noise inflation"),
    "alerts": ("offline.tune.alerts", "alert thresholds: the decision's calibration file"),
}


def run(what: str, argv: list[str]) -> int:
    return int(importlib.import_module(TOOLS[what][0]).main(argv) or 0)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="propwatch tune", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("what", choices=sorted(TOOLS), help="; ".join(f"{k}: {v[1]}" for k, v in TOOLS.items()))
    p.add_argument("args", nargs=argparse.REMAINDER, help="that tool's own options (propwatch tune WHAT --help)")
    a = p.parse_args(argv)
    return run(a.what, a.args)
