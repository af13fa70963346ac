"""CrazyPAD sim-to-real experiment: real Crazyflie 2.1 flights with cut
propellers, tape and CG-offset masses, against the simulator and the classifier.

Modules: ``vehicle`` (Bitcraze motor numbering, hover command), ``mission`` (the
CrazyPAD flight script as a mission), ``data`` (manifest, split, per-flight
summaries), ``experiment`` (calibrate, train, evaluate) and ``cli``
(``propwatch crazypad``).
"""
