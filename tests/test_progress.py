"""Progress bars: shown with a rate and ETA on a terminal, silent in pipes and tests."""

from __future__ import annotations

import io

from monitor import progress


def test_silent_when_stderr_is_not_a_terminal(monkeypatch):
    monkeypatch.setattr("sys.stderr", io.StringIO())
    assert not progress.interactive()
    b = progress.bar(10, "flight", "x")
    b.update(3)
    b.close()  # the stand-in accepts the same calls


def test_bar_on_a_terminal_has_unit_and_eta(monkeypatch):
    class Tty(io.StringIO):
        def isatty(self):
            return True

    err = Tty()
    monkeypatch.setattr("sys.stderr", err)
    assert progress.interactive()
    b = progress.bar(4, "flight", "simulate", file=err, mininterval=0)
    b.update(1)
    b.update(1)
    text = err.getvalue()
    b.close()
    assert "simulate" in text and "2/4" in text and "flight/s" in text and "<" in text  # elapsed<remaining
