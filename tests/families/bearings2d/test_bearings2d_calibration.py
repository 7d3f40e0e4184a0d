"""The calibration table of the manoeuvre experiment (``calibration.py``, issue 36 item 2):
the per-quantity coverage and the NEES cells on synthetic estimates whose errors are drawn
from known covariances (honest, twice too narrow, twice too wide), the chi-square interval of
the mean NEES against scipy and by Monte Carlo, and the table written end to end from a small
run of the experiment, every figure recomputed here from the run and dataset files."""

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from pipeline._common import open_datasets
from tests.conftest import compose_cfg, run_stage_here
from tma.families.bearings2d import calibration, manoeuvre_table
from tma.families.bearings2d.benchmark import estimator_label
from tma.families.bearings2d.status import kinematics_now
from tma.io.runs import open_run, seconds_per_track
from tma.maths.stats import chi2_mean_interval
from tma.stages.aggregate import RunEntry

P1, P2 = chi2.cdf(1, 1), chi2.cdf(4, 1)  # P(|Z| <= 1), P(|Z| <= 2): 0.683, 0.954
T_LAST = 1200.0  # s, own-ship at the origin then


def _tolerance(p, n):
    return 4 * np.sqrt(p * (1 - p) / n)  # a binomial share's 4 sd


def _synthetic(n, seed, scale=1.0, n_bad=0):
    """``n`` ok tracks (plus ``n_bad`` unobservable ones, far off) whose estimate is the truth
    plus an error drawn from N(0, scale^2 Sigma), Sigma the covariance the estimate states:
    honest at scale 1. Targets 5-45 km away now, own-ship at the origin at ``T_LAST``;
    Sigma of (position now, velocity) with correlations, mapped to theta = (x0, y0, vx, vy).
    Returns the estimates, the truth and the true range now (m)."""
    rng = np.random.default_rng(seed)
    m = n + n_bad
    r_now, bearing = rng.uniform(5e3, 45e3, m), rng.uniform(0, 2 * np.pi, m)
    speed, course = rng.uniform(3.0, 12.0, m), rng.uniform(0, 2 * np.pi, m)
    course[:20] = np.deg2rad(rng.uniform(-1.0, 1.0, 20)) % (2 * np.pi)  # heading north
    vx, vy = speed * np.sin(course), speed * np.cos(course)
    theta = np.column_stack([r_now * np.sin(bearing) - vx * T_LAST,
                             r_now * np.cos(bearing) - vy * T_LAST, vx, vy])
    sd = np.column_stack([0.02 * r_now, 0.01 * r_now, np.full(m, 0.3), np.full(m, 0.2)])
    corr = np.array([[1.0, 0.3, 0.5, 0.1], [0.3, 1.0, 0.2, 0.4],
                     [0.5, 0.2, 1.0, 0.3], [0.1, 0.4, 0.3, 1.0]])
    cov_now = sd[:, :, None] * corr * sd[:, None, :]
    A = np.eye(4)
    A[0, 2] = A[1, 3] = -T_LAST  # x0 = x_now - vx t
    cov = A @ cov_now @ A.T
    error = scale * np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((m, 4)))
    error[n:] *= 10.0
    estimate = theta + error
    sigma_rad = np.deg2rad(0.5)
    jtj = np.linalg.inv(cov) * sigma_rad**2  # so that (J^T J)^-1 sigma^2 = cov
    zeros = np.zeros(m)
    _, G = kinematics_now(estimate, np.full(m, T_LAST), zeros, zeros)
    stated = np.sqrt(np.einsum("nij,njk,nik->ni", G, cov, G))
    estimates = pd.DataFrame({
        "track_id": np.arange(m), **dict(zip(("x0_m", "y0_m", "vx_m_s", "vy_m_s"), estimate.T,
                                             strict=True)),
        **{f"jtj_{i}{j}": jtj[:, i, j] for i in range(4) for j in range(i, 4)},
        "sigma_used_deg": 0.5, "t_last_s": T_LAST, "own_x_last_m": 0.0, "own_y_last_m": 0.0,
        "status": ["ok"] * n + ["unobservable"] * n_bad,
        "range_sd_m": stated[:, 0], "course_sd_deg": np.rad2deg(stated[:, 2]),
        "speed_sd_m_s": stated[:, 3], "p_manoeuvre": rng.uniform(0.0, 1.0, m)})
    truth = pd.DataFrame({"track_id": np.arange(m), "x0_m": theta[:, 0], "y0_m": theta[:, 1],
                          "vx_m_s": vx, "vy_m_s": vy, "n_manoeuvres": rng.integers(0, 6, m)})
    return estimates, truth, r_now


