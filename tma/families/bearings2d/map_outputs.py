"""Map outputs of a dataset without truth (an ingested log): per contact a PNG, and the
estimated target tracks as an MCAP that Foxglove's Map panel shows.

Both draw each track's estimated track from when its answer holds (``leg_start_s``) to its
last bearing: the trajectory the answer rests on where the estimator kept it (the side
table ``path``, ``estimated_path``: the smoothed path with its manoeuvres and its one-sigma
errors; ``lm`` and ``last_leg`` on a recording), its last point the answer now; else (an
estimator that assumes constant velocity, a track without a motion fit, an older run) the
straight line of the estimate theta = (x0, y0, vx, vy) (position at the dataset's t = 0 and
velocity; x east, y north, m) with covariance (J^T J)^-1 sigma^2, J^T J and sigma as the
estimator stored them (``jtj_ij``, ``sigma_used_deg``): the position at time t is
p(t) = p0 + v t, its covariance A(t) Sigma A(t)^T with A(t) = [I, t I]. The answer now's
covariance is always the latter (the report's). A 95 % ellipse is
{p : (p - p(t))^T C^-1 (p - p(t)) <= chi-square(2) 95 % point}.

- ``tables/<name>-<label>.png``: own-ship path, every k-th bearing line from own-ship, the
  estimated track (along a kept trajectory with the 95 % ellipses of a few of its
  positions) and the 95 % ellipse at its last bearing, in km east/north, the status in the
  title;
- ``tables/<name>.mcap`` (only with a geographic origin and UTC times): per track
  ``foxglove.LocationFix`` on ``/tma/estimate/<label>`` at each epoch of its estimated track
  (a kept trajectory's points, else its bearing epochs; estimated position, position
  covariance in ENU m^2, type KNOWN), own-ship on ``/ownship/location_fix``; log times
  UTC.

``<label>`` is the contact's shown label (``tma.sources.labels``: safe for file names,
Markdown and topics, long ones shortened with a hash); the table's CSV keeps the id as
written.
"""

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from tma.errors import InputError  # noqa: E402
from tma.families.bearings2d.log import (  # noqa: E402
    GEO,
    OWNSHIP_FIX_TOPIC,
    OWNSHIP_FRAME,
    BearingsLog,
    read_bearings_log,
)
from tma.families.bearings2d.status import HEADING_UNDETERMINED  # noqa: E402
from tma.io.mcap_log import Channel, LogWriter  # noqa: E402
from tma.io.mcap_values import json_record  # noqa: E402
from tma.io.mcap_writer import Encoded  # noqa: E402
from tma.maths.geo import (  # noqa: E402
    MAX_MAPPED_M,
    LocationFix,
    enu_covariance,
    local_to_geodetic,
    location_fix,
)
from tma.maths.linalg import scaled_inverse  # noqa: E402
from tma.report.tables import save_figure  # noqa: E402
from tma.sources.labels import file_part, fit_file_name, shown_labels  # noqa: E402

log = logging.getLogger(__name__)

CHI2_2_P95 = 5.991464547107979  # chi-square(2) 95 % point: the 95 % position ellipse
MAX_PLOTS = 100  # PNGs per table: a log of thousands of contacts gets the first 100
LISTED = 20  # contacts named in a message
BEARING_LINES = 40  # at most about this many bearing lines per plot (every k-th bearing)
ESTIMATE_TOPIC = "/tma/estimate/{label}"
THETA = ("x0_m", "y0_m", "vx_m_s", "vy_m_s")  # position at t = 0 and velocity (m, m/s)
NOMINAL_REACH_M = 20_000.0  # bearing lines of a contact without an estimate to reach
TRUTH_TOPIC = "/tma/truth/{label}"  # the contact's ship, from its AIS (ingest truth=FILE)


# -- covariance ------------------------------------------------------------------------------

