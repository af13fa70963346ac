"""Former entry point of ``propwatch tune noise`` (``offline/tune/noise.py``): runs it after one line naming it."""

import sys

if __name__ == "__main__":
    from offline.tune.noise import main

    print("python -m offline.physics_calibration is deprecated: use 'propwatch tune noise'", file=sys.stderr)
    raise SystemExit(main())
