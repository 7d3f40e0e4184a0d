"""``tma.estimate``: an estimator over a recording or dataset of any family, through the code
``pipeline.estimate`` runs, and the family's results of it."""

from dataclasses import dataclass

import pandas as pd

from tma.api.datasets import _data, _sources
from tma.api.options import _plain
from tma.api.results import Results
from tma.errors import ConfigError


@dataclass(frozen=True)
class Estimated:
    """An estimate in memory, what a family's ``aggregate.results`` hook turns into the results
    of ``tma.estimate``: ``estimator`` (built, with its ``config``), ``estimates`` (its
    table over every log: a row per track, or per track and step), ``side_tables`` (name ->
    DataFrame, those it declares), the ``logs``, ``recorded`` (a recording, not a
    simulation), ``truth`` (a simulation's, or the AIS truth of a recording; None without),
    ``truth_track`` (a recording's ships from their AIS, or None) and ``scenario`` (the
    simulated scenario's config as plain values; None for a recording)."""

    family: str
    estimator: object
    estimates: pd.DataFrame
    side_tables: dict
    logs: list
    recorded: bool
    truth: pd.DataFrame | None
    truth_track: pd.DataFrame | None
    scenario: dict | None


def _estimator_for(family_name: str, estimator, recorded: bool, options: dict):
    """The estimator ``estimator`` (None: the family's first) built from ``options`` as the
    command line builds it (on a recording, its ``recorded_defaults`` first); ValueError for
    one of another family or one that trains an artefact first."""
    from tma.estimator import Estimator, name_set_error
    from tma.families import build_estimator, estimator_class, estimator_names, family

    if "name" in options:  # as the command line's estimator.name= (tma.experiment)
        raise name_set_error(f"name={options['name']!r}", repr(options["name"]))
    known = list(family(family_name).estimators)
    name = known[0] if estimator is None else estimator
    if not isinstance(name, str):
        raise TypeError(f"estimator must be an estimator's name (a str: {', '.join(known)}), "
                        f"got {type(name).__name__}")
    if name not in estimator_names():
        raise ConfigError(f"unknown estimator {name!r}: {family_name}'s are "
                          f"{', '.join(known)}")
    cls = estimator_class(name)
    if cls.family != family_name:
        raise ConfigError(f"estimator {name!r} reads {cls.family} logs, these are "
                          f"{family_name}'s: choose one of {', '.join(known)}")
    if cls.prepare.__func__ is not Estimator.prepare.__func__:  # trains an artefact first
        runs_here = [k for k in known if family(family_name).estimator_class(k).prepare
                     .__func__ is Estimator.prepare.__func__]
        raise ConfigError(f"estimator {name!r} trains an artefact under data/artefacts before "
                          "it runs, which tma.estimate does not write: run it with python -m "
                          f"pipeline.table scenario={family_name} estimator={name} "
                          "[scenario.KEY=VALUE ...] (then tma.runs reads its metrics), or "
                          f"choose one of {', '.join(runs_here)}")
    node = {"name": name, **(cls.recorded_defaults if recorded else {}), **options}
    return build_estimator(node)


def estimate(data, estimator: str | None = None, sigma_deg: float | None = None,
             **options) -> pd.DataFrame:
    """Estimate every track of ``data`` (a ``Recording``, a DataFrame as
    ``Recording.from_frames`` reads it, or a dataset of ``simulate``/``open_dataset``, of any
    family) with ``estimator`` (default: its family's first, ``lm`` for bearings) and its
    ``options`` (``max_iter=50``, ``accel_psd_m2_s3=0``: the keys of ``python -m tma.options
    <estimator>``); ``sigma_deg``: the bearings' nominal noise, for logs that have one
    (default: the log's, else estimated).

    Returns one row per track, the family's results (its aggregate module's ``results``):
    ``bearings2d`` the per-contact report ``pipeline.aggregate`` writes (label, time_now_utc,
    range/bearing/course/speed now with their one-sigma errors, x/y and lat/lon now, status
    and note, sqrt_ka_deg, fit and trend-test p-values, leg_start_s/_utc...), with a
    recording's AIS (``truth=``) the truth, errors, z-scores and ``covered``, with a
    simulation's truth its metrics; ``radar2d``, ``ranges2d``, ``bearing_doppler3d`` each
    track's state at its end and status, with its errors against the truth. An estimate that
    is no answer is blank, with its status and a note. The estimator's own columns (what
    ``plot_contact`` and ``write_map`` draw from) are ``results.tma.estimates``."""
    from tma.families import family
    from tma.stages.estimate import estimate_log

    if "truth" in options:  # the AIS of a log: read with it, as read_log reads a file
        if not isinstance(data, pd.DataFrame):
            raise TypeError("estimate(truth=...) scores a DataFrame read with its AIS; a file "
                            "is read with it by tma.read_log(path, truth=...), a Recording "
                            "by Recording.from_frames(..., truth=...)")
        from tma.api.recording import Recording

        data = Recording.from_frames(data, truth=options.pop("truth"),
                                     options=options.pop("options", None))
    data = _data(data, "estimate")
    _plain({"sigma_deg": sigma_deg, **options}, "estimate")
    fam = family(data.family)
    est = _estimator_for(fam.name, estimator, data.recorded, options)
    logs = list(data.logs)
    if sigma_deg is not None:
        logs = _with_sigma(logs, sigma_deg, fam.name)
    tables, sides = [], {}
    for lg in logs:
        table, side_tables, _ = estimate_log(est, lg)
        tables.append(table.to_pandas())
        for name, side in side_tables.items():
            sides.setdefault(name, []).append(pd.DataFrame(side))
    estimates = pd.concat(tables, ignore_index=True)
    truth, truth_track, scenario = _sources(data)
    report, held = fam.aggregate.results(Estimated(
        fam.name, est, estimates, {k: pd.concat(v, ignore_index=True) for k, v in sides.items()},
        logs, data.recorded, truth, truth_track, scenario))
    report.attrs["tma"] = Results(fam.name, est.name, report.copy(), held)
    return report


def _with_sigma(logs, sigma_deg, family_name: str) -> list:
    """``logs`` with the bearings' nominal noise ``sigma_deg`` (checked as ingest's)."""
    from dataclasses import replace

    from tma.families import family

    if not hasattr(logs[0], "sigma_deg"):
        raise ConfigError(f"sigma_deg is the bearing noise of a bearing log; a {family_name} "
                          f"dataset's noise is its scenario's: tma.simulate({family_name!r}, "
                          "...) sets it (python -m tma.options "
                          f"{family_name} lists its keys)")
    family(family_name).ingest.Settings(sigma_deg=sigma_deg)  # ingest's sigma_deg= check
    return [replace(lg, sigma_deg=float(sigma_deg)) for lg in logs]
