"""The ``propwatch`` console command: a thin dispatcher over subcommand modules.

Each subcommand lives in its own module with ``main(argv=None) -> int`` and is
imported only when asked for, so ``propwatch monitor`` never imports torch or
``offline``. Library errors (``PropwatchError``) become one line on stderr and
exit code 2; nothing else is caught.
"""

from __future__ import annotations

import importlib
import os
import signal
import sys

from monitor.errors import PropwatchError

# name -> (module, one-line help). Offline commands need the ``offline`` extra.
COMMANDS: dict[str, tuple[str, str]] = {
    "simulate": ("offline.simulate", "simulate flights (npz or PX4-like tlog) with ground truth"),
    "train-propellers": ("offline.propellers.cli", "virtual load cell + LSTM propeller models"),
    "dataset": ("offline.dataset.cli", "generate labelled fault data sets (A, B, C, ...)"),
    "train": ("offline.classifier.train_cli", "train the CNN fault classifier"),
    "export": ("offline.classifier.export_cli", "export a trained classifier to ONNX"),
    "evaluate": ("offline.evaluate", "evaluation suites: classifier, alerts, evalsim (evaluation-only sets)"),
    "calibrate": ("offline.calibrate.cli", "fit model extensions to measured flights"),
    "tune": ("offline.tune.cli", "fit beside a shipped model: set coverage (sets), alert thresholds (alerts)"),
    "crazypad": ("offline.crazypad.cli", "sim-to-real experiment on CrazyPAD"),
    "adapt": ("offline.adapt.cli", "calibrate, simulate, train and baseline a new airframe from its healthy logs"),
    "diagnose": ("monitor.diagnose.cli", "diagnose recorded flight logs"),
    "inspect": ("monitor.inspect.cli", "what propwatch read from a log: messages, rates, gaps, motors, CSV"),
    "monitor": ("monitor.daemon.cli", "run the onboard monitor daemon"),
    "keygen": ("monitor.daemon.keygen", "write a new MAVLink 2 signing key for the monitor (mode 0600)"),
    "replay": ("monitor.mavlink.player", "replay a .tlog as if it were PX4"),
    "fleet": ("fleet.cli", "fleet: ingest many logs into a health database (Ray), web report"),
    "baseline": ("monitor.memory.cli", "a vehicle's healthy normal from its own flights: learn, show, note, reset"),
}
# Former commands: each still runs as its new form, after a line on stderr naming it.
DEPRECATED: dict[str, tuple[str, ...]] = {"evalsim": ("evaluate", "evalsim")}


def usage() -> str:
    width = max(map(len, COMMANDS))
    lines = ["usage: propwatch COMMAND [ARGS...]", "", "commands:"]
    lines += [f"  {name:<{width}}  {help_}" for name, (_, help_) in COMMANDS.items()]
    lines += ["", "'propwatch COMMAND --help' for a command's options; 'propwatch --version' (anywhere on the line)."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0 if argv else 2
    if "--version" in argv:  # anywhere: before or after a command and its arguments
        from monitor import version

        print(f"propwatch {version()}")
        return 0
    name, rest = argv[0], argv[1:]
    if name in DEPRECATED:
        new_form = DEPRECATED[name]
        print(f"propwatch {name} is deprecated: use 'propwatch {' '.join(new_form)}'", file=sys.stderr)
        name, rest = new_form[0], [*new_form[1:], *rest]
    if name not in COMMANDS:
        print(f"propwatch: unknown command {name!r}\n\n{usage()}", file=sys.stderr)
        return 2
    module_name = COMMANDS[name][0]
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        if module_name.startswith("offline") and getattr(exc, "name", "") in ("torch", "onnx", "matplotlib", "scipy"):
            print(f"propwatch {name}: needs the offline extra (pip install 'propwatch[offline]'): {exc}", file=sys.stderr)
            return 2
        raise
    try:
        code = int(module.main(rest) or 0)
        sys.stdout.flush()  # here, where a reader that went away is caught, not at interpreter exit
        return code
    except PropwatchError as exc:
        print(f"propwatch {name}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # `propwatch ... | head`: the reader closed the pipe; stop quietly as a shell tool does
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # what is still buffered goes nowhere
        return 128 + signal.SIGPIPE


if __name__ == "__main__":
    sys.exit(main())
