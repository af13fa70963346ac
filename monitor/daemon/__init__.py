"""The onboard monitor daemon (``propwatch monitor``, ``python -m monitor``).

One job per module: ``config`` (the frozen settings), ``resampler`` (streaming
zero-order hold onto the boot-clock grid), ``pipeline`` (messages -> classified
steps; also used by ``propwatch diagnose``), ``plausible`` (each signal's
physical envelope), ``alerts`` (rule, STATUSTEXT), ``events`` (the guarded,
retried events file), ``blind`` (saying when the monitor cannot see),
``latency`` (fixed histogram), ``link`` (the MAVLink connection, signing,
allow-lists and everything we send), ``sdnotify`` (systemd), ``service`` (the
loop), ``cli`` (arguments, wiring).
"""
