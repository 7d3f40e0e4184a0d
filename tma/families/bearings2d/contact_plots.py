"""The per-contact plots of a dataset without truth (an ingested log), what it draws as
``drawn_tracks`` says: ``tables/<name>-<label>.png``: own-ship path, every k-th bearing line
from own-ship, the estimated track (along a kept trajectory with the 95 % ellipses of a few of
its positions) and the 95 % ellipse at its last bearing, in km east/north, the status in the
title. A log of several platforms draws each platform's track in its colour (one that never
moved as a triangle), named, and each one's bearing lines from it in that colour.

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

from tma.families.bearings2d.drawn_tracks import (  # noqa: E402
    BAND_ELLIPSES,
    NOMINAL_REACH_M,
    drawn_bearings,
    drawn_path,
    ellipse_points,
    is_fixed,
    now_only,
    path_rows,
    platform_colour,
    platform_epochs,
    platform_now,
    position_covariance,
    shown_estimates,
    sight_ends,
    sight_reach,
)
from tma.families.bearings2d.log import BearingsLog  # noqa: E402
from tma.sources.labels import file_part, fit_file_name, shown_labels  # noqa: E402
from tma.tables.write import save_figure  # noqa: E402

log = logging.getLogger(__name__)

MAX_PLOTS = 100  # PNGs per table: a log of thousands of contacts gets the first 100
LISTED = 20  # contacts named in a message


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
        self.platforms = []  # per platform of a log of several: (path, now, lines), as needed
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
        several = lg.platform is not None
        if several:  # each platform's lines of sight from it, in its colour
            platform_handles, end = self._draw_platforms(lg, row, valid, track)
            for artist in (self.lines, self.own, self.own_now):
                artist.set_data([], [])
        else:
            reach = (np.hypot(*(track - seen_from).T).max() * 1.3 if finite
                     else NOMINAL_REACH_M)
            ((_, drawn_at, step),) = drawn_bearings(lg, valid)
            start, end = sight_ends(lg, row, drawn_at, reach)
            self.lines.set_data(_segments(start, end).T)
            self.lines.set_label("bearings" + (f" (every {step}th)" if step > 1 else ""))
            self.own.set_data(own.T / 1e3)
            self.own_now.set_data(own[valid[-1], :, None] / 1e3)
            for artists in self.platforms:  # a log of several drawn before
                for artist in artists:
                    artist.set_data([], [])
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
        drawn = (platform_handles if several else [self.lines, self.own]) + (
            [self.track] if finite else []) + ([self.ring] if ring.size else []) + (
            [self.band] if band.size else [])
        self.ax.legend(handles=drawn, loc="best", fontsize=8)
        self.ax.set_title(title, fontsize=10)
        return self.fig

    def _draw_platforms(self, lg: BearingsLog, row: int, valid, track):
        """A log of several platforms: each platform's track (a point where it never moved),
        named, its position at the contact's last bearing and its own lines of sight (every
        k-th of its bearings of the contact), in its colour. Returns the legend's handles
        (their lines of sight, then the tracks) and the lines' ends (m)."""
        while len(self.platforms) < lg.n_platforms:
            colour = platform_colour(len(self.platforms))
            path, = self.ax.plot([], [], color=colour)
            now, = self.ax.plot([], [], "o", color=colour, ms=4)
            lines, = self.ax.plot([], [], color=colour, lw=0.5, alpha=0.7, zorder=1.5)
            self.platforms.append((path, now, lines))
        drawn = {k: (at, step) for k, at, step in drawn_bearings(lg, valid)}
        t_last = lg.t_s[valid[-1]]
        at_all = np.concatenate([at for at, _ in drawn.values()])
        reach = sight_reach(np.column_stack([lg.own_x_m[at_all], lg.own_y_m[at_all]]), track)
        sights, paths, ends = [], [], []
        for k, epochs in enumerate(platform_epochs(lg)):
            path, now, lines = self.platforms[k]
            name, fixed = lg.platforms[k], is_fixed(lg, epochs)
            path.set_data(np.stack([lg.own_x_m[epochs], lg.own_y_m[epochs]]) / 1e3)
            path.set_linestyle("None" if fixed else "-")
            path.set_marker("^" if fixed else "None")
            path.set_label(f"{name} (fixed)" if fixed else name)
            now.set_data(([], []) if fixed else platform_now(lg, k, t_last)[:, None] / 1e3)
            paths.append(path)
            if k in drawn:
                at, step = drawn[k]
                start, end = sight_ends(lg, row, at, reach)
                lines.set_data(_segments(start, end).T)
                lines.set_label(f"{name}'s bearings" + (f" (every {step}th)" if step > 1
                                                        else ""))
                sights.append(lines)
                ends.append(end)
            else:  # it took none of this contact's bearings
                lines.set_data([], [])
        for artists in self.platforms[lg.n_platforms:]:  # a log of more platforms drawn before
            for artist in artists:
                artist.set_data([], [])
        return sights + paths, np.concatenate(ends)

    def close(self):
        plt.close(self.fig)


def _segments(start, end) -> np.ndarray:
    """Line segments from ``start`` to ``end`` (k, 2, m) as one polyline in km, NaN between."""
    return np.stack([start, end, np.full_like(start, np.nan)], axis=1).reshape(-1, 2) / 1e3


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

