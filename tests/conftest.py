"""Test-wide settings.

The daemon's vehicle memory defaults to /var/lib/propwatch (or $PROPWATCH_STATE_DIR): tests never learn into the
machine's own state dir. Set empty here, a daemon started by a test has no vehicle memory unless the test gives it
one (``--state-dir`` in a temporary folder).
"""

import os

os.environ["PROPWATCH_STATE_DIR"] = ""


def pytest_collection_finish(session):
    """The evalsim flights the selected tests declared are flown together, once (tests/evalsim_flights.py)."""
    from evalsim_flights import note_selected

    note_selected(session.items)
