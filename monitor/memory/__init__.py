"""Vehicle memory: each vehicle's own healthy normal, learnt from its flights, and every flight judged against it.

One mechanism, used by ``propwatch diagnose --baseline``, the daemon (``--state-dir``) and ``fleet ingest``:

- ``summary``: a flight (or the part of it flown so far) reduced to sufficient statistics of its rotors'
  omega^2 shares and the regime they were flown in. The daemon feeds it step by step, a log reader all at once;
  the same arithmetic either way.
- ``baseline``: the vehicle's normal (``VehicleBaseline``, one JSON format, ``B.json``): the flights it was learnt
  from, their shares' normal and flight-to-flight spread, the maintenance events.
- ``learn``: flights declared healthy (or that raised nothing) into a baseline; a declared-healthy flight whose rotor
  lies beyond the others' spread is refused, naming the rotor.
- ``judge``: a flight against the baseline: per-rotor deviation, hypothesis sets, confidence at a stated
  false-alarm rate (``monitor/memory/thresholds.py`` names the command that measured it).
- ``cli``: ``propwatch baseline learn | show | note``.

Shares are in PX4 quad-X order (1 front-right CCW, 2 rear-left CCW, 3 front-left CW, 4 rear-right CW).
"""
