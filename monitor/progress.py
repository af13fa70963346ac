"""Progress bars with an ETA on a terminal, silence elsewhere (pipes, CI, tests).

tqdm is optional for the onboard side (``pip install 'propwatch[logs]'`` or
``[offline]`` brings it); without it, or when stderr is not a terminal, the
bar is a do-nothing object and callers keep their plain log lines.
"""

from __future__ import annotations

import sys


class _Silent:
    def update(self, n: float = 1) -> None:
        pass

    def set_postfix_str(self, s: str) -> None:
        pass

    def close(self) -> None:
        pass


def interactive() -> bool:
    """True when a bar would be seen: stderr is a terminal and tqdm is installed (imported only then: ~40 ms)."""
    if not sys.stderr.isatty():
        return False
    try:
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return True


def bar(total: float, unit: str, desc: str, **kw):
    """A tqdm bar on stderr (rate and ETA in ``unit``) when ``interactive()``, else a silent stand-in."""
    if not interactive():
        return _Silent()
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=desc, leave=False, dynamic_ncols=True, **kw)
