"""The bearings' noise from the bearings alone (``bearing_noise.differenced_sigma``), against
the sigma the noise was drawn with: irregular times, missing bearings, two platforms
interleaved, bearings across north, and a target that turns (which a fit's residuals
would count as noise)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tma.families.bearings2d.bearing_noise import MIN_TRIPLES, differenced_sigma


def _bearings(t, ox, oy, x, y, sigma_rad, rng):
    b = np.arctan2(x - ox, y - oy) + rng.normal(0.0, sigma_rad, x.shape)
    return np.mod(b, 2 * np.pi)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), sigma_deg=st.floats(0.05, 3.0),
       missing=st.floats(0.0, 0.5))
def test_the_noise_of_steady_targets_is_found_within_its_sampling_error(seed, sigma_deg,
                                                                        missing):
    """200 tracks at 2-30 km, bearings at irregular times (1-20 s apart), some missing: the
    median over tracks lies within 5 % of sigma, and each track within its own sampling error
    (97 % within 3 of its sd, every one within 6)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(1.0, 20.0, 400))
    ox, oy = 4.0 * t, 1.0 * t
    n = 200
    r0, p0 = rng.uniform(2e3, 3e4, n), rng.uniform(0, 2 * np.pi, n)
    v = rng.uniform(-8, 8, (n, 2))
    x = (r0 * np.sin(p0))[:, None] + v[:, :1] * t
    y = (r0 * np.cos(p0))[:, None] + v[:, 1:] * t
    sigma = np.deg2rad(sigma_deg)
    measured = _bearings(t, ox, oy, x, y, sigma, rng)
    valid = rng.uniform(size=measured.shape) >= missing
    got = differenced_sigma(t, np.where(valid, measured, 0.0), valid)
    assert abs(np.median(got) / sigma - 1) < 0.05
    # each track's error in its own sampling sd, about 1.41 / sqrt(triples) (the MAD's
    # 1.17 / sqrt(n), neighbours sharing bearings; measured over 300 such draws: at most 5.1)
    z = np.abs(got / sigma - 1) / (1.41 / np.sqrt(valid.sum(axis=1) - 2))
    assert np.mean(z < 3) >= 0.97
    assert np.all(z < 6)


def test_two_platforms_are_never_differenced_together():
    """A ship and a buoy 20 km apart take bearings in turn: differencing across them would
    see their bearings' difference (tens of degrees) as noise; each platform's own are 0.5
    deg noise."""
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 1800.0, 5.0)
    platform = np.arange(t.size) % 2
    ox = np.where(platform == 0, 5.0 * t, 20e3)
    oy = np.where(platform == 0, 0.0, -5e3)
    x, y = (8e3 + 3.0 * t)[None, :], (12e3 - 2.0 * t)[None, :]
    sigma = np.deg2rad(0.5)
    measured = _bearings(t, ox, oy, x, y, sigma, rng)
    both = differenced_sigma(t, measured, None, platform)
    assert abs(both[0] / sigma - 1) < 0.15
    assert differenced_sigma(t, measured, None)[0] > 20 * sigma  # as one platform: wrong


def test_a_turn_does_not_count_as_noise_and_north_is_no_jump():
    """A target that turns by 90 deg in a minute while its bearings cross north: the
    estimate stays near sigma (a straight line's residuals would be degrees), and too few
    triples give NaN."""
    rng = np.random.default_rng(2)
    t = np.arange(0.0, 1200.0, 5.0)
    heading = np.where(t < 600, 90.0, np.where(t < 660, 90.0 - (t - 600) * 1.5, 0.0))
    vx, vy = 6.0 * np.sin(np.deg2rad(heading)), 6.0 * np.cos(np.deg2rad(heading))
    x = -2e3 + np.cumsum(vx) * 5.0
    y = 6e3 + np.cumsum(vy) * 5.0
    sigma = np.deg2rad(0.3)
    measured = _bearings(t, 0.0, 0.0, x[None, :], y[None, :], sigma, rng)
    assert np.ptp(np.rad2deg(measured)) > 300  # across north: 359 -> 1 deg
    assert abs(differenced_sigma(t, measured, None)[0] / sigma - 1) < 0.15
    few = np.zeros(measured.shape, dtype=bool)
    few[0, : MIN_TRIPLES + 1] = True  # MIN_TRIPLES - 1 triples
    assert np.isnan(differenced_sigma(t, measured, few)[0])
