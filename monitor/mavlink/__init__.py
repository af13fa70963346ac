"""MAVLink: the codecs shared by the daemon and the tlog reader, and the ``propwatch replay`` log player.

* ``decode``: one pymavlink message -> typed samples on the autopilot's boot clock (``MavlinkDecoder``).
* ``esc``: ESC_STATUS (message 291), absent from pymavlink's bundled dialects, encoded and decoded from its definition.
* ``player``: ``propwatch replay``, a .tlog played back as if it were PX4.
"""
