"""Fleets of vehicles that fly again and again: the evidence vehicle memory (``monitor.memory``) learns from.

``ours``: same-airframe fleets on our own simulator (the set thresholds are measured on);
``evaluate``: every verdict of such a fleet against each vehicle's own history, beside the references.
The evaluation-only simulator's counterpart is ``offline.evalsim`` set ``vehicles``.
"""
