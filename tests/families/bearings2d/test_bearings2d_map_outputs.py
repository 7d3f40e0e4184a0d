"""Outputs of a dataset without truth (an ingested log): the per-track table with its
position now in local metres, latitude/longitude and UTC, a PNG per contact, and the
estimated tracks as an MCAP read back with Foxglove's own schema."""

import json
import logging
import struct

import numpy as np
import pandas as pd
import pymap3d
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from omegaconf import OmegaConf

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from tests.conftest import compose_cfg
from tma.families.bearings2d import contact_plots
from tma.families.bearings2d.drawn_tracks import CHI2_2_P95, ellipse_points
from tma.families.bearings2d.log import read_bearings_log, write_bearings_log
from tma.families.bearings2d.map_mcap import write_map_mcap
from tma.families.bearings2d.scenario import Config, simulate_shard
from tma.families.bearings2d.track_report import track_report
from tma.io.dataset import Dataset, datasets_dir, file_record, shard_relpath, write_manifest
from tma.maths.geo import local_to_geodetic
from tma.stages.aggregate import aggregate

ORIGIN = (59.9, 10.7)  # deg
EPOCH_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z, the scenario's default epoch
LABELS = ["T1", "bravo 2", "T1/x"]  # text ids; two need sanitising for file names
SHOWN = ["T1", "bravo 2", "T1_x"]  # as outputs name them: no path separator


def _simulated(origin=ORIGIN, labels=LABELS, n=3):
    cfg = Config(n_tracks=n, shard_size=n, sigma_deg=0.5, seed=7)
    cfg.origin.lat, cfg.origin.lon = origin if origin else (None, None)
    log, truth = simulate_shard(cfg, 0)
    log.track_label = None if labels is None else np.array(labels, dtype=object)
    return log, truth.to_pandas()


def _ingested_dataset(data_dir, name, log):
    """A dataset laid out as ingest writes it (one shard, a manifest, no truth)."""
    root = datasets_dir(data_dir) / name
    rel = shard_relpath(0)
    n_msg = write_bearings_log(root / rel, log, {"tma.dataset": {"family": "bearings2d"}})
    write_manifest(root, family="bearings2d", source="ingest", name=name,
                   config={"format": "mcap"}, files={},
                   shards={rel: file_record(root / rel, messages=n_msg, tracks=log.n_tracks)},
                   extra={"time_origin_s": 0.0, "sigma_deg": log.sigma_deg})


def _estimate_and_aggregate(tmp_path, name):
    cfg = compose_cfg([f"paths.data_dir={tmp_path / 'data'}",
                       f"paths.tables_dir={tmp_path / 'tables'}", f"dataset={name}",
                       "estimator.initial_bearing_deg=null", "progress=false",
                       "parallel=serial"])
    estimate_stage(cfg)
    aggregate_stage(cfg)
    runs = list((tmp_path / "data" / "runs" / name).glob("lm-*/estimates"))
    return (pd.read_csv(tmp_path / "tables" / f"{name}-lm.csv", dtype={"label": str}),
            pd.read_parquet(runs[0]))


