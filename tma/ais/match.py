"""Which ship each contact of a bearing log is: the one the user names (``truth.match``), or
the one whose AIS track would have produced the contact's bearings.

For a contact (its bearing times, own-ship there, the measured bearings) and a ship (its AIS
track on the log's plane), the ship's bearings are those from own-ship to the ship's
interpolated position at each bearing time; the fit is the RMS of the wrapped differences,
in degrees. A ship is a candidate when its reports cover the contact's bearings and it comes
within ``truth.max_range_km`` of own-ship. It *fits* when its RMS is at most the bound:
``truth.max_rms_deg``, else 3 sigma (the log's nominal sigma; without one, sigma estimated
from the bearings' second differences, robustly: 1.4826 MAD / sqrt(6)), at least 0.1 deg.

Automatic matching says, for every contact, one of: matched (one ship fits, or the best fits
better than ``truth.ambiguity_ratio`` times the next), ambiguous (two fit about as well: the
contact gets no truth, the message names both and the option that settles it), or no fit
(the nearest ship's RMS and the bound, or why no ship is a candidate). A given match is
checked the same way; one that cannot be (an MMSI the file does not hold, that does not cover
the contact, never comes within reach or does not fit) refuses the file (``TruthError``),
since the user said it is so. Either way, a ship whose AIS has a gap longer than
``truth.max_gap_s`` over the contact's bearings gives it no truth, and the reason says where.
"""

from dataclasses import dataclass, field

import numpy as np

from tma.ais.options import FIT_SIGMAS, MIN_FIT_DEG, TruthError, TruthOptions
from tma.ais.tracks import PlaneTrack
from tma.maths.angles import wrap_to_180
from tma.utc import format_utc

MAD_TO_SD = 1.4826  # a normal sample's median absolute deviation to its standard deviation


@dataclass
class Contact:
    """One contact of a bearing log: ``t_s`` (s from the log's epoch) of its bearings,
    own-ship there (m, the log's plane) and the bearings (deg clockwise from north);
    ``sigma_deg`` the log's nominal noise or None."""

    track_id: int
    label: str
    t_s: np.ndarray
    own_x_m: np.ndarray
    own_y_m: np.ndarray
    bearing_deg: np.ndarray
    sigma_deg: float | None = None


@dataclass
class Match:
    """What matching found for one contact. ``mmsi``: its ship (None: no truth); ``how``:
    ``given`` or ``bearings``; ``verdict``: ``matched``, ``given``, ``ambiguous``, ``no fit``
    or ``gap`` (the ship is known, its AIS has a gap); ``rms_deg`` the ship's fit (or the
    best candidate's), ``bound_deg`` the fit bound, ``sigma_deg`` the sigma it came from
    (``sigma_source``: ``nominal`` or ``estimated``); ``runner_up``: (MMSI, RMS) of the next
    candidate; ``note``: the one line a user reads."""

    track_id: int
    label: str
    mmsi: int | None
    how: str
    verdict: str
    rms_deg: float
    bound_deg: float
    sigma_deg: float
    sigma_source: str
    runner_up: tuple[int, float] | None = None
    max_gap_s: float = float("nan")
    note: str = ""
    candidates: dict = field(default_factory=dict)

    @property
    def has_truth(self) -> bool:
        return self.verdict in ("matched", "given")

    def record(self) -> dict:
        """For the manifest."""
        return {"label": self.label, "mmsi": self.mmsi, "how": self.how,
                "verdict": self.verdict, "rms_deg": _finite(self.rms_deg),
                "bound_deg": _finite(self.bound_deg), "sigma_deg": _finite(self.sigma_deg),
                "sigma_source": self.sigma_source,
                "runner_up": None if self.runner_up is None else
                {"mmsi": self.runner_up[0], "rms_deg": _finite(self.runner_up[1])},
                "max_gap_s": _finite(self.max_gap_s), "note": self.note}


def _finite(x):
    return float(x) if np.isfinite(x) else None


def bearings_from(contact: Contact, x_m, y_m) -> np.ndarray:
    """Bearings (deg clockwise from north) from own-ship to positions ``x_m``, ``y_m``."""
    return np.rad2deg(np.arctan2(x_m - contact.own_x_m, y_m - contact.own_y_m)) % 360.0