def _rows(estimates, truth):
    rows = calibration.calibration_rows("lm", "manoeuvres 3/h", 0.5, estimates, truth)
    return pd.DataFrame(rows, columns=calibration.COLUMNS)


def test_honest_errors_are_covered_as_the_normal_says():
    """Per quantity 68.3 % within 1 sd and 95.4 % within 2 sd, 95 % consistent and a mean
    NEES of 4, in the row and in every cell, within binomial tolerances; the unobservable
    tracks (ten times off) count in N, not in the figures; nothing is outside its target."""
    n = 4000
    estimates, truth, r_now = _synthetic(n, seed=1, n_bad=300)
    table = _rows(estimates, truth)
    row = table[table.cell_group == "all"].iloc[0]
    assert (row.n_tracks, row.n_ok, row.graded) == (n + 300, n, True)
    for q in calibration.QUANTITIES:
        assert abs(row[f"{q}_within_1sd"] - P1) <= _tolerance(P1, n), q
        assert abs(row[f"{q}_within_2sd"] - P2) <= _tolerance(P2, n), q
        assert row[f"{q}_within_1sd_lo"] < row[f"{q}_within_1sd"] < row[f"{q}_within_1sd_hi"]
    assert abs(row.consistent - 0.95) <= _tolerance(0.95, n)
    # chi-square(4): variance 8 (whether a mean lies in its 95 % interval is a 5 % event
    # by construction: the interval is tested below by Monte Carlo)
    assert abs(row.mean_nees - 4.0) <= 4 * np.sqrt(8.0 / n)
    assert row.outside == ""
    cells = table[table.cell_group != "all"]
    assert set(cells.cell_group) == {"range_km", "manoeuvres", "p_manoeuvre"}
    for _, cell in cells[cells.graded].iterrows():
        assert abs(cell.consistent - 0.95) <= _tolerance(0.95, cell.n_ok), cell.cell
        assert cell.outside == "", cell.cell
    # the cells' members, counted here from what the synthetic tracks are
    ok = estimates.status == "ok"
    made = truth.n_manoeuvres.to_numpy()
    p = estimates.p_manoeuvre.to_numpy()
    expected = {("range_km", "<15"): r_now < 15e3,
                ("range_km", "15-30"): (r_now >= 15e3) & (r_now <= 30e3),
                ("range_km", ">30"): r_now > 30e3,
                **{("manoeuvres", str(k)): made == k for k in range(3)},
                ("manoeuvres", "3+"): made >= 3,
                ("p_manoeuvre", "<0.5"): p < 0.5,
                ("p_manoeuvre", "0.5-0.99"): (p >= 0.5) & (p <= 0.99),
                ("p_manoeuvre", ">0.99"): p > 0.99}
    got = {(g, c): (t, k) for g, c, t, k in cells[["cell_group", "cell", "n_tracks", "n_ok"]]
           .itertuples(index=False)}
    assert got == {key: (int(mask.sum()), int((mask & ok).sum()))
                   for key, mask in expected.items()}
    # a cell of fewer than 100 ok tracks is not graded
    assert not cells.set_index(["cell_group", "cell"]).loc[("p_manoeuvre", ">0.99"), "graded"]


def test_course_errors_are_wrapped():
    """Targets heading north: estimates either side of 0/360 deg are a small course error."""
    estimates, truth, _ = _synthetic(200, seed=2)
    tracks = calibration.track_calibration(estimates, truth)
    assert np.abs(tracks.course_z[:20]).max() < 5
    assert (np.abs(estimates.course_sd_deg[:20]) < 10).all()


@pytest.mark.parametrize("scale, within, side", [(2.0, (chi2.cdf(0.25, 1), P1), "<"),
                                                 (0.5, (P2, chi2.cdf(16, 1)), ">")])
