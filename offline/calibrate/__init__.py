"""Sim-to-real calibration: show what the simulation gets wrong, name the cause, fix the model.

``calibrate(tables, vehicle)`` (calibrate.py) is the library entry point; ``fit.py`` fits the term library
(terms.py) and selects by held-out BIC through gates whose every verdict is reported, and holds the steady-state
view for logs without body rates; ``unexplained.py`` reports what no term can express. ``propwatch calibrate``
(cli.py) reads logs, prints or writes the result, the calibrated vehicle YAML (writer.py) and a report with plots
(report.py). The gates are set on our own simulator's nominal flights (nominal_flights.py, derive_gates.py); see
docs/CALIBRATION.md.
"""