@pytest.fixture(scope="module")
def mapped(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("map")
    log, truth = _simulated()
    _ingested_dataset(tmp_path / "data", "sea", log)
    report, estimates = _estimate_and_aggregate(tmp_path, "sea")
    return tmp_path / "tables", log, truth, report, estimates


def _covariance_now(estimates, t):
    """Independent of the code under test: (J^T J)^-1 sigma^2 by a plain inverse, then the
    position p0 + v t."""
    jtj = np.empty((len(estimates), 4, 4))
    for i in range(4):
        for j in range(i, 4):
            jtj[:, i, j] = jtj[:, j, i] = estimates[f"jtj_{i}{j}"]
    theta_cov = np.linalg.inv(jtj) * np.deg2rad(estimates["sigma_used_deg"].to_numpy())[
        :, None, None] ** 2
    A = np.zeros((len(estimates), 2, 4))
    A[:, 0, 0] = A[:, 1, 1] = 1.0
    A[:, 0, 2] = A[:, 1, 3] = t
    return A @ theta_cov @ np.swapaxes(A, 1, 2)


def test_table_holds_state_now_in_metres_lat_lon_and_utc(mapped):
    tables, log, truth, report, estimates = mapped
    assert (tables / "sea-lm.md").exists()
    for column in ("range_now_m", "range_sd_m", "bearing_now_deg", "bearing_sd_deg",
                   "course_deg", "course_sd_deg", "speed_m_s", "speed_sd_m_s", "status",
                   "x_now_m", "x_sd_m", "y_now_m", "y_sd_m", "lat_now_deg", "lon_now_deg",
                   "time_now_utc", "label"):
        assert column in report.columns, column
    assert list(report.label) == LABELS
    assert (report.status == "ok").all()
    t = estimates.t_last_s.to_numpy()
    assert list(report.time_now_utc) == [
        (pd.Timestamp(EPOCH_NS, tz="UTC") + pd.Timedelta(seconds=s)).strftime(
            "%Y-%m-%dT%H:%M:%SZ") for s in t]
    # latitude/longitude: pymap3d's forward map of the sea-level point gives x, y back
    east, north, _ = pymap3d.geodetic2enu(report.lat_now_deg, report.lon_now_deg, 0.0,
                                          *ORIGIN, 0.0)
    np.testing.assert_allclose(east, report.x_now_m, rtol=0, atol=1e-3)
    np.testing.assert_allclose(north, report.y_now_m, rtol=0, atol=1e-3)
    # one-sigma position errors, and the range sd the estimator reported, from the same
    # covariance computed independently
    cov = _covariance_now(estimates, t)
    np.testing.assert_allclose(report.x_sd_m, np.sqrt(cov[:, 0, 0]), rtol=1e-6)
    np.testing.assert_allclose(report.y_sd_m, np.sqrt(cov[:, 1, 1]), rtol=1e-6)
    los = np.column_stack([report.x_now_m - estimates.own_x_last_m,
                           report.y_now_m - estimates.own_y_last_m])
    los /= np.hypot(*los.T)[:, None]
    np.testing.assert_allclose(np.sqrt(np.einsum("ni,nij,nj->n", los, cov, los)),
                               report.range_sd_m, rtol=1e-6)
    # and the truth lies inside the 99.9 % region of that covariance
    err = np.column_stack([report.x_now_m - (truth.x0_m + truth.vx_m_s * t),
                           report.y_now_m - (truth.y0_m + truth.vy_m_s * t)])
    assert np.all(np.einsum("ni,nij,nj->n", err, np.linalg.inv(cov), err) < 13.8)


def _decoded(path):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        messages = {}
        for _, channel, message, fix in reader.iter_decoded_messages(log_time_order=False):
            messages.setdefault(channel.topic, []).append((message, fix))
        records = {m.name: m.metadata for m in reader.iter_metadata()}
    return schemas, messages, records


def test_estimated_tracks_mcap_in_foxglove_schema(mapped):
    tables, log, _, report, estimates = mapped
    schemas, messages, records = _decoded(tables / "sea-lm.mcap")
    topics = ["/ownship/location_fix", *(f"/tma/estimate/{label}" for label in SHOWN)]
    assert sorted(schemas) == sorted(topics)
    assert {s.name for s in schemas.values()} == {"foxglove.LocationFix"}
    assert {s.encoding for s in schemas.values()} == {"protobuf"}
    geo = {k: json.loads(v) for k, v in records["tma.geo"].items()}
    assert (geo["origin_lat_deg"], geo["origin_lon_deg"], geo["epoch_utc_ns"]) == (
        *ORIGIN, EPOCH_NS)
    all_times = [m.log_time for m in sorted(
        (m for ms in messages.values() for m, _ in ms), key=lambda m: m.sequence)]
    assert all_times == sorted(all_times)  # written in time order

    own = messages["/ownship/location_fix"]
    assert len(own) == log.t_s.size
    ref_lat, ref_lon, _ = pymap3d.enu2geodetic(log.own_x_m, log.own_y_m, 0.0, *ORIGIN, 0.0)
    np.testing.assert_allclose([f.latitude for _, f in own], ref_lat, rtol=0, atol=1e-7)
    np.testing.assert_allclose([f.longitude for _, f in own], ref_lon, rtol=0, atol=1e-7)

    for n, label in enumerate(SHOWN):
        fixes = messages[f"/tma/estimate/{label}"]
        k = np.flatnonzero(np.isfinite(log.bearing_deg[n]))
        assert len(fixes) == k.size  # one fix per bearing epoch
        t = log.t_s[k]
        stamps = np.array([f.timestamp.seconds * 10**9 + f.timestamp.nanos for _, f in fixes])
        np.testing.assert_array_equal(stamps, [m.log_time for m, _ in fixes])
        np.testing.assert_array_equal(stamps, EPOCH_NS + np.round(t * 1e9).astype(np.int64))
        e = estimates.iloc[n]
        x, y = e.x0_m + e.vx_m_s * t, e.y0_m + e.vy_m_s * t
        lat = np.array([f.latitude for _, f in fixes])
        lon = np.array([f.longitude for _, f in fixes])
        east, north, up = pymap3d.geodetic2enu(lat, lon, 0.0, *ORIGIN, 0.0)
        np.testing.assert_allclose(east, x, rtol=0, atol=1e-3)
        np.testing.assert_allclose(north, y, rtol=0, atol=1e-3)
        # the tangent-plane point is d^2 / 2R above the sea; its lat/lon differ by about
        # d^3 / 2R^2: under a metre within 45 km
        ref_lat, ref_lon, _ = pymap3d.enu2geodetic(x, y, 0.0, *ORIGIN, 0.0)
        np.testing.assert_allclose(lat, ref_lat, rtol=0, atol=1e-5)
        cov = np.array([f.position_covariance for _, f in fixes]).reshape(-1, 3, 3)
        assert {f.position_covariance_type for _, f in fixes} == {3}  # KNOWN
        expected = _covariance_now(estimates.iloc[[n] * k.size], t)
        np.testing.assert_allclose(cov[:, :2, :2], expected, rtol=1e-6)
        assert np.all(cov[:, 2, :] == 0) and np.all(cov[:, :, 2] == 0)
        np.testing.assert_allclose([lat[-1], lon[-1]],
                                   report.loc[n, ["lat_now_deg", "lon_now_deg"]].to_numpy(float),
                                   rtol=0, atol=1e-9)


def test_a_position_only_contact_is_drawn_and_mapped_at_its_position_now(mapped, tmp_path):
    """A contact whose heading is not determined (``position_only``, its course and speed
    blank as the report leaves them): the map holds one fix, its position now with its
    covariance, at its last bearing; the plot draws that point alone and says so, where the
    others keep their track."""
    from tma.families.bearings2d.track_report import blank_headings

    _, log, _, report, estimates = mapped
    report = report.copy()
    report.loc[1, "status"] = "position_only"
    blank_headings(report)
    path = write_map_mcap(tmp_path / "po.mcap", report, estimates, [log], EPOCH_NS, ORIGIN,
                          {"dataset": "sea"})
    _, messages, _ = _decoded(path)
    (fix,) = [f for _, f in messages[f"/tma/estimate/{SHOWN[1]}"]]
    k = np.flatnonzero(np.isfinite(log.bearing_deg[1]))
    t = log.t_s[k[-1]]
    assert fix.timestamp.seconds * 10**9 + fix.timestamp.nanos == EPOCH_NS + round(t * 1e9)
    np.testing.assert_allclose([fix.latitude, fix.longitude],
                               report.loc[1, ["lat_now_deg", "lon_now_deg"]].to_numpy(float),
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.reshape(fix.position_covariance, (3, 3))[:2, :2],
                               _covariance_now(estimates.iloc[[1]], np.array([t]))[0],
                               rtol=1e-6)
    assert len(messages[f"/tma/estimate/{SHOWN[0]}"]) == np.isfinite(log.bearing_deg[0]).sum()
    figure = contact_plots.contact_figure(report, estimates, [log], LABELS[1])
    lines = {ln.get_label(): ln for ln in figure.axes[0].lines}
    assert "estimated track" not in lines
    x, y = lines["estimated position now (heading not determined)"].get_data()
    np.testing.assert_allclose(np.column_stack([x, y]) * 1e3,
                               report.loc[[1], ["x_now_m", "y_now_m"]].to_numpy(float),
                               rtol=1e-9)
    assert "course and speed not determined" in figure.axes[0].get_title()
    figure = contact_plots.contact_figure(report, estimates, [log], LABELS[0])
    assert {ln.get_label() for ln in figure.axes[0].lines} >= {"estimated track"}


def _png_size(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24]), len(data)


