"""tma: batch target motion analysis and passive tracking.

Angles are degrees in configs, logs and tables and radians inside the code; bearings and
courses are measured clockwise from north (x east, y north, metres, seconds) unless a
scenario family documents otherwise.

From Python (``docs/api.md``): ``tma.read_log``, ``tma.Recording.from_frames``,
``tma.estimate``, ``tma.plot_contact``, ``tma.write_map``, ``tma.open_dataset``,
``tma.runs``, ``tma.runs_dataset``, ``tma.simulate`` and ``tma.campaign`` (``tma.api``),
loaded when first used so that ``import tma`` stays light.
"""

from tma.version import __version__

API = ("Recording", "read_log", "estimate", "plot_contact", "write_map", "open_dataset",
       "runs", "runs_dataset", "simulate", "campaign")
__all__ = [*API, "__version__"]


def __getattr__(name: str):
    if name in API:
        from tma import api

        return getattr(api, name)
    raise AttributeError(f"module 'tma' has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *API])
