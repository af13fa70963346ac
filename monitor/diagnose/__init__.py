"""``propwatch diagnose``: recorded flight logs -> per-propeller fault verdicts."""