def test_one_png_per_contact(mapped):
    tables = mapped[0]
    for part in ("T1", "bravo_2", "T1_x"):
        (width, height), size = _png_size(tables / f"sea-lm-{part}.png")
        assert (width, height) == (840, 840)  # 7 in at 120 dpi
        assert size > 20_000  # lines were drawn, not an empty frame


def test_without_origin_no_map_mcap_and_a_line_saying_why(tmp_path, caplog, monkeypatch):
    log, _ = _simulated(origin=None, labels=None)
    _ingested_dataset(tmp_path / "data", "local", log)
    monkeypatch.setattr(contact_plots, "MAX_PLOTS", 2)
    with caplog.at_level(logging.INFO):
        report, _ = _estimate_and_aggregate(tmp_path, "local")
    assert not (tmp_path / "tables" / "local-lm.mcap").exists()
    assert "no map MCAP (local-lm.mcap): the dataset has no geographic origin" in caplog.text
    assert "plotting the first 2 of 3 contacts" in caplog.text
    assert report.lat_now_deg.isna().all() and report.lon_now_deg.isna().all()
    assert list(report.label) == ["0", "1", "2"]
    assert sorted(p.name for p in (tmp_path / "tables").glob("*.png")) == [
        "local-lm-0.png", "local-lm-1.png"]


