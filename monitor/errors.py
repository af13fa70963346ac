"""Exceptions shared by the onboard and offline sides.

Library code raises these with the offending file, field or message in the
text; only the command-line layer turns them into an exit code.
"""


class PropwatchError(Exception):
    """Base class for every error propwatch reports to a user."""


class ConfigError(PropwatchError):
    """A YAML or dataclass config is malformed: unknown, missing or non-physical key."""


class ModelError(PropwatchError):
    """A model file is missing, unreadable or does not fit the data it is given."""


class LogFormatError(PropwatchError):
    """A flight log cannot be read, or lacks a stream that is needed."""