def theta_covariance(estimates: pd.DataFrame) -> np.ndarray:
    """(n, 4, 4) covariance of theta = (x0, y0, vx, vy), (J^T J)^-1 sigma_used^2, from the
    run's ``jtj_ij`` (upper triangle) and ``sigma_used_deg``; inverted in the diagonally
    scaled form, as the estimators do. NaN where the estimator found J^T J singular (its
    one-sigma columns are blank there)."""
    n = len(estimates)
    jtj = np.empty((n, 4, 4))
    for i in range(4):
        for j in range(i, 4):
            jtj[:, i, j] = jtj[:, j, i] = estimates[f"jtj_{i}{j}"].to_numpy(float)
    usable = (np.isfinite(estimates["range_sd_m"].to_numpy(float))
              & np.isfinite(jtj).all(axis=(1, 2)))
    cov, _ = scaled_inverse(np.where(usable[:, None, None], jtj, np.eye(4)), 0.0)
    cov *= np.deg2rad(estimates["sigma_used_deg"].to_numpy(float))[:, None, None] ** 2
    cov[~usable] = np.nan
    return cov


def shown_estimates(report: pd.DataFrame, estimates: pd.DataFrame):
    """``(theta, theta_cov)`` of each track, ``(n, 4)`` and ``(n, 4, 4)``, as the report shows
    them: NaN where it shows no estimate (its range is blank: diverged, collapsed or without
    a one-sigma error, ``status.not_an_answer``), so that no plot or map draws one there."""
    theta = estimates[list(THETA)].to_numpy(float).copy()
    cov = theta_covariance(estimates)
    hidden = ~np.isfinite(report["range_now_m"].to_numpy(float))
    theta[hidden], cov[hidden] = np.nan, np.nan
    return theta, cov


def now_only(report: pd.DataFrame) -> np.ndarray:
    """Per track whether only its position now is drawn: where its status says where it is
    heading is not determined (``status.HEADING_UNDETERMINED``, ``position_only``), the line
    back from now along its velocity would draw a past the bearings do not give."""
    return report["status"].isin(HEADING_UNDETERMINED).to_numpy()


def position_covariance(theta_cov: np.ndarray, t_s) -> np.ndarray:
    """Covariance (m^2, east-north) of p(t) = p0 + v t: ``(n, 2, 2)`` for one time per track
    (``t_s`` shaped (n,)), ``(n, k, 2, 2)`` for ``t_s`` shaped (n, k)."""
    t = np.asarray(t_s, float)[..., None, None]
    c = theta_cov[:, None] if np.ndim(t_s) == 2 else theta_cov
    pp, pv, vv = c[..., :2, :2], c[..., :2, 2:], c[..., 2:, 2:]
    return pp + t * (pv + np.swapaxes(pv, -1, -2)) + t * t * vv


def path_rows(paths: pd.DataFrame | None) -> dict:
    """The side table ``path`` (``estimated_path``) by track id: ``{id: (t_s (k,), xy (k,
    2), cov (k, 2, 2))}``; empty without one (an older run, an estimator that keeps
    none)."""
    if paths is None or paths.empty:
        return {}
    out = {}
    for track_id, rows in paths.groupby("track_id", sort=False):
        sx, sy = rows["x_sd_m"].to_numpy(float), rows["y_sd_m"].to_numpy(float)
        xy = sx * sy * rows["xy_corr"].to_numpy(float)
        cov = np.stack([np.stack([sx * sx, xy], -1), np.stack([xy, sy * sy], -1)], -2)
        out[int(track_id)] = (rows["t_s"].to_numpy(float), rows[["x_m", "y_m"]].to_numpy(float),
                              cov)
    return out


