"""Several observers in the ``bearings2d`` scenario (``scenario.observers``, ``observing``) and
the cross-fix experiment (``bearings2d_crossfix``, ``crossfix_table.py``), issue 39 item 3:
the log of several platforms the scenario writes, checked against positions and bearings
computed here from the config; the table of a small run of the real stages, its figures
recomputed here from the run files; and the experiment as Hydra composes it."""

import hashlib

import numpy as np
import pandas as pd
import pytest
from scipy.stats import binomtest, kstest

from pipeline._common import estimator_nodes, scenario_nodes
from tests.conftest import compose_cfg, run_stage_here
from tma.config import to_plain
from tma.config_nodes import validate
from tma.errors import ConfigError
from tma.families import dataset_name
from tma.families.bearings2d import crossfix_table, scenario
from tma.families.bearings2d.log import read_bearings_log, write_bearings_log
from tma.families.bearings2d.metrics import NEES_95
from tma.families.bearings2d.scenario import Config, label, simulate_shard
from tma.io.dataset import Dataset
from tma.io.runs import open_run
from tma.stages.simulate import simulate_datasets

SIGMA = 0.5
OWN = {"name": "ownship", "legs": [{"course_deg": 0.0, "duration_s": 600.0}]}  # north, 5 m/s
BUOY = {"name": "buoy", "start_x_m": -10000.0, "start_y_m": 20000.0, "sample_period_s": 10.0,
        "time_offset_s": 3.0}
SHIP2 = {"name": "ship2", "start_x_m": 32000.0, "start_y_m": 0.0, "speed_m_s": 4.0,
         "legs": [{"course_deg": 270.0, "duration_s": 500.0}], "sample_period_s": 4.0,
         "time_offset_s": 1.0}


def _config(observing=None, n=40, **more) -> Config:
    node = {"family": "bearings2d", "n_tracks": n, "shard_size": n, "sigma_deg": SIGMA,
            "observers": [OWN, BUOY, SHIP2], "observing": observing, **more}
    return validate(Config, node, "scenario 'bearings2d'")


def _where(name, t):
    """Each platform's position at times ``t``, from its config (straight legs, or fixed)."""
    t = np.asarray(t, float)
    return {"ownship": (0.0 * t, 5.0 * t), "buoy": (-10000.0 + 0 * t, 20000.0 + 0 * t),
            "ship2": (32000.0 - 4.0 * t, 0.0 * t)}[name]


def _times(o, end):
    return o.get("time_offset_s", 0.0) + o.get("sample_period_s", 2.0) * np.arange(
        int((end - o.get("time_offset_s", 0.0)) / o.get("sample_period_s", 2.0) + 1e-9) + 1)


def test_several_platforms_write_a_log_of_several():
    """A platform per epoch, epochs ordered by (time, platform), each platform's own times
    (its offset and period: asynchronous), positions (the buoy stays put) and bearings from
    its own position; the log written and read back unchanged."""
    log, truth = simulate_shard(_config(), 0)
    assert log.platforms == ("ownship", "buoy", "ship2")
    order = np.lexsort((log.platform, log.t_s))
    assert np.array_equal(order, np.arange(log.t_s.size))
    truth = truth.to_pandas().set_index("track_id").loc[log.track_id]
    ends = {"ownship": 600.0, "buoy": 600.0, "ship2": 500.0}  # the buoy: the longest path's
    residuals = {}
    for k, (o, name) in enumerate(zip((OWN, BUOY, SHIP2), log.platforms, strict=True)):
        mine = log.platform == k
        assert np.allclose(log.t_s[mine], _times(o, ends[name]), rtol=0, atol=1e-9)
        x, y = _where(name, log.t_s[mine])
        assert np.allclose(log.own_x_m[mine], x, atol=1e-6)
        assert np.allclose(log.own_y_m[mine], y, atol=1e-6)
        t = log.t_s[mine]
        tx = truth["x0_m"].to_numpy()[:, None] + truth["vx_m_s"].to_numpy()[:, None] * t
        ty = truth["y0_m"].to_numpy()[:, None] + truth["vy_m_s"].to_numpy()[:, None] * t
        true = np.rad2deg(np.arctan2(tx - x, ty - y))
        residuals[name] = ((log.bearing_deg[:, mine] - true + 180.0) % 360.0 - 180.0) / SIGMA
    assert np.ptp(log.own_x_m[log.platform == 1]) == np.ptp(log.own_y_m[log.platform == 1]) == 0
    assert set(np.round(log.t_s[log.platform == 1] % 10.0, 9)) == {3.0}  # between own-ship's
    for name, r in residuals.items():  # N(0, 1) each: the noise declared, from its platform
        assert kstest(r.ravel(), "norm").pvalue > 1e-3, name
    # independent streams: the buoy's and own-ship's noise at nearby epochs uncorrelated
    a = residuals["ownship"][:, 1:301:5].ravel()
    b = residuals["buoy"][:, :60].ravel()
    assert abs(np.corrcoef(a, b)[0, 1]) < 4.0 / np.sqrt(a.size)


