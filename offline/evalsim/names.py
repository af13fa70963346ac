"""Set names and defaults, importable without RotorPy (which imports torch): keeps ``--help`` fast."""

SET_NAMES = (
    "paper",
    "shift",
    "healthy",
    "onset",
    "hidden",
    "effectiveness",
    "paper_torque_rising",
    "shift_half",
    "shift_quarter",
    "forward_flight",
    "vehicles",
)
DEFAULT_DURATION_S = 80.0
