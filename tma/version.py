"""tma's version (the installed package's; ``0.0.0+checkout`` in a checkout not installed):
recorded in every manifest and log, and part of every run's key."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("tma")
except PackageNotFoundError:  # running from a checkout without installation
    __version__ = "0.0.0+checkout"
