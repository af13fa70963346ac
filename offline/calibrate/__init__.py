"""Sim-to-real calibration (issue 7): show what the simulation gets wrong, name the cause, fix the model.

``calibrate(tables, vehicle)`` (calibrate.py) is the library entry point;
``propwatch calibrate`` (cli.py) reads logs, prints or writes the result, the
calibrated vehicle YAML (writer.py) and a report with plots (report.py).
"""