def estimated_sigma(bearing_deg: np.ndarray) -> float:
    """sigma (deg) of the bearings' noise from their second differences (robust: 1.4826 MAD
    / sqrt(6); a smooth true bearing hardly moves them). NaN for fewer than 5 bearings."""
    if bearing_deg.size < 5:
        return float("nan")
    d2 = wrap_to_180(wrap_to_180(bearing_deg[2:] - bearing_deg[1:-1])
                     - wrap_to_180(bearing_deg[1:-1] - bearing_deg[:-2]))
    return float(MAD_TO_SD * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


@dataclass
class Fit:
    """A ship against a contact: its RMS bearing difference (deg), the longest AIS gap over
    the contact's bearings (s) and its least range from own-ship (m)."""

    mmsi: int
    rms_deg: float
    max_gap_s: float
    min_range_m: float
    gap_at_s: float


def fit(contact: Contact, ship: PlaneTrack) -> Fit | None:
    """The ship against the contact; None when its reports do not cover the bearings."""
    x, y = ship.at(contact.t_s)
    if not np.isfinite(x).all():
        return None
    gaps = ship.gap(contact.t_s)
    k = int(np.argmax(gaps))
    diff = wrap_to_180(contact.bearing_deg - bearings_from(contact, x, y))
    return Fit(ship.mmsi, float(np.sqrt(np.mean(diff ** 2))), float(gaps[k]),
               float(np.min(np.hypot(x - contact.own_x_m, y - contact.own_y_m))),
               float(contact.t_s[k]))


def _bound(contact: Contact, options: TruthOptions) -> tuple[float, float, str]:
    """(bound, sigma, where sigma came from) of a contact's fit."""
    if contact.sigma_deg is not None:
        sigma, source = float(contact.sigma_deg), "nominal"
    else:
        sigma, source = estimated_sigma(contact.bearing_deg), "estimated"
    if options.max_rms_deg is not None:
        return float(options.max_rms_deg), sigma, source
    return max(FIT_SIGMAS * np.nan_to_num(sigma), MIN_FIT_DEG), sigma, source


def match_contacts(contacts: list[Contact], ships: dict[int, PlaneTrack],
                   options: TruthOptions, epoch_ns: int, where: str) -> list[Match]:
    """A ``Match`` per contact (module docstring); ``TruthError`` for a given match that
    cannot hold."""
    given = options.match or {}
    labels = {c.label for c in contacts} | {str(c.track_id) for c in contacts}
    unknown = [k for k in given if k not in labels]
    if unknown:
        raise TruthError(f"truth.match names contact {unknown[0]}, which {where} does not hold "
                         f"(its contacts: {', '.join(sorted({c.label for c in contacts})[:20])})")
    for contact_label, mmsi in given.items():
        if mmsi not in ships:
            raise TruthError(f"truth.match: MMSI {mmsi} (contact {contact_label}) has no "
                             f"position report in {options.file}")
    return [_match(c, ships, options, epoch_ns,
                   given.get(c.label, given.get(str(c.track_id)))) for c in contacts]


def _utc(epoch_ns: int, t_s: float) -> str:
    return format_utc(epoch_ns + int(round(t_s * 1e9)))


def _match(contact: Contact, ships: dict[int, PlaneTrack], options: TruthOptions,
           epoch_ns: int, given: int | None) -> Match:
    bound, sigma, source = _bound(contact, options)
    reach = options.max_range_km * 1e3
    sigma_text = (f"sigma {sigma:.2f} deg ({source})" if np.isfinite(sigma) else
                  "sigma unknown")
    base = dict(track_id=contact.track_id, label=contact.label, bound_deg=bound,
                sigma_deg=sigma, sigma_source=source)
    span = f"{_utc(epoch_ns, contact.t_s[0])} to {_utc(epoch_ns, contact.t_s[-1])}"
    if given is not None:
        ship = ships[given]
        f = fit(contact, ship)
        if f is None:
            raise TruthError(
                f"truth.match: MMSI {given}'s AIS ({_utc(epoch_ns, ship.t_s[0])} to "
                f"{_utc(epoch_ns, ship.t_s[-1])}) does not cover contact {contact.label}'s "
                f"bearings ({span}), and no option extrapolates a ship's track: give an AIS "
                "file whose reports of it cover those times (or cut the log to its AIS's "
                "times), or check the MMSI")
        if f.min_range_m > reach:
            raise TruthError(
                f"truth.match: MMSI {given} never comes within {options.max_range_km:g} km of "
                f"own-ship while contact {contact.label} is seen (nearest "
                f"{f.min_range_m / 1e3:.0f} km): not this contact's ship; check the MMSI")
        if f.rms_deg > bound:
            raise TruthError(
                f"truth.match: MMSI {given} does not fit contact {contact.label}'s bearings "
                f"(RMS difference {f.rms_deg:.2f} deg, bound {bound:.2f} deg from "
                f"{sigma_text}): not this contact's ship? check the MMSI, or set "
                "truth.max_rms_deg= to accept it")
        return _with_gap(Match(**base, mmsi=given, how="given", verdict="given",
                               rms_deg=f.rms_deg, max_gap_s=f.max_gap_s,
                               note=f"MMSI {given} (given): RMS bearing difference "
                                    f"{f.rms_deg:.2f} deg against {sigma_text}"),
                         f, options, epoch_ns)
    fits, counts, short = [], {"outside the AIS times": 0, "out of reach": 0}, []
    for ship in ships.values():
        if ship.t_s[0] > contact.t_s[0] or ship.t_s[-1] < contact.t_s[-1]:
            counts["outside the AIS times"] += 1
            short.append(ship)
            continue
        f = fit(contact, ship)
        if f.min_range_m > reach:
            counts["out of reach"] += 1
            continue
        fits.append(f)
    fits.sort(key=lambda f: f.rms_deg)
    candidates = {"ships": len(ships), "candidates": len(fits), **counts}
    def partly():  # (only where no ship fits: it fits the ships the AIS covers in part)
        return _partly_covering(contact, short, bound, reach, epoch_ns, span)

    if not fits:
        why = (f"no ship's AIS covers its bearings ({span}) within {options.max_range_km:g} km "
               f"of own-ship ({len(ships)} ships: {counts['outside the AIS times']} outside "
               f"those times, {counts['out of reach']} out of reach){partly()}")
        return Match(**base, mmsi=None, how="bearings", verdict="no fit", rms_deg=np.nan,
                     note=why, candidates=candidates)
    best = fits[0]
    runner = (fits[1].mmsi, fits[1].rms_deg) if len(fits) > 1 else None
    next_text = "" if runner is None else f"; next MMSI {runner[0]} at {runner[1]:.2f} deg"
    if best.rms_deg > bound:
        return Match(**base, mmsi=None, how="bearings", verdict="no fit", rms_deg=best.rms_deg,
                     runner_up=runner, candidates=candidates,
                     note=f"no ship fits its bearings: the nearest is MMSI {best.mmsi} at an "
                          f"RMS difference of {best.rms_deg:.2f} deg, beyond the bound "
                          f"{bound:.2f} deg ({sigma_text}){next_text}"
                          + (partly() or "; give truth.match= or truth.max_rms_deg= if you "
                                       "know better"))
    if runner is not None and runner[1] <= bound and runner[1] < (
            options.ambiguity_ratio * best.rms_deg):
        return Match(**base, mmsi=None, how="bearings", verdict="ambiguous",
                     rms_deg=best.rms_deg, runner_up=runner, candidates=candidates,
                     note=f"ambiguous: MMSI {best.mmsi} (RMS {best.rms_deg:.2f} deg) and MMSI "
                          f"{runner[0]} ({runner[1]:.2f} deg) both fit its bearings "
                          f"(bound {bound:.2f} deg, {sigma_text}); say which with "
                          f"truth.match={{{contact.label}:<MMSI>}}")
    return _with_gap(Match(**base, mmsi=best.mmsi, how="bearings", verdict="matched",
                           rms_deg=best.rms_deg, runner_up=runner, max_gap_s=best.max_gap_s,
                           candidates=candidates,
                           note=f"MMSI {best.mmsi}: RMS bearing difference {best.rms_deg:.2f} "
                                f"deg against {sigma_text} (bound {bound:.2f} deg){next_text}"),
                     best, options, epoch_ns)


def _partly_covering(contact: Contact, ships: list[PlaneTrack], bound: float, reach: float,
                     epoch_ns: int, span: str) -> str:
    """What to say of the ships whose AIS covers only part of the contact's bearings (so are
    no candidates): the best of them that fits the bearings it covers (most of them), named
    with where its reports end and what would make it a candidate; "" when none fits."""
    best = None
    for ship in ships:
        inside = (contact.t_s >= ship.t_s[0]) & (contact.t_s <= ship.t_s[-1])
        if inside.sum() < max(5, contact.t_s.size // 2):
            continue
        part = Contact(contact.track_id, contact.label, contact.t_s[inside],
                       contact.own_x_m[inside], contact.own_y_m[inside],
                       contact.bearing_deg[inside], contact.sigma_deg)
        f = fit(part, ship)
        if f is not None and f.rms_deg <= bound and f.min_range_m <= reach and (
                best is None or f.rms_deg < best[1].rms_deg):
            best = (ship, f, int(inside.sum()))
    if best is None:
        return ""
    ship, f, n = best
    return (f"; MMSI {ship.mmsi} fits the {n} of {contact.t_s.size} bearings its AIS covers "
            f"(RMS {f.rms_deg:.2f} deg) but its reports run {_utc(epoch_ns, ship.t_s[0])} to "
            f"{_utc(epoch_ns, ship.t_s[-1])}, not over the contact's {span}, and no option "
            "extrapolates a ship's track: give an AIS file whose reports of it cover those "
            "times, or cut the log to its AIS's times")


def _with_gap(match: Match, f: Fit, options: TruthOptions, epoch_ns: int) -> Match:
    """``match`` refused (verdict ``gap``) when its ship's AIS has a gap over the bound."""
    if f.max_gap_s <= options.max_gap_s:
        return match
    match.verdict = "gap"
    match.note = (f"{match.note}; but its AIS has a gap of {f.max_gap_s:.0f} s at "
                  f"{_utc(epoch_ns, f.gap_at_s)} (truth.max_gap_s = {options.max_gap_s:g} s; "
                  f"truth.max_gap_s={gap_bound(f.max_gap_s)} accepts it): no truth")
    return match


def gap_bound(gap_s: float) -> int:
    """A ``truth.max_gap_s`` that accepts a gap of ``gap_s``: the next multiple of 10 s."""
    return int(np.ceil(gap_s / 10.0 + 1e-9) * 10)
