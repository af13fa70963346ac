"""Evaluation-only second simulator.

NEVER used for training or model selection: it exists to score what we ship on
physics we did not assume. It shares no dynamics, propeller or controller code
with ``offline.sim``: the rigid body is RotorPy's ``Multirotor`` (extended with
per-rotor coefficients), the damage model, wind, sensors and the PX4-like
controller are its own. Its unmeasured assumptions sit away from the centre of
the training ranges on purpose (see README.md). Only the I/O boundary is shared:
``offline.sim.io_tlog`` writes its .tlog from a ``offline.sim.log.FlightLog``.
A test proves no module under offline/dataset, offline/classifier or
offline/propellers imports it.
"""
