"""Test-wide settings.

The daemon's vehicle memory defaults to /var/lib/propwatch (or $PROPWATCH_STATE_DIR): tests never learn into the
machine's own state dir. Set empty here, a daemon started by a test has no vehicle memory unless the test gives it
one (``--state-dir`` in a temporary folder).
"""

import os

os.environ["PROPWATCH_STATE_DIR"] = ""
