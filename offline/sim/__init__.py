"""Batched 6-DOF quadrotor simulator with a PX4-like controller.

Entry points: ``simulate`` (simulator.py), ``SimConfig``, ``FlightLog`` (log.py),
propeller models (propeller.py; fault signatures: faults.py), missions (mission.py),
writers (io_npz.py, io_tlog.py). ``propwatch simulate`` is ``offline/simulate.py``.
"""
