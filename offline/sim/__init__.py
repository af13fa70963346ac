"""Batched 6-DOF quadrotor simulator with a PX4-like controller (issue 2).

Entry points: ``simulate`` (simulator.py), ``SimConfig``, ``FlightLog`` (log.py),
propeller models (propeller.py), missions (mission.py), writers (io_npz.py,
io_tlog.py) and ``propwatch simulate`` (cli.py).
"""
