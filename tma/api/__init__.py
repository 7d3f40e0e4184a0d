"""tma from Python: recorded logs and simulations in, pandas DataFrames out, through the same
code the commands run (``docs/api.md``).

- ``read_log(path, **options)`` reads a recorded log as ``python -m pipeline.ingest`` does
  (``tma.ingest.read_log``) into a ``Recording``; ``Recording.from_frames(bearings,
  navigation=None, **options)`` reads pandas DataFrames through the same CSV reader.
- ``estimate(data, estimator=None, sigma_deg=None, **options)`` runs an estimator over a
  recording or a simulated or stored dataset of any family as ``pipeline.estimate`` does
  (``Estimator.estimate`` on each log) and returns one row per track: the family's per-track
  results (its aggregate module's ``results`` hook), while the estimator's own columns, which
  ``plot_contact`` and ``write_map`` draw from, stay in ``results.tma`` (``Results``).
- ``campaign(input, truth=None, **options)`` scores every log of a folder or a glob against
  its AIS and pools the verdicts (``tma.ais.campaign``) as ``pipeline.table input=DIR`` does.
- ``plot_contact`` and ``write_map`` draw and write what aggregate draws and writes, for the
  families whose aggregate module has those hooks.
- ``open_dataset``, ``runs``, ``runs_dataset`` and ``simulate`` read stored datasets and
  runs, and simulate in memory what ``pipeline.simulate`` would store.

Options are ingest's and an estimator's, named as on the command line: as keyword arguments
by their group (``columns={"time": "tid"}``, ``bearing={"units": "rad"}``) or in a dict of
dotted names (``options={"columns.time": "tid"}``). Recorded logs are those of the family
that reads them (the one with an ``ingest`` module: ``bearings2d``).

Every error is one line of the kind pandas users catch: ``ValueError`` (``tma.errors``),
``TypeError`` for an argument of the wrong kind, ``FileNotFoundError`` for no such file, and
for a map that cannot be written the ``OSError`` the system gave.
"""

from tma.api.campaign import campaign
from tma.api.datasets import (
    SimulatedDataset,
    StoredDataset,
    open_dataset,
    runs,
    runs_dataset,
    simulate,
)
from tma.api.estimate import Estimated, estimate
from tma.api.recording import Recording, read_log
from tma.api.results import Results, ResultsAccessor, plot_contact, write_map

__all__ = ["Estimated", "Recording", "Results", "ResultsAccessor", "SimulatedDataset",
           "StoredDataset", "campaign", "estimate", "open_dataset", "plot_contact", "read_log",
           "runs", "runs_dataset", "simulate", "write_map"]
