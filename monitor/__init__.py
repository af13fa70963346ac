"""propwatch onboard side: numpy, pymavlink and onnxruntime only (never torch or offline)."""

from __future__ import annotations


def version() -> str:
    """The installed distribution's version (pyproject.toml's), or the checkout's when not installed."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("propwatch")
    except PackageNotFoundError:
        return __version__


__version__ = "0.1.0"  # kept equal to pyproject.toml's version (tests/test_cli_basics.py checks)