def drawn_path(kept, theta, cov_now, t_from, t_now):
    """``(t_s, xy, cov)`` of a track's kept trajectory (a ``path_rows`` entry) from
    ``t_from`` on, its point at the last bearing ``t_now`` the answer now: ``theta``'s
    position then, with ``cov_now``, the report's (where the answer is a mixture over the
    manoeuvres, its most probable trajectory ends within its errors); None without a kept
    trajectory, or where ``theta`` is not finite (no estimate shown)."""
    if kept is None or not np.isfinite(theta).all():
        return None
    t, xy, cov = kept
    held = t >= t_from
    t, xy, cov = t[held], xy[held].copy(), cov[held].copy()
    if t.size == 0:
        return None
    if t[-1] == t_now:
        xy[-1] = theta[:2] + theta[2:] * t_now
        cov[-1] = cov_now
    return t, xy, cov


BAND_ELLIPSES = 6  # 95 % ellipses drawn along a kept trajectory (besides the one now)


def ellipse_points(center, cov, n=90) -> np.ndarray:
    """(n, 2) points of the 95 % ellipse of a 2x2 covariance around ``center``."""
    w, V = np.linalg.eigh(cov)
    s = np.linspace(0.0, 2 * np.pi, n)
    unit = np.stack([np.cos(s), np.sin(s)])
    return np.asarray(center) + (V @ (np.sqrt(np.maximum(w, 0) * CHI2_2_P95)[:, None] * unit)).T


# -- the dataset's logs ----------------------------------------------------------------------

def read_logs(dataset) -> list[BearingsLog]:
    """The bearing logs of every shard of ``dataset`` (each verified against the manifest)."""
    return [read_bearings_log(dataset.verified_path(rel)) for rel in dataset.shard_paths]


def reference(logs: list[BearingsLog], where: str):
    """``(epoch_utc_ns, origin_deg, labels)`` shared by the shards (labels: track id ->
    text, the id itself when unlabelled); InputError if the shards disagree."""
    epochs = {lg.epoch_utc_ns for lg in logs}
    origins = {None if lg.origin_deg is None else tuple(map(float, lg.origin_deg))
               for lg in logs}
    if len(epochs) > 1 or len(origins) > 1:
        raise InputError(f"{where}: the shards disagree on their UTC epoch or geographic "
                         "origin; ingest the log again")
    labels = {}
    for lg in logs:
        names = lg.track_label if lg.track_label is not None else lg.track_id.astype(str)
        labels.update(zip(lg.track_id.tolist(), map(str, names), strict=True))
    return next(iter(epochs), None), next(iter(origins), None), labels


# -- per contact PNG -------------------------------------------------------------------------

