"""propwatch evaluate SUITE: every evaluation under one command, one suite each.

    propwatch evaluate classifier [ARGS]  accuracy, confusion and fault precision/recall per data set, beside
                                          the paper
    propwatch evaluate alerts [ARGS]      the decision rule's false alarms per hour and detection delays on
                                          independent flights of both simulators
    propwatch evaluate evalsim [ARGS]     write a named evaluation-only set from the second simulator, never
                                          for training

'propwatch evaluate SUITE --help' lists a suite's options.
The form before suites ('propwatch evaluate --data ...') is deprecated: the classifier suite runs, with a line on
stderr naming the new form.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# suite -> (module with main(argv), one line)
SUITES = {
    "classifier": ("offline.classifier.evaluate_cli", "a classifier on labelled data sets"),
    "alerts": ("offline.alerts.evaluate", "the decision rule on independent flights"),
    "evalsim": ("offline.evalsim.cli", "write an evaluation-only set from the second simulator"),
}


def run(suite: str, argv: list[str]) -> int:
    return int(importlib.import_module(SUITES[suite][0]).main(argv) or 0)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0].startswith("-") and argv[0] not in ("-h", "--help"):
        print("propwatch evaluate: without a suite is deprecated: use 'propwatch evaluate classifier ...'", file=sys.stderr)
        return run("classifier", argv)
    p = argparse.ArgumentParser(
        prog="propwatch evaluate", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("suite", choices=sorted(SUITES), help="; ".join(f"{k}: {v[1]}" for k, v in SUITES.items()))
    p.add_argument("args", nargs=argparse.REMAINDER, help="the suite's own options (propwatch evaluate SUITE --help)")
    a = p.parse_args(argv)
    return run(a.suite, a.args)