def test_the_log_of_several_platforms_round_trips(tmp_path):
    log, _ = simulate_shard(_config(observing="ownship+buoy"), 0)
    write_bearings_log(tmp_path / "a.mcap", log)
    back = read_bearings_log(tmp_path / "a.mcap")
    assert back.platforms == ("ownship", "buoy")
    assert np.array_equal(back.platform, log.platform)
    assert np.array_equal(back.t_s, log.t_s)
    assert np.allclose(back.bearing_deg, log.bearing_deg, rtol=0, atol=1e-12)


def test_observing_picks_platforms_with_their_own_noise_and_the_same_targets():
    """One platform observing writes a log of one own-ship; each platform's bearings are the
    same whichever others observe with it; the targets are those of the same seed without
    observers (the shard's first stream), their distance from the first declared observer."""
    alone, truth_alone = simulate_shard(_config("ownship"), 0)
    assert alone.platform is None and alone.platforms is None
    pair, truth_pair = simulate_shard(_config("ownship+buoy"), 0)
    assert truth_pair.equals(truth_alone)
    own = pair.platform == 0
    assert np.array_equal(pair.t_s[own], alone.t_s)
    assert np.array_equal(pair.bearing_deg[:, own], alone.bearing_deg)
    three, _ = simulate_shard(_config(), 0)
    assert np.array_equal(three.bearing_deg[:, three.platform == 1],
                          pair.bearing_deg[:, pair.platform == 1])
    # the buoy first: it is the reference, its noise still its own
    swapped, _ = simulate_shard(_config("buoy+ownship"), 0)
    assert swapped.platforms == ("buoy", "ownship")
    assert np.array_equal(swapped.bearing_deg[:, swapped.platform == 0],
                          pair.bearing_deg[:, pair.platform == 1])
    default, truth_default = simulate_shard(
        validate(Config, {"family": "bearings2d", "n_tracks": 40, "shard_size": 40,
                          "sigma_deg": SIGMA}, "scenario 'bearings2d'"), 0)
    assert truth_default.equals(truth_alone)
    assert not np.array_equal(default.bearing_deg[:, :alone.t_s.size], alone.bearing_deg)


# sha256 of the bearings and truth columns of Config(n_tracks=7, shard_size=5, sigma_deg=0.3)
# shards 0 and 1 before observers were added (test_bearings2d_outliers.py's, computed before
# outliers.prob): without observers every byte stays
BEFORE = {0: "c349da5f7ab0ab0056ef79c3c14c3077379d9b493ab398d529572d893b8b7cff",
          1: "fb7d4241d96d9cce96a032685d732e05b1dee26222a13426938047199e6d46f3"}


