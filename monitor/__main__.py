"""``python -m monitor`` runs the monitor daemon (same as ``propwatch monitor``)."""

import sys

from monitor.cli import main

if __name__ == "__main__":
    sys.exit(main(["monitor", *sys.argv[1:]]))
