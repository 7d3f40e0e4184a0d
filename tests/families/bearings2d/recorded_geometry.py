"""A recorded encounter with a known truth, for the reader tests: own-ship zig-zagging at
5 m/s from 59.9 N 10.7 E, contacts starting 15 km away at 8 m/s, bearings every 6 s with
0.5 deg noise (400 per contact, 40 min), own-ship fixes at 1 Hz. Positions are in the
east-north plane at the own-ship's first fix (pymap3d, WGS84, h = 0), so an ingested dataset
uses the same frame."""

from dataclasses import dataclass

import numpy as np
import pandas as pd
import pymap3d

from tma.families.bearings2d.estimators.lm import Config as LmConfig
from tma.families.bearings2d.estimators.lm import LevenbergMarquardt
from tma.families.bearings2d.ingest import OBSERVATION
from tma.families.bearings2d.log import read_bearings_log
from tma.io.dataset import Dataset
from tma.sources.options import source_options as reading_options
from tma.stages.ingest import ingest as ingest_log

ORIGIN = (59.9, 10.7)  # deg
START_UTC = "2025-06-01T08:00:00Z"
EPOCH_NS = int(pd.Timestamp(START_UTC).value)
SPEED = 5.0  # own-ship, m/s
LEG_S = 600.0  # zig-zag legs
COURSES = (45.0, 135.0)  # deg, alternating
BEARING_DT, N_BEARINGS, FIRST_BEARING_S = 6.0, 400, 0.5
SIGMA_DEG = 0.5
# contacts: (bearing from own-ship at t = 0 (deg), distance (m), course (deg), speed (m/s))
# (range one-sigma about 0.6, 0.6, 1.2 % at the end: 5 % is four sigma or more)
CONTACTS = {"T1": (40.0, 15000.0, 200.0, 8.0), "T2": (150.0, 15000.0, 20.0, 8.0),
            "T3": (300.0, 15000.0, 160.0, 8.0)}