class _TrackPlots:
    """One figure, drawn again for each contact: its artists are made once and given each
    contact's data (a new figure and a tight layout per contact cost twice as much: the
    layout's text measuring, not the drawing, was most of it); the layout is fixed, with room
    for the axis labels and a two-line title."""

    def __init__(self):
        self.fig, ax = plt.subplots(figsize=(7, 7))
        self.ax = ax
        self.lines, = ax.plot([], [], color="0.6", lw=0.5)  # one line, NaN between segments
        self.own, = ax.plot([], [], color="tab:blue", label="own-ship")
        self.own_now, = ax.plot([], [], "o", color="tab:blue", ms=4)
        self.track, = ax.plot([], [], color="tab:red", label="estimated track")
        self.track_now, = ax.plot([], [], "o", color="tab:red", ms=4)
        self.ring, = ax.plot([], [], color="tab:red", lw=1, ls="--",
                             label="95 % position (last bearing)")
        self.band, = ax.plot([], [], color="tab:red", lw=0.6, ls=":",
                             label="along the track: 95 % positions")
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("east (km)")
        ax.set_ylabel("north (km)")
        ax.grid(True, alpha=0.3)
        self.fig.subplots_adjust(left=0.1, right=0.97, bottom=0.07, top=0.91)

    def draw(self, title: str, lg: BearingsLog, row: int, theta, cov_now, t_from=-np.inf,
             position_only=False, kept=None):
        """One contact: own-ship's whole path, every bearing's line, the estimated track
        from ``t_from`` (where its solution holds: ``leg_start_s``; ``last_leg`` solves a
        later leg) and its 95 % ellipse now (km); no track where ``theta`` is NaN (no
        estimate shown). The track is the trajectory the answer rests on where the estimator
        kept it (``kept``: a ``path_rows`` entry), with the 95 % ellipses of a few of its
        positions; else the straight line of ``theta``, of which a ``position_only`` track
        (``now_only``: where it is heading is not determined) draws the position now alone."""
        valid = np.flatnonzero(np.isfinite(lg.bearing_deg[row]))
        held = valid[lg.t_s[valid] >= t_from]  # the bearings the solution rests on
        held = held if held.size else valid
        own = np.column_stack([lg.own_x_m, lg.own_y_m])
        path = drawn_path(kept, theta, cov_now, lg.t_s[held[0]], lg.t_s[valid[-1]])
        band = np.empty((0, 2))
        if path is not None:  # the trajectory the answer rests on, to now
            t_path, track, covs = path
            seen_from = own[np.clip(np.searchsorted(lg.t_s, t_path), 0, lg.t_s.size - 1)]
            picks = np.unique(np.linspace(0, t_path.size - 1, BAND_ELLIPSES + 1).round()
                              .astype(int)[:-1])
            rings = [np.vstack([ellipse_points(track[k], covs[k]), [np.nan, np.nan]])
                     for k in picks if np.isfinite(covs[k]).all()]
            band = np.concatenate(rings) if rings else band
        else:
            held = held[-1:] if position_only else held
            track = theta[:2] + np.outer(lg.t_s[held], theta[2:])  # estimated positions then
            seen_from = own[held]
        finite = np.isfinite(track).all()
        reach = (np.hypot(*(track - seen_from).T).max() * 1.3 if finite
                 else NOMINAL_REACH_M)
        step = max(1, int(np.ceil(valid.size / BEARING_LINES)))
        b = np.deg2rad(lg.bearing_deg[row, valid[::step]])
        start = own[valid[::step]]
        end = start + reach * np.column_stack([np.sin(b), np.cos(b)])
        lines = np.stack([start, end, np.full_like(start, np.nan)], axis=1).reshape(-1, 2) / 1e3

        self.lines.set_data(lines.T)
        self.lines.set_label("bearings" + (f" (every {step}th)" if step > 1 else ""))
        self.own.set_data(own.T / 1e3)
        self.own_now.set_data(own[valid[-1], :, None] / 1e3)
        shown = [own]
        ring = np.empty((0, 2))
        if finite:
            shown.append(track)
            if np.isfinite(cov_now).all():
                ring = ellipse_points(track[-1], cov_now)
                shown.append(ring)
            if band.size:
                shown.append(band[np.isfinite(band).all(axis=1)])
        else:
            shown.append(end)
            band = np.empty((0, 2))
        self.track.set_data(track.T / 1e3 if finite else ([], []))
        if not position_only:
            self.track.set_label("estimated track")
        else:  # its track to now where kept, else its position now alone
            self.track.set_label("estimated track to now (heading not determined)"
                                 if path is not None else
                                 "estimated position now (heading not determined)")
        self.track.set_marker("o" if position_only and path is None else "None")
        self.track_now.set_data(track[-1, :, None] / 1e3 if finite else ([], []))
        self.ring.set_data(ring.T / 1e3)
        self.band.set_data(band.T / 1e3)
        box = np.concatenate(shown) / 1e3  # a square view of everything but the bearing lines
        lo, hi = box.min(axis=0), box.max(axis=0)
        mid, half = (lo + hi) / 2, 0.54 * (hi - lo).max() + 0.1
        self.ax.set_xlim(mid[0] - half, mid[0] + half)
        self.ax.set_ylim(mid[1] - half, mid[1] + half)
        drawn = [self.lines, self.own] + ([self.track] if finite else []) + (
            [self.ring] if ring.size else []) + ([self.band] if band.size else [])
        self.ax.legend(handles=drawn, loc="best", fontsize=8)
        self.ax.set_title(title, fontsize=10)
        return self.fig

    def close(self):
        plt.close(self.fig)


