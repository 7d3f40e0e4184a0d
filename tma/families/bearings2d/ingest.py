"""What ``bearings2d`` reads from a recorded log, and the logs it makes of it.

The readers and the stage are the core's (``tma.sources``, ``tma.stages.ingest``); this family
declares its observation, the bearing (``OBSERVATION``: degrees clockwise from north or
radians, a direction vector as ``atan2(x, y)``, tma's own ``tma.BearingBatch`` on
``/sonar/bearings``), guards it against radians read as degrees (``radians_guard``), checks
its settings (``Settings``: ``sigma_deg``, ``min_bearings``) and puts each own-ship's bearings
on one epoch grid shared by its tracks (``logs``): a ``BearingsLog`` per own-ship, NaN where a
track has no bearing at an epoch, with the nominal noise an MCAP log declares (``tma.sensor``)
or ``sigma_deg``.
"""

import logging
from dataclasses import dataclass

import numpy as np

from tma.config import Params, param
from tma.errors import InputError
from tma.families.bearings2d.log import BEARINGS_TOPIC, SCHEMAS, BearingsLog, nominal_sigma
from tma.io.track_epochs import epochs, scatter
from tma.maths.geo import check_mapped
from tma.sources.base import Observation, Unit
from tma.utc import MAX_SPAN_S

log = logging.getLogger(__name__)
MAX_CELLS = 1 << 26  # bearings grid cells (tracks x epochs) per log: 512 MiB of float64
RADIANS_MIN_COUNT = 10


def _from_vector(x, y):
    return np.where((x == 0) & (y == 0), np.nan, np.rad2deg(np.arctan2(x, y)) % 360)


def radians_guard(recordings, options, where):
    """Refuse bearings of unstated units that all lie within +-2 pi: radians read as degrees
    fit a far, slow target with a tiny residual, and no statistic can tell it afterwards."""
    if options.bearing.units is not None or any(r.contacts.units_stated for r in recordings):
        return
    b = np.concatenate([r.contacts.values for r in recordings])
    if b.size >= RADIANS_MIN_COUNT and np.all(np.abs(b) <= 2 * np.pi):
        raise InputError(f"{where}: every bearing lies within +-2 pi ({b.min():.3g} to "
                         f"{b.max():.3g}): they look like radians. Set bearing.units=rad to "
                         "convert them, or bearing.units=deg if they really are degrees")


OBSERVATION = Observation(
    role="bearing", plural="bearings", column="bearing_deg",
    columns=("bearing_deg", "bearing_rad", "bearing", "brg", "brg_deg", "brg_rad",
             "true_bearing_deg", "azimuth_deg", "azimuth_rad", "azimuth"),
    fields=("bearing_deg", "bearing_rad", "bearing", "data", "vector"),
    units=(Unit("deg", "degrees", ("deg", "degree", "degrees"), lambda v: v, 360,
                "[-360, 360]"),
           Unit("rad", "radians", ("rad", "radian", "radians"), np.rad2deg, 2 * np.pi,
                "[-2 pi, 2 pi]")),
    from_vector=_from_vector, vector_rule="atan2(x, y)",
    topic=BEARINGS_TOPIC, schema=SCHEMAS[BEARINGS_TOPIC], guard=radians_guard, direction=True)


@dataclass
class Settings(Params):
    """The family's own ingest settings (given as they come from the command line; their
    types and values checked as declared: ``Params``)."""

    sigma_deg: float | None = param(None, "nominal bearing noise (deg) for covariances, over "
                                    "what an MCAP log declares; null: the log's, else "
                                    "estimated from the residuals; at least 0.001 deg, "
                                    "finer than any bearing sensor, the least noise the "
                                    "motion fit assumes (ncv.MIN_SIGMA_RAD)", "[0.001, 90)")
    min_bearings: int = param(5, "bearings each track needs (4 unknowns and one degree of "
                              "freedom for the noise)", "[5, inf)")

    @property
    def where(self) -> str:
        return "ingest"


def _enough_bearings(aligned, settings: Settings, where: str) -> dict:
    """Leave out the contacts with fewer than ``min_bearings`` bearings kept (``bad_rows=
    drop``; under ``fail`` refuse the file, as a contact with too few bearings always was);
    what the manifest records of them (``skipped_contacts``)."""
    ids = np.concatenate([p.track_id for p in aligned.platforms])
    known, counts = np.unique(ids, return_counts=True)
    few = counts < settings.min_bearings
    if not few.any():
        return {"min_bearings": settings.min_bearings, "count": 0, "contacts": {}}
    names = known.astype(str) if aligned.labels is None else aligned.labels[known]
    shown = {str(n): int(c) for n, c in zip(names[few], counts[few], strict=True)}
    listed = ", ".join(f"{n} ({c})" for n, c in list(shown.items())[:10])
    if aligned.dropped.policy == "fail":
        raise InputError(f"{where}: track(s) {', '.join(list(shown)[:10])} have "
                         f"{counts[few].min()} bearing(s); estimating 4 parameters (x0, y0, vx, "
                         f"vy) needs at least {settings.min_bearings} (min_bearings); "
                         "bad_rows=drop skips such contacts")
    if few.all():
        raise InputError(f"{where}: no contact has min_bearings = {settings.min_bearings} "
                         f"bearings: {listed}")
    for p in aligned.platforms:
        keep = ~np.isin(p.track_id, known[few])
        p.t_s, p.own_x_m, p.own_y_m, p.track_id, p.values = (
            p.t_s[keep], p.own_x_m[keep], p.own_y_m[keep], p.track_id[keep], p.values[keep])
    aligned.platforms = [p for p in aligned.platforms if p.t_s.size]
    log.warning("%s: skipped %d contact(s) with fewer than min_bearings = %d bearings: %s",
                where, int(few.sum()), settings.min_bearings, listed)
    return {"min_bearings": settings.min_bearings, "count": int(few.sum()), "contacts": shown}