def test_errors_twice_too_narrow_or_too_wide_are_flagged(scale, within, side):
    """Errors twice the stated sd: 38.3 % within 1 sd, 68.3 % within 2 sd, 33 % consistent,
    mean NEES 16; half of it: 95.4 %, 99.99 %, 100 %, 1. Every per-quantity share and the
    consistency of the row and of every graded cell are outside their
    targets, on the side they miss it; the mean NEES beside its interval says low or high."""
    n = 3000
    estimates, truth, _ = _synthetic(n, seed=3, scale=scale)
    table = _rows(estimates, truth)
    row = table[table.cell_group == "all"].iloc[0]
    expected_consistent = chi2.cdf(calibration.NEES_95 / scale**2, 4)
    for q in calibration.QUANTITIES:
        for k, p in zip((1, 2), within, strict=True):
            assert abs(row[f"{q}_within_{k}sd"] - p) <= _tolerance(p, n) + 1e-9, (q, k)
            assert f"{q} within {k} sd {100 * row[f'{q}_within_{k}sd']:.1f} % {side}" \
                in row.outside
    assert abs(row.consistent - expected_consistent) <= _tolerance(expected_consistent, n) + 1e-9
    assert abs(row.mean_nees - 4 * scale**2) <= scale**2 * 4 * np.sqrt(8.0 / n)
    assert f"consistent {100 * row.consistent:.1f} % {side}" in row.outside
    graded = table[(table.cell_group != "all") & table.graded]
    assert len(graded) >= 8
    bound = 100 * calibration.CONSISTENT_TARGET[0 if side == "<" else 1]
    assert graded.outside.str.contains(rf"(?:^|; )consistent [\d.]+ % {side} {bound:g} %$").all()
    for q in calibration.QUANTITIES:  # every graded cell per quantity too, not by NEES alone
        for k in (1, 2):
            assert graded.outside.str.contains(rf"{q} within {k} sd [\d.]+ % {side}").all(), \
                (q, k)
    shown = calibration.shown_rows(table)["mean NEES (95 % if honest)"].iloc[0]
    assert shown.endswith("high" if scale > 1 else "low")


def test_an_empty_or_ungraded_cell_grades_nothing():
    estimates, truth, _ = _synthetic(50, seed=4, scale=2.0)
    row = _rows(estimates, truth).iloc[0]
    assert row.n_ok == 50 and not row.graded and row.outside == ""
    nothing = calibration.nees_figures(np.array([np.nan]))
    assert nothing["consistent"] != nothing["consistent"]  # NaN: no track, no share
    assert np.isnan(nothing["mean_nees_lo"])


@pytest.mark.parametrize("n", [1, 7, 100, 2000])
def test_the_mean_nees_interval_is_the_chi_square_one(n):
    """Against scipy's quantiles of chi-square(4 n) / n, and by Monte Carlo: the mean of n
    chi-square(4) draws lies below / above it 2.5 % of the time each (binomial tolerance)."""
    lo, hi = chi2_mean_interval(n, 4)
    np.testing.assert_allclose([lo, hi], chi2.ppf([0.025, 0.975], 4 * n) / n, rtol=1e-10)
    lo90, hi90 = chi2_mean_interval(n, 4, confidence=0.9)
    np.testing.assert_allclose([lo90, hi90], chi2.ppf([0.05, 0.95], 4 * n) / n, rtol=1e-10)
    rng = np.random.default_rng(n)
    trials = 40000
    # the sum of n chi-square(4) draws, drawn as such for small n, by its definition
    # (a sum of squared normals) checked against the gamma draw at n = 7
    means = rng.chisquare(4, (trials, n)).mean(axis=1) if n <= 100 else \
        rng.chisquare(4 * n, trials) / n
    for share in (np.mean(means < lo), np.mean(means > hi)):
        assert abs(share - 0.025) <= _tolerance(0.025, trials)
    if n == 7:
        squares = (rng.standard_normal((trials, 4 * n)) ** 2).mean(axis=1) * 4
        assert abs(np.mean((squares >= lo) & (squares <= hi)) - 0.95) <= _tolerance(0.95, trials)


def test_the_mean_nees_interval_of_no_track_is_nan():
    lo, hi = chi2_mean_interval(np.array([0, 10]), 4)
    assert np.isnan(lo[0]) and np.isnan(hi[0]) and lo[1] < 4 < hi[1]


# -- end to end ---------------------------------------------------------------------------------

N = 60


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    """The manoeuvre experiment, shrunk: 60 targets, constant velocity and manoeuvres 3 an
    hour (no wander), ``lm`` (the scenario's prior)."""
    root = tmp_path_factory.mktemp("calibration")
    args = ["experiment=bearings2d_manoeuvre", f"scenario.n_tracks={N}",
            "scenario.shard_size=30", "scenario.target.accel_psd_m2_s3=0.0",
            "estimator=lm", "parallel=serial", "progress=false",
            f"paths.data_dir={root / 'data'}", f"paths.tables_dir={root / 'tables'}"]
    run_stage_here("table", *args)
    entries = []
    for dataset in open_datasets(compose_cfg(args)):
        for run_root in sorted((root / "data" / "runs" / dataset.name).glob("[!.]*")):
            manifest, estimates = open_run(run_root)  # the runs the command made
            entries.append(RunEntry(dataset, manifest["estimator"], run_root, manifest,
                                    estimates.to_pandas(), seconds_per_track(run_root)))
    return root, entries


def _wrapped(deg):
    return (deg + 180.0) % 360.0 - 180.0


