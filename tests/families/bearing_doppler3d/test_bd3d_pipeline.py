"""The ``bearing_doppler3d`` table end to end: simulate, estimate (training and reusing CMNF's
artefacts), aggregate; an estimator refuses another family's dataset."""

import shutil

import pandas as pd
import pytest

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from pipeline.simulate import simulate_stage
from tests.conftest import compose_cfg
from tma.errors import ConfigError
from tma.families.bearing_doppler3d.estimators.cmnf import CMNF
from tma.io.atomic import sha256_file
from tma.io.dataset import Dataset


def test_wrong_family_and_pipeline(tmp_path):
    # serial: parallelism is not the point here (tests/test_pipeline.py checks that outputs
    # do not depend on n_jobs); 20 s paths are long enough for the divergence rule (from 10 s
    # on) and for the EKF to beat the prior mean
    common = [f"paths.data_dir={tmp_path}/data", f"paths.tables_dir={tmp_path}/tables",
              "progress=false", "parallel=serial"]
    bearings = compose_cfg(["scenario.n_tracks=10", "scenario.shard_size=10", *common])
    simulate_stage(bearings)
    with pytest.raises(ConfigError, match="'ekf' reads 'bearing_doppler3d' datasets"):
        estimate_stage(compose_cfg(["scenario.n_tracks=10", "scenario.shard_size=10",
                                    "estimator=ekf", *common]))
    cfg = compose_cfg(["experiment=bearing_doppler3d_table", "scenario.n_tracks=40",
                       "scenario.shard_size=20", "scenario.duration_s=20",
                       "estimators.cmnf.training_paths=400",
                       "estimators.prior_mean.bundle_paths=400", *common])
    simulate_stage(cfg)
    estimate_stage(cfg)
    artefacts = list((tmp_path / "data" / "artefacts").glob("cmnf-*/arrays.npz"))
    assert len(artefacts) == 2  # one per observation model, reused on the next run
    stamp = {p: p.stat().st_mtime_ns for p in artefacts}
    estimate_stage(cfg)
    assert {p: p.stat().st_mtime_ns for p in artefacts} == stamp
    dataset = Dataset.open(next(p for p in (tmp_path / "data" / "datasets").iterdir()
                                if p.name.startswith("bearing_doppler3d-doppler")))
    cmnf = CMNF.prepare({"name": "cmnf", "training_paths": 400, "training_seed": 7,
                         "pinv_rtol": 1e-12, "covariance_every": 10, "artefact": None},
                        dataset, tmp_path / "data")
    assert cmnf["artefact"]["sha256"] == sha256_file(
        tmp_path / "data" / "artefacts" / cmnf["artefact"]["key"] / "arrays.npz")
    assert "path" not in cmnf["artefact"]  # the run key must not depend on a path's spelling
    # aggregate trains nothing: without the artefacts it still reads the finished runs
    shutil.rmtree(tmp_path / "data" / "artefacts")
    aggregate_stage(cfg)
    assert not (tmp_path / "data" / "artefacts").exists()
    table = pd.read_csv(tmp_path / "tables" / "bearing_doppler3d.csv")
    assert len(table) == 8 and set(table.doppler) == {True, False}
    assert (table.training_paths.dropna() == 400).all()
    paths = sorted((tmp_path / "data" / "runs").glob("*/*/path_metrics.parquet"))
    assert len(paths) == 8
    shares = sorted(pd.read_parquet(p)["track_lost"].mean() for p in paths)
    assert shares == sorted(table.divergence_share)
    ekf = table[(table.estimator == "ekf") & table.doppler].iloc[0]
    prior = table[(table.estimator == "prior_mean") & table.doppler].iloc[0]
    assert ekf.rmse_X_T < prior.rmse_X_T and ekf.rmse_phi_T < prior.rmse_phi_T
