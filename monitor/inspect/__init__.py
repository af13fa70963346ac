"""``propwatch inspect``: what propwatch read from a log (``cli``: the command; ``log``: the statistics and CSV)."""
