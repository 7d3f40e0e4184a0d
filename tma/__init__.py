"""tma: batch target motion analysis and passive tracking.

Angles are degrees in configs, logs and tables and radians inside the code; bearings and
courses are measured clockwise from north (x east, y north, metres, seconds) unless a
scenario family documents otherwise.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("tma")
except PackageNotFoundError:  # running from a checkout without installation
    __version__ = "0.0.0+checkout"
