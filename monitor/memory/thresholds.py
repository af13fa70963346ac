"""The constants of the vehicle-memory judgement, each with the command that measured it.

All were measured on our own simulator's same-airframe fleet (``offline/vehicles/ours.py``, seed 1, 24 airframes,
3 references + 9 later flights each), never on the evaluation-only simulator:

    python -m offline.vehicles.calibrate --fleet OUT/ours_cal

(``make tune-memory`` simulates that fleet and runs it; ``make evaluate-memory`` measures the rule; figures in
docs/VEHICLE_MEMORY.md.)

- ``PRIOR_COV``: the flight-to-flight covariance of a healthy vehicle's share intercepts (PX4 rotor order), the
  population's, before a vehicle's own flights refine it. ``PRIOR_FLIGHTS``: how many flights that prior weighs, a
  stated prior (with 3 flights of its own, a vehicle's spread is 3 parts prior to 2 parts its own).
- ``FAULT_STATISTIC``: the fault statistic (chi^2 units: the best hypothesis's improvement over "as normal") from
  which a flight is FAULTY: at least the healthy later flights' 99th percentile (7.4 on that fleet: a false FAULT on
  at most 1 % of a vehicle's healthy flights), raised in steps of 0.5 while no exactly named single of >= 6 % is lost
  (12.0; 1 of 96 healthy flights past it, ambiguous). ``SUSPECT_STATISTIC``: the healthy 95th percentile.
- ``SET_STATISTIC``: a hypothesis stays in the set while its statistic is within this of the best: the 99th
  percentile of (best - truth) over damaged singles past the healthy 99th percentile.
- ``SCAN_FAULT_STATISTIC`` / ``SCAN_SUSPECT_STATISTIC``: the same levels for a flight judged through time
  (``monitor.memory.through_time``: the largest statistic of the flight's ends from each 2-s mark): the healthy later
  flights' 99th / 95th percentile of that largest statistic, never below ``FAULT_STATISTIC`` / ``SUSPECT_STATISTIC``.
"""

from __future__ import annotations

PRIOR_COV = (
    (8.859e-05, -2.835e-05, -3.423e-05, -2.600e-05),
    (-2.835e-05, 4.892e-05, -1.846e-05, -2.115e-06),
    (-3.423e-05, -1.846e-05, 9.079e-05, -3.810e-05),
    (-2.600e-05, -2.115e-06, -3.810e-05, 6.622e-05),
)
PRIOR_FLIGHTS = 3.0
FAULT_STATISTIC = 12.0
SUSPECT_STATISTIC = 3.5
SET_STATISTIC = 3.6
SCAN_FAULT_STATISTIC = 14.0
SCAN_SUSPECT_STATISTIC = 6.5
# The thrust loss a verdict of "healthy" claims to exclude: a healthy verdict is confident only where a loss this
# large on any one rotor would have crossed FAULT_STATISTIC (the bar for exact naming).
CLAIMED_LOSS = 0.06
MEASURED_BY = "python -m offline.vehicles.calibrate --fleet OUT/ours_cal (our simulator, seed 1, 24 airframes)"
