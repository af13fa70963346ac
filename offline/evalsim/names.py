"""The evaluation sets' names and default flight length, apart so ``propwatch evalsim --help`` imports no simulator (torch)."""

SET_NAMES = ("paper", "shift", "healthy", "onset", "hidden", "effectiveness")
DEFAULT_DURATION_S = 80.0
