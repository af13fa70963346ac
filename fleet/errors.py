"""Errors of the fleet tools (a ``PropwatchError``: the CLI prints them and exits 2)."""

from monitor.errors import PropwatchError


class FleetError(PropwatchError):
    """A fleet database, cluster address or argument is unusable; the text names it."""


def need(module: str):
    """Import an optional dependency of the ``fleet`` extra, or say how to install it."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise FleetError(f"propwatch fleet needs {module} (pip install 'propwatch[fleet]'): {exc}") from exc
