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
    "strangers_healthy",
    "strangers_onset",
    "strangers_takeoff",
    "strangers_stopped",
    "strangers_memory",
)
# Quad-X airframes of other sizes (offline/evalsim/strangers.py).
STRANGER_SETS = tuple(n for n in SET_NAMES if n.startswith("strangers_"))
# The seed the strangers_* sets are scored on, fixed before any threshold of the first-flight rules was set; never
# run while developing. Try the generator and the harness with STRANGERS_DEV_SEED.
STRANGERS_EVAL_SEED = 4_719_355
STRANGERS_DEV_SEED = 11
DEFAULT_DURATION_S = 80.0