def write_track_plots(report: pd.DataFrame, estimates: pd.DataFrame, logs, tables_dir,
                      name: str, progress=None, paths: pd.DataFrame | None = None
                      ) -> list[Path]:
    """``<name>-<label>.png`` per contact (the first ``MAX_PLOTS``), titled with the time of
    its last bearing in UTC (the report's), or in seconds from the log's start when it is
    not dated; returns their paths. ``progress``: a progress bar (None: on a terminal
    only); ``paths``: the run's side table ``path``, if any (``path_rows``)."""
    theta, theta_cov = shown_estimates(report, estimates)
    kept = path_rows(paths)
    cov_now = position_covariance(theta_cov, estimates["t_last_s"].to_numpy(float))
    headless = now_only(report)
    where = {int(i): (lg, row) for lg in logs for row, i in enumerate(lg.track_id)}
    shown = shown_labels(report["label"])
    if len(report) > MAX_PLOTS:
        log.info("%s: plotting the first %d of %d contacts (MAX_PLOTS); the table and the map "
                 "MCAP hold them all", name, MAX_PLOTS, len(report))
    from tqdm.auto import tqdm  # here: a report without contacts to plot needs none

    paths, used = [], set()
    plots = _TrackPlots()
    try:
        for n, r in enumerate(tqdm(report.head(MAX_PLOTS).itertuples(index=False),
                                   total=min(len(report), MAX_PLOTS), desc=f"{name} plots",
                                   unit="contact", disable=None if progress is None
                                   else not progress)):
            lg, row = where[int(r.track_id)]
            part = file_part(shown[n])
            if part in used:  # two labels alike as file names: the id tells them apart
                part = f"{part}-{r.track_id}"
            used.add(part)
            path = Path(tables_dir) / fit_file_name(name, part, ".png")
            save_figure(plots.draw(plot_title(name, shown[n], r), lg, row, theta[n],
                                   cov_now[n], r.leg_start_s, headless[n],
                                   kept.get(int(r.track_id))), path)
            paths.append(path)
    finally:
        plots.close()
    return paths


def plot_title(name: str, shown: str, r) -> str:
    """A contact plot's title: the contact, its status and its kinematics now, at the UTC of
    its last bearing (or in seconds from the log's start when the report has none: a log
    that is not dated). ``r``: its report row; where it shows no estimate (blank range), the
    title says so and the report's note says why."""
    when = (r.time_now_utc if isinstance(r.time_now_utc, str)
            else f"t = {r.t_now_s:g} s from the start")
    if not np.isfinite(r.range_now_m):
        return (f"{name}: contact {shown}, status {r.status}\nno estimate shown (the table's "
                f"note says why), last bearing at {when}")
    if not np.isfinite(r.course_deg):  # position_only: where it is heading is not determined
        return (f"{name}: contact {shown}, status {r.status}\nrange {r.range_now_m / 1e3:.2f} "
                f"km, bearing {r.bearing_now_deg:.1f} deg, course and speed not determined at "
                f"{when}")
    return (f"{name}: contact {shown}, status {r.status}\nrange {r.range_now_m / 1e3:.2f} km, "
            f"course {r.course_deg:.1f} deg, speed {r.speed_m_s:.2f} m/s at {when}")


