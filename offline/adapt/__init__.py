"""``propwatch adapt``: a new airframe from its healthy logs to a model, a card and a healthy baseline."""