def test_the_experiment_writes_the_calibration_table(small_run):
    """Both tables written; the manoeuvre table keeps its columns and names the calibration
    table; per estimator and motion the cell ``all`` and the cells, each figure recomputed
    here from the estimators' own columns (range, course, speed now and their sd) and the
    truth file, the consistency that of the manoeuvre table."""
    root, entries = small_run
    tables = root / "tables"
    main = pd.read_csv(tables / "bearings2d_manoeuvre.csv")
    assert list(main.columns) == manoeuvre_table.COLUMNS
    assert "`bearings2d_manoeuvre-calibration.md`" in (tables / "bearings2d_manoeuvre.md") \
        .read_text()
    table = pd.read_csv(tables / "bearings2d_manoeuvre-calibration.csv", keep_default_na=False,
                        na_values=[""])
    assert list(table.columns) == calibration.COLUMNS
    text = (tables / "bearings2d_manoeuvre-calibration.md").read_text()
    assert "| estimator | motion | N | ok | within 1 sd %" in text
    assert "| estimator | motion | cell | N | ok | graded (>= 100 ok) |" in text
    assert len(entries) == 2
    for entry in entries:
        config = entry.dataset.manifest["config"]
        label = estimator_label(entry.estimator, entry.manifest["config"])
        motion = manoeuvre_table.motion_label(config)
        rows = table[(table.estimator == label) & (table.motion == motion)]
        est = entry.estimates.sort_values("track_id").reset_index(drop=True)
        truth = pd.read_parquet(entry.dataset.root / "truth.parquet").set_index("track_id") \
            .loc[est.track_id].reset_index()
        t, ox, oy = est.t_last_s, est.own_x_last_m, est.own_y_last_m
        dx = truth.x0_m + truth.vx_m_s * t - ox
        dy = truth.y0_m + truth.vy_m_s * t - oy
        true = {"range": np.hypot(dx, dy), "speed": np.hypot(truth.vx_m_s, truth.vy_m_s),
                "course": np.rad2deg(np.arctan2(truth.vx_m_s, truth.vy_m_s))}
        z = {"range": (est.range_now_m - true["range"]) / est.range_sd_m,
             "course": _wrapped(est.course_deg - true["course"]) / est.course_sd_deg,
             "speed": (est.speed_m_s - true["speed"]) / est.speed_sd_m_s}
        ok = (est.status == "ok").to_numpy()
        moving = "n_manoeuvres" in truth
        assert moving == (motion != "constant velocity")
        cells = {"all": np.ones(N, bool), "<15": true["range"] < 15e3,
                 "15-30": (true["range"] >= 15e3) & (true["range"] <= 30e3),
                 ">30": true["range"] > 30e3}
        if moving:
            cells.update({str(k): truth.n_manoeuvres == k for k in range(3)})
            cells["3+"] = truth.n_manoeuvres >= 3
            assert ((truth.n_manoeuvres > 0) == truth.manoeuvring).all()
        has_p = "p_manoeuvre" in est
        assert has_p == (entry.estimator == "lm" and moving)
        if has_p:
            p = est.p_manoeuvre
            cells.update({"<0.5": p < 0.5, "0.5-0.99": (p >= 0.5) & (p <= 0.99), ">0.99": p > 0.99})
        expected = {c: np.asarray(m, bool) for c, m in cells.items() if np.any(m)}
        assert list(rows.cell) == list(expected), (label, motion)
        for (_, row), (cell, mask) in zip(rows.iterrows(), expected.items(), strict=True):
            sel = mask & ok
            assert (row.n_tracks, row.n_ok) == (mask.sum(), sel.sum()), (label, motion, cell)
            for q in calibration.QUANTITIES:
                for k in (1, 2):
                    share = np.mean(np.abs(z[q][sel]) <= k) if sel.any() else np.nan
                    np.testing.assert_allclose(row[f"{q}_within_{k}sd"], share, rtol=1e-5,
                                               err_msg=f"{label} {motion} {cell} {q} {k}")
        all_row = rows.iloc[0]
        main_row = main[(main.estimator == label) & (main.motion == motion)].iloc[0]
        np.testing.assert_allclose(all_row.consistent, main_row.consistent, rtol=1e-5)
        assert all_row.n_ok == round(main_row.ok * N)
        if all_row.n_ok:
            lo, hi = chi2.ppf([0.025, 0.975], 4 * all_row.n_ok) / all_row.n_ok
            np.testing.assert_allclose([all_row.mean_nees_lo, all_row.mean_nees_hi], [lo, hi],
                                       rtol=1e-5)
    assert table.graded.sum() == 0 and (table.outside.isna()).all()  # 60 tracks: none graded
