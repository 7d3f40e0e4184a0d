"""Exceptions that carry a message meant for the user, not a traceback.

Each is of the built-in kind a pandas or scikit-learn user already catches: a bad value,
option or input is a ``ValueError`` (``except ValueError`` catches every ``TmaError``), a
missing input file also a ``FileNotFoundError``. The commands print any of them as one
``error:`` line (``pipeline._common.guarded``)."""


class TmaError(ValueError):
    """Base class: the pipeline prints these as one clear line and exits non-zero."""


class ConfigError(TmaError):
    """A configuration value is unknown, of the wrong type or out of range."""


class InputError(TmaError):
    """An input file (CSV, MCAP, dataset) is malformed or inconsistent."""


class IntegrityError(InputError):
    """A file does not match the hash recorded in its manifest."""


class MissingFileError(InputError, FileNotFoundError):
    """An input file that does not exist (``except FileNotFoundError`` catches it too)."""


class ConfigTypeError(ConfigError, TypeError):
    """A configuration value of the wrong type (``except TypeError`` catches it too)."""


class Interrupted(Exception):
    """The work stopped before its end (a worker process that died, a signal): what was
    finished is kept (each shard is written whole or not at all), nothing complete was
    replaced, and the same command again resumes. ``status``: the command's exit status."""

    def __init__(self, message: str, status: int = 2):
        super().__init__(message)
        self.status = status