@pytest.mark.parametrize("shard", [0, 1])
def test_without_observers_every_byte_stays(shard):
    cfg = Config(n_tracks=7, shard_size=5, sigma_deg=0.3)
    log, truth = simulate_shard(cfg, shard)
    h = hashlib.sha256(np.ascontiguousarray(log.bearing_deg).tobytes())
    for column in truth.column_names:
        h.update(np.ascontiguousarray(truth[column].to_numpy()).tobytes())
    assert h.hexdigest() == BEFORE[shard]
    assert log.platform is None and log.platforms is None
    assert label(cfg) == "sigma0.3-n7"
    # the config's hash too (computed on main before observers): the dataset's name, its
    # manifest and the config_sha256 in each shard's metadata, so every byte of it, stay
    assert dataset_name(scenario, cfg) == "bearings2d-sigma0.3-n7-daf6f3e813"
    assert "observers" not in to_plain(cfg) and "observing" not in to_plain(cfg)
    plain = to_plain(_config("ownship+buoy"))
    assert plain["observing"] == "ownship+buoy" and len(plain["observers"]) == 3
    assert validate(Config, plain, "scenario 'bearings2d'") == _config("ownship+buoy")


def test_moving_targets_are_seen_by_every_platform():
    """Wandering targets: each platform's bearings point at the one path of each target, so
    the residuals against the truth at the last bearing grow only with the wander."""
    log, truth = simulate_shard(_config("ownship+buoy", target={"accel_psd_m2_s3": 1e-4}), 0)
    assert log.accel_psd_m2_s3 == 1e-4 and log.platforms == ("ownship", "buoy")
    truth = truth.to_pandas().set_index("track_id").loc[log.track_id]
    for k, name in enumerate(log.platforms):
        last = np.flatnonzero(log.platform == k)[-1]
        t = log.t_s[last]
        x, y = _where(name, t)
        tx = truth["x0_m"].to_numpy() + truth["vx_m_s"].to_numpy() * t  # the state then
        ty = truth["y0_m"].to_numpy() + truth["vy_m_s"].to_numpy() * t
        r = (log.bearing_deg[:, last] - np.rad2deg(np.arctan2(tx - x, ty - y)) + 180) % 360 - 180
        assert np.all(np.abs(r) < 5 * SIGMA), name  # 5 sigma: the noise alone (t within 10 s)


def test_the_same_config_gives_the_same_bytes_on_any_number_of_workers(tmp_path):
    node = {"family": "bearings2d", "n_tracks": 30, "shard_size": 10, "sigma_deg": SIGMA,
            "observers": [OWN, BUOY]}
    shards = []
    for workers in (1, 2):
        [root] = simulate_datasets([node], tmp_path / f"w{workers}", engine=workers,
                                   progress=False)
        shards.append({k: v["sha256"] for k, v in Dataset.open(root).manifest["shards"]
                       .items()})
    assert shards[0] == shards[1] and len(shards[0]) == 3


@pytest.mark.parametrize("change, match", [
    ({"observing": "ownship+radar"}, "radar is not among the observers"),
    ({"observers": [OWN, OWN]}, "names must be distinct"),
    ({"observers": [BUOY]}, "buoy is fixed and no observer moves: give its duration_s"),
    ({"observers": [{**BUOY, "name": "a b", "duration_s": 60.0}]}, "observers\\[0\\].name"),
    ({"observers": [OWN, {**BUOY, "time_offset_s": 700.0}]}, "after its last bearing time"),
    ({"observers": [{**OWN, "duration_s": 60.0}]}, "duration_s is for a fixed platform"),
    ({"observer": {"speed_m_s": 3.0}}, "observer.\\* is the one own-ship"),
    ({"observers": [], "observing": "ownship"}, "observers is empty"),
])
def test_bad_observers_fail_in_one_line(change, match):
    node = {"family": "bearings2d", "observers": [OWN, BUOY], **change}
    with pytest.raises(ConfigError, match=match) as info:
        validate(Config, node, "scenario 'bearings2d'")
    assert "\n" not in str(info.value)


# -- the experiment, shrunk, through the real stages -------------------------------------------