def test_ellipse_is_the_95_percent_contour():
    cov = np.array([[4.0e4, -1.5e4], [-1.5e4, 1.0e4]])
    center = np.array([1000.0, -2000.0])
    d = ellipse_points(center, cov) - center
    np.testing.assert_allclose(np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov), d), CHI2_2_P95,
                               rtol=1e-12)
    # and 95 % of Gaussian draws fall inside it
    draws = np.random.default_rng(3).multivariate_normal([0, 0], cov, 20000)
    inside = np.einsum("ni,ij,nj->n", draws, np.linalg.inv(cov), draws) <= CHI2_2_P95
    assert abs(inside.mean() - 0.95) < 0.005


def test_points_off_the_map_have_no_latitude(recwarn):
    lat, lon = local_to_geodetic([np.nan, np.inf, 3e6, 1e4], [0.0, 0.0, 0.0, 2e4], ORIGIN)
    assert np.isnan(lat[:3]).all() and np.isnan(lon[:3]).all()
    east, north, _ = pymap3d.geodetic2enu(lat[3], lon[3], 0.0, *ORIGIN, 0.0)
    np.testing.assert_allclose([east, north], [1e4, 2e4], rtol=0, atol=1e-6)
    assert not recwarn.list  # no numpy warnings from pymap3d on NaN


def test_a_track_without_a_finite_estimate_is_left_out_of_the_map(mapped, tmp_path, caplog):
    tables, log, _, _, estimates = mapped
    broken = estimates.copy()
    broken.loc[1, "x0_m"] = np.nan
    back = read_bearings_log(next((tables.parent / "data" / "datasets" / "sea").glob(
        "log/*.mcap")))
    labels = dict(zip(back.track_id.tolist(), back.track_label, strict=True))
    report = track_report(broken, EPOCH_NS, ORIGIN, labels)
    assert np.isnan(report.lat_now_deg[1]) and np.isfinite(report.lat_now_deg[[0, 2]]).all()
    with caplog.at_level(logging.WARNING):
        write_map_mcap(tmp_path / "m.mcap", report, broken, [back], EPOCH_NS, ORIGIN, {})
    assert "for bravo 2: not in the map" in caplog.text
    schemas, _, _ = _decoded(tmp_path / "m.mcap")
    assert sorted(schemas) == ["/ownship/location_fix", "/tma/estimate/T1", "/tma/estimate/T1_x"]


# -- many contacts: one warning line per verdict, a progress bar, time -----------------------

def test_many_contacts_warn_once_per_status_and_show_progress(tmp_path, caplog, capsys):
    """30 contacts estimated by nbearings (none `ok`: biased, so `approximate` or `poor_fit`
    against the declared noise): one warning line per verdict with its count, not 30; the
    per-contact plots with a progress bar unless progress=false."""
    log, _ = _simulated(labels=[f"C{i:02d}" for i in range(30)], n=30)
    _ingested_dataset(tmp_path / "data", "many", log)
    cfg = compose_cfg([f"paths.data_dir={tmp_path / 'data'}",
                       f"paths.tables_dir={tmp_path / 'tables'}", "dataset=many",
                       "estimator=nbearings", "progress=false", "parallel=serial"])
    estimate_stage(cfg)
    jobs = [(Dataset.open(datasets_dir(tmp_path / "data") / "many"),
             OmegaConf.to_container(cfg.estimator))]
    with caplog.at_level(logging.WARNING):
        aggregate(tmp_path / "data", tmp_path / "tables", jobs, progress=True)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    table = pd.read_csv(tmp_path / "tables" / "many-nbearings.csv")
    counts = table.status.value_counts()
    assert "ok" not in counts and counts.min() > 1
    # besides: the map's one line naming the contacts whose estimate is not shown (here
    # biased answers off where their last bearings point, status.not_an_answer)
    blank = table.label[table.range_now_m.isna()]
    off_map = [w for w in warnings if not w.startswith("many: ")]
    assert off_map == ([] if blank.empty else [next(w for w in warnings if w.endswith(
        f"for {', '.join(blank)}: not in the map"))])
    warnings = [w for w in warnings if w not in off_map]
    assert sorted(warnings) == sorted(
        next(w for w in warnings if w.startswith(f"many: {n} tracks {status} ("))
        for status, n in counts.items())
    for status, n in counts.items():
        first = ", ".join(table.label[table.status == status][:10])
        (line,) = [w for w in warnings if w.startswith(f"many: {n} tracks {status} (")]
        assert f"): {first}" in line and line.endswith("the table's 'why' column says more "
                                                       "for each")
    assert "many-nbearings plots: 100%" in capsys.readouterr().err
    aggregate(tmp_path / "data", tmp_path / "tables", jobs, progress=False)
    assert "plots" not in capsys.readouterr().err
    assert len(list((tmp_path / "tables").glob("many-nbearings-C*.png"))) == 30
