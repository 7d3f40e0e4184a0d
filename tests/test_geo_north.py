"""The meridian convergence on a log's plane (``tma.maths.geo.north_on_plane_deg``) against
pymap3d's geodesy: the direction, on the tangent plane at the origin, from a point to the
point 100 m true north of it."""

import numpy as np
import pymap3d
from hypothesis import given, settings
from hypothesis import strategies as st

from tma.maths.geo import local_to_geodetic, north_at_local, north_on_plane_deg


@settings(max_examples=40, deadline=None)
@given(lat0=st.floats(-75.0, 75.0), lon0=st.floats(-180.0, 180.0),
       east_km=st.floats(-150.0, 150.0), north_km=st.floats(-150.0, 150.0))
def test_true_north_on_the_plane_is_pymap3ds(lat0, lon0, east_km, north_km):
    origin = (lat0, lon0)
    lat, lon = local_to_geodetic(np.array([east_km * 1e3]), np.array([north_km * 1e3]), origin)
    n_lat, n_lon, _ = pymap3d.aer2geodetic(0.0, 0.0, 100.0, lat[0], lon[0], 0.0)
    ne, nn, _ = pymap3d.geodetic2enu(n_lat, n_lon, 0.0, lat0, lon0, 0.0)
    pe, pn, _ = pymap3d.geodetic2enu(lat[0], lon[0], 0.0, lat0, lon0, 0.0)
    expected = np.rad2deg(np.arctan2(ne - pe, nn - pn))
    got = north_on_plane_deg(lat, lon, origin)[0]
    assert abs(got - expected) < 1e-4
    assert abs(north_at_local(east_km * 1e3, north_km * 1e3, origin) - expected) < 1e-4
    # the rule of thumb: about -(lon - lon0) sin(lat) near the origin
    if abs(east_km) < 20 and abs(north_km) < 20:
        approx = -((lon[0] - lon0 + 180.0) % 360.0 - 180.0) * np.sin(np.deg2rad(lat[0]))
        assert abs(got - approx) < 2e-3
