"""tma's version: recorded in every manifest and log, and part of every run's key. Written
here once; ``pyproject.toml`` reads it (``[tool.setuptools.dynamic]``), so the installed
package's metadata says the same without every command importing ``importlib.metadata``
(0.02-0.07 s of each start-up)."""

__version__ = "0.6.0"
