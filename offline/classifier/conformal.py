"""Former entry point of ``propwatch tune sets`` (``offline/tune/sets.py``): runs it after one line naming it."""

import sys

if __name__ == "__main__":
    from offline.tune.sets import main

    print("python -m offline.classifier.conformal is deprecated: use 'propwatch tune sets'", file=sys.stderr)
    raise SystemExit(main())