N = 300


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    """``bearings2d_crossfix`` with 300 constant-velocity targets, own-ship straight alone and
    with the buoy, ``lm``: simulate, estimate and aggregate (``pipeline.table``)."""
    root = tmp_path_factory.mktemp("crossfix")
    args = ["experiment=bearings2d_crossfix", f"scenario.n_tracks={N}",
            "scenario.shard_size=150", "scenario.target.accel_psd_m2_s3=0.0",
            "scenario.observing=[ownship,ownship+buoy]", "estimator=lm", "parallel=serial",
            "progress=false", f"paths.data_dir={root / 'data'}",
            f"paths.tables_dir={root / 'tables'}"]
    run_stage_here("table", *args)
    table = pd.read_csv(root / "tables" / "bearings2d_crossfix.csv")
    assert list(table.columns) == crossfix_table.COLUMNS
    markdown = (root / "tables" / "bearings2d_crossfix.md").read_text()
    runs = {}
    for run_root in sorted((root / "data" / "runs").glob("*/lm-*")):
        dataset = Dataset.open(root / "data" / "datasets" / run_root.parent.name)
        runs[crossfix_table.platforms_label(dataset.manifest["config"])] = (
            dataset, open_run(run_root)[1].to_pandas())
    return table.set_index("platforms"), runs, markdown


def _true_range_now(dataset, estimates):
    """Per track the true range from own-ship (straight north at 5 m/s from the origin) at
    its last bearing, and the estimated one, computed here."""
    truth = dataset.read_truth().set_index("track_id").loc[estimates["track_id"]]
    t = estimates["t_last_s"].to_numpy()
    ox, oy = 0.0 * t, 5.0 * t

    def rng(x0, y0, vx, vy):
        return np.hypot(x0 + vx * t - ox, y0 + vy * t - oy)

    cols = ["x0_m", "y0_m", "vx_m_s", "vy_m_s"]
    return (rng(*(truth[c].to_numpy() for c in cols)),
            rng(*(estimates[c].to_numpy() for c in cols)), truth, t)


def runs_nees(dataset, estimates) -> np.ndarray:
    """Per track the normalised error of theta, (theta_hat - theta)^T I (theta_hat - theta)
    with I = J^T J / sigma^2 the information the estimator reports (``jtj_ij``)."""
    truth = dataset.read_truth().set_index("track_id").loc[estimates["track_id"]]
    cols = ["x0_m", "y0_m", "vx_m_s", "vy_m_s"]
    e = estimates[cols].to_numpy() - truth[cols].to_numpy()
    jtj = np.empty((len(e), 4, 4))
    for i in range(4):
        for j in range(4):
            jtj[:, i, j] = estimates[f"jtj_{min(i, j)}{max(i, j)}"].to_numpy()
    sigma = np.deg2rad(estimates["sigma_used_deg"].to_numpy())
    return np.einsum("ni,nij,nj->n", e, jtj, e) / sigma**2


def test_one_platform_that_does_not_manoeuvre_cannot_tell_range(small_run):
    table, runs, _ = small_run
    row = table.loc["ownship"]
    assert row["n_tracks"] == N
    _, estimates = runs["ownship"]
    assert (estimates["status"] == "ok").sum() <= 0.02 * N  # flagged, not answered
    assert row["ok"] == pytest.approx((estimates["status"] == "ok").mean(), abs=1e-6)
    assert np.isinf(row["crlb_range_median_m"]) and np.isnan(row["crossing_deg"])


