"""Exceptions that carry a message meant for the user, not a traceback."""


class TmaError(Exception):
    """Base class: the pipeline prints these as one clear line and exits non-zero."""


class ConfigError(TmaError):
    """A configuration value is unknown, of the wrong type or out of range."""


class InputError(TmaError):
    """An input file (CSV, MCAP, dataset) is malformed or inconsistent."""


class IntegrityError(InputError):
    """A file does not match the hash recorded in its manifest."""
