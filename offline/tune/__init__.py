"""``propwatch tune``: what is fitted to a shipped model's outputs (set coverage, alert thresholds); see ``cli``."""
