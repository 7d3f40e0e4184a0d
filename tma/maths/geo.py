"""The geographic reference of a log: WGS84 to local metres and back, and Foxglove fixes.

A log's local plane is the east-north tangent plane at its origin ``(lat, lon)`` (degrees,
WGS84, height 0): x east, y north in metres, as pymap3d's ``geodetic2enu`` gives them for a
point at sea level (height 0) with the up component dropped. ``local_to_geodetic`` is the
exact inverse: the sea-level point whose east and north are (x, y). Positions on the map are
``foxglove.LocationFix`` messages (Foxglove's own protobuf schema, so its Map panel shows
them).
"""

import numpy as np
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix

from tma.errors import InputError

SEA_LEVEL_TOL_M = 1e-6  # height above the sea at which a point counts as on it
MAX_ITERATIONS = 20  # each shrinks the height by ~(distance / earth radius)^2: 8 at 2000 km
MAX_MAPPED_M = 2e6  # farther from the origin the tangent plane is no map: NaN


def geodetic_to_local(lat_deg, lon_deg, origin_deg) -> tuple[np.ndarray, np.ndarray]:
    """East and north (m) on the tangent plane at ``origin_deg`` = (lat, lon) of the
    sea-level points at ``lat_deg``, ``lon_deg`` (deg, WGS84; pymap3d ``geodetic2enu``, h = 0,
    the up component dropped); vectorised."""
    import pymap3d

    east, north, _ = pymap3d.geodetic2enu(lat_deg, lon_deg, 0.0, origin_deg[0], origin_deg[1],
                                          0.0, deg=True)
    return np.asarray(east, dtype=float), np.asarray(north, dtype=float)


def check_mapped(x_m, y_m, t_s, where: str = "") -> None:
    """The own-ship-off-the-map rule, for ingest (before anything is written, ``where``: the
    input) and the log writer alike: an InputError when own-ship (``x_m``, ``y_m`` at times
    ``t_s``) goes farther than ``MAX_MAPPED_M`` from the origin, where its tangent plane maps
    nothing (``local_to_geodetic`` would give NaN), naming the first such time."""
    distance = np.hypot(np.asarray(x_m, float), np.asarray(y_m, float))
    far = ~(distance <= MAX_MAPPED_M)  # NaN and inf too
    if far.any():
        k = int(np.argmax(far))
        raise InputError(f"{where + ': ' if where else ''}own-ship goes farther than "
                         f"{MAX_MAPPED_M / 1e3:g} km from the origin ({distance[k] / 1e3:.0f} km "
                         f"at t = {t_s[k]:.9g} s after the log's start): its tangent plane "
                         "cannot map it; split the log")


def local_to_geodetic(x_m, y_m, origin_deg) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude (deg, WGS84) of the sea-level points at east ``x_m`` and north
    ``y_m`` (m) of ``origin_deg`` = (lat, lon) on its tangent plane; vectorised.

    The tangent-plane point itself (up = 0) lies d^2 / 2R above the sea (18 m at 15 km), so
    the up component is solved for: u <- u - h(x, y, u) until the height h is 0 (within a
    micrometre; 2 or 3 iterations at the ranges bearings reach). NaN for points not finite or
    farther than ``MAX_MAPPED_M`` (2000 km) from the origin."""
    import pymap3d  # here: every command imports this module with the bearings2d log

    lat0, lon0 = origin_deg
    x, y = np.broadcast_arrays(np.asarray(x_m, float), np.asarray(y_m, float))
    lat, lon = np.full(x.shape, np.nan), np.full(x.shape, np.nan)
    mapped = np.hypot(x, y) <= MAX_MAPPED_M  # False for NaN and inf too
    x, y = x[mapped], y[mapped]
    up = np.zeros_like(x)
    for _ in range(MAX_ITERATIONS):
        _, _, h = pymap3d.enu2geodetic(x, y, up, lat0, lon0, 0.0)
        up = up - h
        if np.all(np.abs(h) < SEA_LEVEL_TOL_M):
            break
    lat[mapped], lon[mapped], _ = pymap3d.enu2geodetic(x, y, up, lat0, lon0, 0.0)
    return lat, lon


def north_on_plane_deg(lat_deg, lon_deg, origin_deg) -> np.ndarray:
    """The direction (deg, clockwise from the plane's north) of true north at the points
    ``lat_deg``, ``lon_deg`` (WGS84) on the tangent plane at ``origin_deg``: the meridian
    convergence, about -(lon - lon0) sin(lat) (east of the origin in the north, true north
    leans west: -0.0156 deg per km east at 60 deg N). A direction measured from true north at
    a point (a sensor's bearing) is that plus this on the plane; vectorised."""
    lat, lon = np.deg2rad(np.asarray(lat_deg, float)), np.deg2rad(np.asarray(lon_deg, float))
    lat0, lon0 = np.deg2rad(origin_deg[0]), np.deg2rad(origin_deg[1])
    # true north at the point, in earth-centred axes, onto the origin's east and north
    nx, ny, nz = -np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)
    east = -np.sin(lon0) * nx + np.cos(lon0) * ny
    north = (-np.sin(lat0) * np.cos(lon0) * nx - np.sin(lat0) * np.sin(lon0) * ny
             + np.cos(lat0) * nz)
    return np.rad2deg(np.arctan2(east, north))


def north_at_local(x_m, y_m, origin_deg) -> np.ndarray:
    """``north_on_plane_deg`` at the plane points (``x_m``, ``y_m``) of the plane at
    ``origin_deg`` (0 where a point is not mapped): what a direction on the plane there
    loses to be read from true north, as a chart reads it."""
    lat, lon = local_to_geodetic(np.asarray(x_m, float), np.asarray(y_m, float), origin_deg)
    return np.nan_to_num(north_on_plane_deg(lat, lon, origin_deg))


UNKNOWN, KNOWN = (LocationFix.PositionCovarianceType.Value(k) for k in ("UNKNOWN", "KNOWN"))
NO_COVARIANCE = [0.0] * 9


def enu_covariance(covariance_en_m2) -> np.ndarray:
    """(..., 9): 2x2 east-north position covariances (m^2) as LocationFix's row-major 3x3
    ENU ones, up 0 (the model puts the target on the sea surface)."""
    c = np.asarray(covariance_en_m2, float)
    out = np.zeros((*c.shape[:-2], 3, 3))
    out[..., :2, :2] = c
    return out.reshape(*c.shape[:-2], 9)


def location_fix(time_ns: int, frame_id: str, lat_deg: float, lon_deg: float,
                 covariance_enu=None) -> LocationFix:
    """A ``foxglove.LocationFix`` at sea level (altitude 0). ``covariance_enu``: 9 values
    (``enu_covariance``), type KNOWN; None: unknown (type UNKNOWN, zeros)."""
    fix = LocationFix(frame_id=frame_id, latitude=lat_deg, longitude=lon_deg, altitude=0.0,
                      position_covariance=NO_COVARIANCE if covariance_enu is None
                      else covariance_enu,
                      position_covariance_type=UNKNOWN if covariance_enu is None else KNOWN)
    fix.timestamp.seconds, fix.timestamp.nanos = divmod(int(time_ns), 10**9)
    return fix