def ownship_en(t):
    """Own-ship east, north (m) at times ``t`` (s): legs of LEG_S alternating COURSES."""
    t = np.asarray(t, dtype=float)
    n_legs = int(np.ceil(t.max() / LEG_S)) + 1
    course = np.deg2rad(np.resize(COURSES, n_legs))
    ends = np.cumsum(np.c_[np.sin(course), np.cos(course)] * SPEED * LEG_S, axis=0)
    starts = np.vstack([[0.0, 0.0], ends[:-1]])
    leg = np.minimum((t // LEG_S).astype(int), n_legs - 1)
    dt = t - leg * LEG_S
    return (starts[leg, 0] + np.sin(course[leg]) * SPEED * dt,
            starts[leg, 1] + np.cos(course[leg]) * SPEED * dt)


def contact_en(label, t):
    bearing, dist, course, speed = CONTACTS[label]
    b, c = np.deg2rad(bearing), np.deg2rad(course)
    t = np.asarray(t, dtype=float)
    return dist * np.sin(b) + speed * np.sin(c) * t, dist * np.cos(b) + speed * np.cos(c) * t


def latlon(east, north, origin=ORIGIN):
    """Latitude, longitude (deg) of the sea-level points (height 0) whose east and north on the
    tangent plane at ``origin`` are ``east``, ``north`` (m): the up offset is solved for, so
    that pymap3d's geodetic2enu at height 0 gives ``east``, ``north`` back."""
    up = np.zeros_like(np.asarray(east, dtype=float))
    for _ in range(4):
        lat, lon, h = pymap3d.enu2geodetic(east, north, up, origin[0], origin[1], 0.0)
        up = up - h
    return np.asarray(lat), np.asarray(lon)


@dataclass
class Recorded:
    bearings: pd.DataFrame  # t_s (since START_UTC), track, bearing_deg, own east/north/lat/lon
    navigation: pd.DataFrame  # t_s at 1 Hz, east_m, north_m, lat, lon


def recorded(labels=("T1",), seed=7, nav_dt=1.0) -> Recorded:
    rng = np.random.default_rng(seed)
    t = FIRST_BEARING_S + BEARING_DT * np.arange(N_BEARINGS)
    rows = []
    for label in labels:
        ox, oy = ownship_en(t)
        cx, cy = contact_en(label, t)
        true = np.rad2deg(np.arctan2(cx - ox, cy - oy))
        noisy = np.mod(true + SIGMA_DEG * rng.standard_normal(t.size), 360.0)
        lat, lon = latlon(ox, oy)
        rows.append(pd.DataFrame({"t_s": t, "track": label, "bearing_deg": noisy,
                                  "east_m": ox, "north_m": oy, "lat": lat, "lon": lon}))
    bearings = pd.concat(rows).sort_values(["t_s", "track"], kind="stable")
    t_nav = np.arange(0.0, t[-1] + 2.0, nav_dt)
    ex, ny = ownship_en(t_nav)
    lat, lon = latlon(ex, ny)
    nav = pd.DataFrame({"t_s": t_nav, "east_m": ex, "north_m": ny, "lat": lat, "lon": lon})
    return Recorded(bearings.reset_index(drop=True), nav)


def iso(t_s) -> list[str]:
    """ISO-8601 UTC texts of times since START_UTC, e.g. 2025-06-01T08:00:00.500000Z."""
    stamps = pd.to_datetime(EPOCH_NS + np.round(np.asarray(t_s) * 1e9).astype(np.int64),
                            utc=True)
    return [s.strftime("%Y-%m-%dT%H:%M:%S.%fZ") for s in stamps]


def estimate(root) -> pd.DataFrame:
    """``lm`` on every shard of the dataset at ``root`` (starting from each track's first
    bearing), one row per track with its label (or id) as ``label``."""
    dataset = Dataset.open(root)
    # the contacts hold course and speed exactly: assume so (a recording's default assumes
    # real-ship wander and manoeuvres, whose wider errors would blur what these tests check,
    # the geometry)
    estimator = LevenbergMarquardt(LmConfig(initial_bearing_deg=None, accel_psd_m2_s3=0.0,
                                            manoeuvre_rate_per_h=0.0))
    frames = []
    for rel in dataset.shard_paths:
        log = read_bearings_log(dataset.verified_path(rel))
        out = estimator.estimate(log)
        frame = pd.DataFrame({k: v for k, v in out.items() if np.ndim(v) == 1})
        labels = dataset.manifest.get("track_labels") or {}
        frame["label"] = [labels.get(str(i), str(i)) for i in log.track_id]
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def check_against_truth(estimates: pd.DataFrame, t_offset_s=0.0, labels=None, range_tol=0.05,
                        course_tol_deg=3.0):
    """Range now within 5 % and course within 3 deg of the truth for every track.
    ``t_offset_s``: the dataset's t = 0 in the truth's time (since START_UTC);
    ``labels``: dataset label -> contact (default: the same)."""
    assert len(estimates) >= 1
    for _, row in estimates.iterrows():
        contact = (labels or {}).get(row.label, row.label)
        t = row.t_last_s + t_offset_s
        ox, oy = ownship_en(np.array([t]))
        cx, cy = contact_en(contact, np.array([t]))
        true_range = float(np.hypot(cx - ox, cy - oy)[0])
        true_course = CONTACTS[contact][2]
        assert abs(row.range_now_m / true_range - 1) < range_tol, (contact, row.range_now_m,
                                                                   true_range)
        course_err = (row.course_deg - true_course + 180) % 360 - 180
        assert abs(course_err) < course_tol_deg, (contact, row.course_deg, true_course)


def source_options(node=None):
    """The reading options of ``bearings2d`` (its observation, the bearing) from ``node``."""
    return reading_options(node, OBSERVATION)


def ingest(input_path, **kwargs):
    """``tma.stages.ingest.ingest`` of a bearing log into a ``bearings2d`` dataset."""
    return ingest_log(input_path, family="bearings2d", **kwargs)
