"""The onboard monitor daemon (``propwatch monitor``, ``python -m monitor``).

One job per module: ``config`` (the frozen settings), ``resampler`` (streaming
zero-order hold onto the boot-clock grid), ``pipeline`` (messages -> classified
steps; also used by ``propwatch diagnose``), ``alerts`` (rule, STATUSTEXT,
events file), ``link`` (the MAVLink connection and everything we send),
``sdnotify`` (systemd), ``service`` (the loop), ``cli`` (arguments, wiring).
"""
