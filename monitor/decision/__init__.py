"""The decision layer: from each window's evidence to suspect / fault, shared by the daemon and ``diagnose``.

Each name lives in one module and is imported from there (this package re-exports nothing):

* ``rule``: the CUSUMs, the two levels and the STATUSTEXT wording (``Decision``, ``statustext``); its docstring
  describes the whole rule.
* ``config``: the rule's settings and levels (``DecisionConfig``).
* ``thresholds``: thresholds from the false-alarm rates, and the calibration file that sets them.
* ``regime``: landing, take-off, manoeuvres, collective steps and battery sag (``RegimeTracker``, ``StepInputs``).
* ``rotor_share``: physics evidence from the rotors' omega^2 shares and the yaw balance (``RotorShare``).
* ``stream_evidence``: VIBRATION and ESC_STATUS checked before they count as evidence.
* ``effectiveness``: rotor effectiveness from the moment balance, and the 16 propeller-set hypotheses it weighs.
* ``hypotheses``: the conformal set of propeller-set hypotheses a verdict names.
* ``envelope``: the physical envelope of the context streams (velocity, specific force), for the daemon and the log
  reader alike.
"""