def logs(aligned, settings: Settings, where: str):
    """``(logs, config, extra)``: one ``BearingsLog`` per own-ship of ``aligned``
    (``tma.sources.align``), checked; what the dataset's config and manifest record of the
    settings and of the contacts skipped for too few bearings."""
    skipped = _enough_bearings(aligned, settings, where)
    named = [p.recording.platform for p in aligned.platforms]
    if len(named) > 1 and None not in named:  # several platforms: one track per contact
        ps = aligned.platforms
        platform = np.concatenate([np.full(p.t_s.size, k, np.int64) for k, p in enumerate(ps)])
        out = _logs(*(np.concatenate([getattr(p, a) for p in ps])
                      for a in ("t_s", "own_x_m", "own_y_m", "track_id", "values")),
                    nominal_sigma(ps[0].recording.metadata, where), where, platform=platform,
                    names=tuple(named))
    else:
        out = []
        for p in aligned.platforms:
            sigma = nominal_sigma(p.recording.metadata, where)  # the input's tma.sensor
            out += _logs(p.t_s, p.own_x_m, p.own_y_m, p.track_id, p.values, sigma, where)
    for lg in out:
        lg.epoch_utc_ns = aligned.epoch_utc_ns
        lg.origin_deg = aligned.origin_deg
        if aligned.labels is not None:
            lg.track_label = aligned.labels[lg.track_id]
    all_ids = np.concatenate([lg.track_id for lg in out])
    if np.unique(all_ids).size != all_ids.size:
        raise InputError(f"{where}: a track id appears with two different own-ship paths")
    for lg in out:
        if settings.sigma_deg is not None:  # the option overrides what an MCAP log may declare
            lg.sigma_deg = float(settings.sigma_deg)
        if lg.t_s[-1] > MAX_SPAN_S:
            raise InputError(f"{where}: the log spans {lg.t_s[-1]:.3g} s (at most "
                             f"{MAX_SPAN_S:.3g} s): times must be seconds")
        lg.validate(where)
        if lg.origin_deg is not None:  # before anything is written, naming the input
            check_mapped(lg.own_x_m, lg.own_y_m, lg.t_s, where)
    labels = aligned.summary["track_labels"]
    if labels is not None and skipped["count"]:  # the skipped contacts are not in the dataset
        kept = {str(i) for lg in out for i in lg.track_id}
        labels = {i: s for i, s in labels.items() if i in kept}
    return out, {"min_bearings": settings.min_bearings}, {
        "sigma_deg": out[0].sigma_deg, "skipped_contacts": skipped, "track_labels": labels}


def _logs(t, x, y, track, bearing, sigma, where, platform=None, names=None
          ) -> list[BearingsLog]:
    """One own-ship's bearings on its epoch grid (several platforms: ``platform``, each
    value's index into ``names``, on one grid of (time, platform) epochs); tracks split into
    several logs only when the grid (tracks x epochs) would exceed MAX_CELLS."""
    ids, counts = np.unique(track, return_counts=True)
    n_epochs = epochs(t, platform)[0].size  # (distinct times, or (time, platform) pairs)
    if ids.size * n_epochs <= MAX_CELLS:
        groups = [ids]
    else:  # bound each group's grid by (tracks in it) x (its bearings)
        groups, start, total = [], 0, 0
        for k, c in enumerate(counts):
            if k > start and (k - start + 1) * (total + c) > MAX_CELLS:
                groups.append(ids[start:k])
                start, total = k, 0
            total += c
        groups.append(ids[start:])
    logs = []
    for group in groups:
        rows = np.isin(track, group) if len(groups) > 1 else slice(None)
        logs.append(_grid(t[rows], x[rows], y[rows], track[rows], bearing[rows], group, sigma,
                          where, None if platform is None else platform[rows], names))
    return logs


def _grid(t, x, y, track, bearing, ids, sigma, where, platform=None, names=None
          ) -> BearingsLog:
    """The (tracks x epochs) bearing array; own-ship at each epoch (equal at equal times).
    Several platforms: an epoch per distinct (time, platform), ordered by time then
    platform, each at its platform's position."""
    t_s, col, first = epochs(t, platform)
    _, grid = scatter(track, col, bearing, t_s.size, where, "bearings", t_s.__getitem__,
                      track_id=ids)
    return BearingsLog(t_s=t_s, own_x_m=x[first], own_y_m=y[first], track_id=ids,
                       bearing_deg=grid, sigma_deg=sigma,
                       platform=None if platform is None else platform[first],
                       platforms=None if platform is None else names)


def contacts(logs: list[BearingsLog]):
    """Each track of ``logs`` as a ``tma.ais.match.Contact`` (its bearings, own-ship there,
    its label and the log's nominal sigma): what ``ingest truth=FILE`` matches to the AIS."""
    from tma.ais.match import Contact

    out = []
    for lg in logs:
        labels = lg.track_label if lg.track_label is not None else lg.track_id.astype(str)
        for row, track in enumerate(lg.track_id.tolist()):
            have = np.isfinite(lg.bearing_deg[row])
            out.append(Contact(int(track), str(labels[row]), lg.t_s[have], lg.own_x_m[have],
                               lg.own_y_m[have], lg.bearing_deg[row, have], lg.sigma_deg))
    return out