def contact_figure(report: pd.DataFrame, estimates: pd.DataFrame, logs, label,
                   name: str = "tma", paths: pd.DataFrame | None = None):
    """The matplotlib Figure of one contact's plot (as ``write_track_plots`` draws it),
    ``label`` its report label (or track id), ``paths`` the side table ``path`` if any;
    ValueError naming the contacts when there is no such contact, or when ``logs`` do not
    hold its bearings."""
    labels = report["label"].astype(str).to_numpy()
    match = np.flatnonzero(labels == str(label))
    if match.size == 0:
        listed = ", ".join(labels[:LISTED]) + (", ..." if labels.size > LISTED else "")
        raise ValueError(f"no contact {label!r} in these results; their contacts: {listed}")
    n = int(match[0])
    r = report.iloc[n]
    place = next(((lg, row) for lg in logs for row, i in enumerate(lg.track_id)
                  if int(i) == int(r.track_id)), None)
    if place is None:
        raise ValueError(f"contact {label!r} (track id {r.track_id}) is not in this recording: "
                         "pass the recording these results were estimated from")
    theta, theta_cov = shown_estimates(report.iloc[[n]], estimates.iloc[[n]])
    cov_now = position_covariance(theta_cov, estimates["t_last_s"].to_numpy(float)[[n]])[0]
    plots = _TrackPlots()
    return plots.draw(plot_title(name, shown_labels(report["label"])[n], r), *place,
                      theta[0], cov_now, r.leg_start_s, now_only(report.iloc[[n]])[0],
                      path_rows(paths).get(int(r.track_id)))


# -- the estimated tracks as an MCAP ---------------------------------------------------------

def write_map_mcap(path, report: pd.DataFrame, estimates: pd.DataFrame, logs, epoch_utc_ns,
                   origin_deg, run: dict, truth_track: pd.DataFrame | None = None,
                   paths: pd.DataFrame | None = None) -> Path:
    """Write the estimated tracks and own-ship as ``foxglove.LocationFix`` (see the module
    docstring), in time order; returns ``path``. Tracks whose estimate the report does not
    show (blank: ``shown_estimates``) or that lie beyond ``MAX_MAPPED_M`` of the origin are
    left out (logged). ``truth_track``: the contacts' ships from their AIS
    (``tma.ais.truth``), beside the estimates (``truth_parts``); ``paths``: the run's side
    table ``path``, if any (``path_rows``)."""
    theta, theta_cov = shown_estimates(report, estimates)
    headless = now_only(report)
    kept = path_rows(paths)
    where = {int(i): (k, row) for k, lg in enumerate(logs) for row, i in enumerate(lg.track_id)}
    own_topics = ([OWNSHIP_FIX_TOPIC] if len(logs) == 1
                  else [f"/ownship/{k}/location_fix" for k in range(len(logs))])
    channels = [Channel.protobuf(topic, LocationFix, {"frame": "own-ship, sea level"})
                for topic in own_topics]
    parts = []  # per topic: (t_s, lat, lon, covariance or None, frame_id)
    for lg in logs:
        lat, lon = local_to_geodetic(lg.own_x_m, lg.own_y_m, origin_deg)
        parts.append((lg.t_s, lat.tolist(), lon.tolist(), None, OWNSHIP_FRAME))
    skipped, used = [], set()
    shown = shown_labels(report["label"])
    for n, r in enumerate(report.itertuples(index=False)):
        k, row = where[int(r.track_id)]
        t = logs[k].t_s[np.isfinite(logs[k].bearing_deg[row])]
        held = t >= r.leg_start_s
        t = t[held] if held.any() else t  # where the solution holds (its leg)
        drawn = drawn_path(kept.get(int(r.track_id)), theta[n],
                           position_covariance(theta_cov[n:n + 1], t[-1:])[0], t[0], t[-1])
        if drawn is not None:  # the trajectory the answer rests on
            t, xy, cov = drawn
            x, y = xy.T
        else:
            t = t[-1:] if headless[n] else t  # its position now alone (now_only)
            x, y = (theta[n, :2, None] + theta[n, 2:, None] * t)
            cov = position_covariance(theta_cov[n:n + 1], t[None, :])[0]
        lat, lon = local_to_geodetic(x, y, origin_deg)
        if not np.isfinite(lat).all():  # no estimate shown, or one farther than a map
            skipped.append(shown[n])
            continue
        topic = ESTIMATE_TOPIC.format(label=shown[n])
        if topic in used:  # labels of different shards alike: the id tells them apart
            topic = f"{topic}-{r.track_id}"
        used.add(topic)
        cov = enu_covariance(cov) if np.isfinite(cov).all() else None
        if drawn is not None:
            what = ("the trajectory its answer rests on (smoothed, with its manoeuvres), from "
                    "leg_start_s to its last bearing" + (" (where it is heading now is not "
                                                         "determined)" if headless[n] else "")
                    + ", there its answer now; covariance: the trajectory's, at the last "
                    "bearing as in the report")
        elif headless[n]:
            what = ("its position at the last bearing alone (where it is heading is not "
                    "determined); covariance as in the report")
        else:
            what = ("the estimator's track over the bearings its solution rests on (from "
                    "leg_start_s); covariance as in the report")
        channels.append(Channel.protobuf(topic, LocationFix, {
            "track_id": str(r.track_id), "status": r.status, "estimate": what}))
        parts.append((t, lat.tolist(), lon.tolist(), cov, f"contact {shown[n]}"))
    if truth_track is not None:
        for channel, part in truth_parts(report, truth_track):
            channels.append(channel)
            parts.append(part)
    if skipped:
        log.warning("%s: no estimate shown (the table's note says why) or none within %g km "
                    "of the origin for %s: not in the map", path, MAX_MAPPED_M / 1e3,
                    ", ".join(skipped))
    t_all = np.concatenate([p[0] for p in parts])
    which = np.repeat(np.arange(len(parts)), [p[0].size for p in parts])
    order = np.lexsort((which, t_all))  # time order; own-ship first at equal times
    metadata = {GEO: json_record({"origin_lat_deg": origin_deg[0],
                                  "origin_lon_deg": origin_deg[1], "epoch_utc_ns": epoch_utc_ns}),
                "tma.run": json_record(run)}
    with LogWriter(path, channels, metadata, epoch_utc_ns=epoch_utc_ns) as w:
        payloads = [p for t, lat, lon, cov, frame in parts
                    for p in _fixes(w.log_times(t), frame, lat, lon, cov)]
        w.write_encoded([ch.topic for ch in channels], which[order], t_all[order],
                        Encoded.of([payloads[k] for k in order.tolist()]))
    return Path(path)


