"""The onboard monitor daemon (``propwatch monitor``, ``python -m monitor``).

One job per module:

* ``cli``: arguments and wiring; ``keygen``: ``propwatch keygen``, a signing key.
* ``service``: the loop; ``Daemon.handle`` takes each message through watch -> pipeline -> decide -> announce.
* ``autopilot``: the autopilot as the daemon sees it (identity, stream rates, arming, heartbeats, version, acks).
* ``pipeline``: messages -> classified grid steps (``clockguard``: the boot clock; ``resampler``: the streaming
  zero-order hold onto the grid; ``plausible``: each signal's physical envelope; ``pacing``: when to read next).
* ``decide``: a grid step through the pause, the judges and blindness (``rotor_evidence``: the moment balance;
  ``memory_adapter``: the vehicle's memory, ``monitor.memory``) to the announcer.
* ``announce``: STATUSTEXT, the events file, systemd's STATUS and latency (``alerts``: the STATUSTEXT queue and rate
  limiter; ``events``: the guarded, retried events file; ``sdnotify``: systemd; ``latency``: a fixed histogram).
* ``blind``: saying when the monitor cannot see.
* ``link``: the MAVLink connection and everything we send (``signing``: MAVLink 2 signatures; ``pin``: which
  autopilot is listened to).
* ``config``: the frozen settings.
"""