def test_a_second_platform_makes_it_observable_and_consistent(small_run):
    """With the buoy: nearly every track ``ok``; 95 % of them (a binomial interval) within
    the chi-square(4) 95 % point; the range RMSE at the last bearing, from own-ship (the
    reference, wherever the buoy is), within 25 % of the Cramer-Rao bound; the crossing angle
    as computed here from the buoy's and own-ship's positions; each figure recomputed from
    the run files."""
    table, runs, _ = small_run
    row = table.loc["ownship+buoy"]
    dataset, estimates = runs["ownship+buoy"]
    ok = (estimates["status"] == "ok").to_numpy()
    assert ok.mean() >= 0.95 and row["ok"] == pytest.approx(ok.mean(), rel=1e-5)
    true_range, est_range, truth, t = _true_range_now(dataset, estimates)
    # the reference platform's position now, whichever platform took the last bearing
    assert np.allclose(estimates["own_y_last_m"], 5.0 * t) and np.allclose(
        estimates["own_x_last_m"], 0.0)
    rmse = np.sqrt(np.mean((est_range - true_range)[ok] ** 2))
    assert row["rmse_range_ok_m"] == pytest.approx(rmse, rel=1e-5)
    assert 0.8 <= row["rmse_range_ok_m"] / row["crlb_range_ok_m"] <= 1.25
    consistent = int(round(row["consistent"] * ok.sum()))
    assert binomtest(consistent, int(ok.sum()), 0.95).pvalue > 1e-3
    nees_ok = runs_nees(dataset, estimates)[ok]
    assert consistent == int((nees_ok <= NEES_95).sum())
    tx = truth["x0_m"].to_numpy() + truth["vx_m_s"].to_numpy() * t
    ty = truth["y0_m"].to_numpy() + truth["vy_m_s"].to_numpy() * t
    a = np.rad2deg(np.arctan2(tx, ty - 5.0 * t) - np.arctan2(tx + 10000.0, ty - 20000.0))
    a = np.abs((a + 180.0) % 360.0 - 180.0)
    crossing = np.median(np.minimum(a, 180.0 - a))
    assert row["crossing_deg"] == pytest.approx(crossing, rel=1e-5)
    assert 40.0 <= crossing <= 90.0  # the experiment's geometry: lines that cross well
    assert row["ref2"] >= 0.95 and row["median_range_error"] < 0.01


def test_the_markdown_table_names_the_platforms(small_run, tmp_path):
    """Each row's platforms, the unobservable bound as inf, the declared platforms."""
    _, _, markdown = small_run
    rows = [line for line in markdown.splitlines() if line.startswith("| lm |")]
    assert [r.split(" | ")[1] for r in rows] == ["ownship", "ownship+buoy"]
    assert rows[0].endswith("| inf |")
    assert "- buoy: fixed at (-10000, 20000) m, a bearing every 10 s from t = 3 s" in markdown
    assert crossfix_table.write_crossfix_table([], tmp_path, "x") == []


def test_the_experiment_composes():
    cfg = compose_cfg(["experiment=bearings2d_crossfix"])
    assert cfg.table == "bearings2d_crossfix" and cfg.table_kind == "crossfix"
    nodes = scenario_nodes(cfg)
    observing = ["ownship", "ownship+buoy", "ownship+ship2", "ownship_legs",
                 "ownship_legs+buoy"]
    assert [n["observing"] for n in nodes] == observing * 2  # the last axis varies fastest
    assert [n["target"]["accel_psd_m2_s3"] for n in nodes] == [0.0] * 5 + [1e-4] * 5
    assert [n["name"] for n in estimator_nodes(cfg)] == ["lm", "last_leg"]
    for node in nodes:
        cfg_ = validate(Config, node, "scenario 'bearings2d'")
        buoy = next(o for o in cfg_.observers if o.name == "buoy")
        assert not buoy.legs  # fixed


def test_a_contact_whose_last_bearing_is_the_buoys_is_drawn_from_its_recording():
    """``tma.plot_contact`` checks the results against the log: range now is read from
    own-ship (the reference) although the buoy took the last bearing (at t = 601 s); the
    same results against another log still fail."""
    import tma

    own = {**OWN, "legs": [{"course_deg": 0.0, "duration_s": 601.0}]}
    buoy = {**BUOY, "time_offset_s": 1.0}
    data = tma.simulate(n_tracks=3, shard_size=3, observers=[own, buoy], observing="ownship+buoy")
    assert data.logs[0].platform[-1] == 1 and data.logs[0].t_s[-1] == 601.0
    results = tma.estimate(data, "lm")
    assert np.allclose(results.tma.estimates["own_y_last_m"], 5.0 * 601.0)
    assert tma.plot_contact(results, data, results["label"].iloc[0]) is not None
    other = tma.simulate(n_tracks=3, shard_size=3, observers=[OWN, BUOY])
    with pytest.raises(ValueError, match="not estimated from this recording"):
        tma.plot_contact(results, other, results["label"].iloc[0])