def _fixes(t_ns, frame: str, lat, lon, cov) -> list[bytes]:
    """``location_fix`` messages, serialised: one message whose changing fields are set anew
    for each (3x faster than a new message each, the same bytes)."""
    fix, out = location_fix(0, frame, 0.0, 0.0, None if cov is None else cov[0]), []
    for k, (ns, a, b) in enumerate(zip(t_ns.tolist(), lat, lon, strict=True)):
        fix.latitude, fix.longitude = a, b
        fix.timestamp.seconds, fix.timestamp.nanos = divmod(ns, 10**9)
        if cov is not None:
            fix.position_covariance[:] = cov[k]
        out.append(fix.SerializeToString(deterministic=True))
    return out


def truth_parts(report: pd.DataFrame, truth_track: pd.DataFrame) -> list:
    """``(channel, part)`` per contact with an AIS truth: its ship's position at each of its
    bearing times on ``/tma/truth/<label>`` (``foxglove.LocationFix``, no covariance), as
    ``write_map_mcap`` writes the estimates beside it."""
    shown = dict(zip(report["track_id"].tolist(), shown_labels(report["label"]), strict=True))
    mmsi = (dict(zip(report["track_id"].tolist(), report["truth_mmsi"].tolist(), strict=True))
            if "truth_mmsi" in report else {})
    out = []
    for track_id, rows in truth_track.groupby("track_id", sort=True):
        if track_id not in shown:
            continue
        label = shown[track_id]
        channel = Channel.protobuf(TRUTH_TOPIC.format(label=label), LocationFix, {
            "track_id": str(track_id), "mmsi": str(mmsi.get(track_id, "")),
            "truth": "the contact's ship from its AIS, interpolated at its bearing times"})
        out.append((channel, (rows["t_s"].to_numpy(float), rows["lat_deg"].tolist(),
                              rows["lon_deg"].tolist(), None, f"AIS {mmsi.get(track_id, '')}"
                              f" (contact {label})")))
    return out
