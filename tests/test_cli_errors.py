"""Every failure a user can cause is one line on stderr and exit status 2, never a traceback.
Issue 8, items 1, 4 and 5. Each case runs the stage's Hydra entry point in this process
(``run_stage_here``); one case per verb also runs as a user would, in a new interpreter.

The read-only and full disks are real: a small tmpfs in a private mount namespace
(``unshare -m``, so nothing outside the test sees it).
"""

import shutil
import subprocess
import sys
import textwrap

import pandas as pd
import pytest

from tests.conftest import REPO, run_cli, run_stage_here
from tma.families.bearings2d.scenario import Config, simulate_shard

PY = sys.executable


def _csv(path, *, n=2, edit=None):
    log, _ = simulate_shard(Config(n_tracks=n, shard_size=n, sigma_deg=0.3, seed=5), 0)
    df = pd.DataFrame([{"time_s": t, "own_x_m": log.own_x_m[k], "own_y_m": log.own_y_m[k],
                        "bearing_deg": log.bearing_deg[i, k], "track_id": i}
                       for k, t in enumerate(log.t_s) for i in range(n)])
    if edit:
        edit(df)
    df.to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """A data dir holding one small simulated dataset, and CSV inputs."""
    root = tmp_path_factory.mktemp("cli")
    run_cli("simulate", f"paths.data_dir={root / 'data'}", "scenario.n_tracks=20",
            "scenario.shard_size=10", "progress=false", "parallel=serial")
    _csv(root / "good.csv")
    _csv(root / "t1e12.csv", edit=_set("time_s", 5, 1e12))
    _csv(root / "t1e300.csv", edit=_set("time_s", 7, 1e300))
    _csv(root / "b1e20.csv", edit=_set("bearing_deg", 3, 1e20))  # (ids are kept as text)
    return root


def _set(column, row, value):
    """An edit of one cell (CSV line ``row + 2``)."""
    def edit(df):
        df[column] = df[column].astype(float).where(df.index != row, value)
    return edit


# case: (verb, overrides (with {root} for the workspace), text the error line must contain)
CASES = {
    "name is an absolute path": ("ingest", ["input={root}/good.csv", "name={root}"],
                                 "is not a plain name"),
    "name climbs out": ("ingest", ["input={root}/good.csv", "name=../runs"], "not a plain name"),
    "dataset climbs out": ("estimate", ["dataset=../runs"], "dataset='../runs' is not a plain"),
    "table climbs out": ("aggregate", ["table=/tmp/x"], "table='/tmp/x' is not a plain name"),
    "n_jobs not a number": ("simulate", ["parallel.n_jobs=abc"], "parallel.n_jobs must be"),
    "n_jobs zero": ("estimate", ["parallel.n_jobs=0"], "parallel.n_jobs must be"),
    "force not a boolean": ("simulate", ["force=maybe"], "force must be true or false"),
    "time of 1e12 s": ("ingest", ["input={root}/t1e12.csv"], "line 7 makes the log span"),
    "time of 1e300 s": ("ingest", ["input={root}/t1e300.csv"], "line 9 makes the log span"),
    "bearing of 1e20": ("ingest", ["input={root}/b1e20.csv"],
                        "bearing_deg 1e+20 on line 5 is outside [-360, 360]"),
    "initial distance zero": ("estimate", ["estimator.initial_distance_m=0"],
                              "initial_distance_m must be in (0, 1e9), got 0"),
    "initial distance negative": ("estimate", ["estimator.initial_distance_m=-5"],
                                  "initial_distance_m must be in (0, 1e9), got -5"),
    "initial bearing nan": ("estimate", ["estimator.initial_bearing_deg=nan"],
                            "initial_bearing_deg"),
    "max_range_rel_sd negative": ("estimate", ["estimator.max_range_rel_sd=-1"],
                                  "max_range_rel_sd must be > 0, got -1"),
    "unknown dataset": ("estimate", ["dataset=nothing_here"], "no dataset at"),
    "input missing": ("ingest", ["input={root}/absent.csv"], "absent.csv: no such file"),
    # found by an adversarial review
    "unknown top-level key": ("simulate", ["+foo=1"], "unknown option(s) foo"),
    "data dir null": ("estimate", ["paths.data_dir=null"], "paths.data_dir must be a directory"),
    "grid not a mapping": ("estimate", ["grid=5"], "grid must be null or"),
    "unresolvable interpolation": ("estimate", ["estimator.max_iter=${{oc.env:TMA_NOPE}}"],
                                   "Environment variable 'TMA_NOPE' not found"),
    "negative seed": ("simulate", ["scenario.seed=-1"], "seed must be >= 0"),
    "huge n_tracks": ("simulate", ["scenario.n_tracks=1000000000000000000000000000000"],
                      "too large"),
    "nested number list": ("simulate", ["scenario=radar2d", "scenario.radar_xy_m=[[1],0]"],
                           "radar_xy_m[0] must be a number"),
    "ingest min_bearings": ("ingest", ["input={root}/good.csv", "min_bearings=abc"],
                            "min_bearings must be"),
    "ingest sigma not a number": ("ingest", ["input={root}/good.csv", "sigma_deg=abc"],
                                  "sigma_deg must be"),
}


def _assert_one_line(proc, expected):
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr + proc.stdout
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert expected in lines[0], lines[0]


# one case per verb also in a new interpreter: the ``python -m`` entry as a user runs it
IN_A_NEW_PROCESS = ("name climbs out", "unknown dataset", "negative seed", "table climbs out")


@pytest.mark.parametrize(("case", "run"), [
    *[pytest.param(case, run_stage_here, id=case) for case in sorted(CASES)],
    *[pytest.param(case, run_cli, id=f"{case} (new process)") for case in IN_A_NEW_PROCESS]])
def test_one_clear_line(workspace, case, run):
    verb, overrides, expected = CASES[case]
    overrides = [o.format(root=workspace) for o in overrides]
    before = sorted(p for p in (workspace / "data").rglob("*") if "hydra" not in p.parts)
    scenario = [] if verb == "ingest" else ["scenario.n_tracks=20", "scenario.shard_size=10"]
    args = (f"paths.data_dir={workspace / 'data'}", "progress=false",
            f"paths.tables_dir={workspace / 'tables'}", *scenario, *overrides)
    proc = run(verb, *args, check=False)
    _assert_one_line(proc, expected)
    after = sorted(p for p in (workspace / "data").rglob("*") if "hydra" not in p.parts)
    assert [p for p in after if p not in before and not p.name.endswith(".lock")] == []


needs_unshare = pytest.mark.skipif(shutil.which("unshare") is None or shutil.which("mount") is None,
                                   reason="needs unshare and mount (util-linux)")


def _in_small_disk(script: str, tmp_path) -> subprocess.CompletedProcess:
    """Run ``script`` (sh) in a private mount namespace with a 2 MiB tmpfs at $DISK."""
    disk = tmp_path / "disk"
    disk.mkdir()
    body = f"mount -t tmpfs -o size=2m tmpfs {disk} || exit 97\nDISK={disk}\n" + script
    proc = subprocess.run(["unshare", "-m", "sh", "-c", body], cwd=REPO, capture_output=True,
                          text=True, timeout=300)
    if proc.returncode == 97:
        pytest.skip("this machine does not allow mounting a tmpfs in a mount namespace")
    return proc


@needs_unshare
def test_read_only_data_dir_is_one_line(workspace, tmp_path):
    proc = _in_small_disk(textwrap.dedent(f"""
        mkdir -p $DISK/data && mount -o remount,ro $DISK || exit 97
        {PY} -m pipeline.ingest input={workspace}/good.csv paths.data_dir=$DISK/data
        """), tmp_path)
    _assert_one_line(proc, "Read-only file system (errno 30)")


@needs_unshare
def test_disk_full_is_one_line_and_keeps_the_good_dataset(workspace, tmp_path):
    """A good dataset, then the disk fills up, then ``force=true`` with a new input: one line,
    and the good dataset is byte-identical."""
    big = _csv(tmp_path / "big.csv", n=12)
    proc = _in_small_disk(textwrap.dedent(f"""
        D=$DISK/data
        {PY} -m pipeline.ingest input={workspace}/good.csv name=t paths.data_dir=$D \
            >/dev/null 2>&1 || exit 98
        (cd $D/datasets/t && find . -type f | sort | xargs sha256sum) > {tmp_path}/before
        head -c $(( $(df -k --output=avail $DISK | tail -1) * 1024 - 96 * 1024 )) /dev/zero \
            > $DISK/filler
        {PY} -m pipeline.ingest input={big} name=t force=true paths.data_dir=$D
        echo "status $?" >&2
        (cd $D/datasets/t && find . -type f | sort | xargs sha256sum) > {tmp_path}/after
        ls -a $D/datasets >&2
        """), tmp_path)
    lines = proc.stderr.strip().splitlines()
    assert lines[1] == "status 2", proc.stderr
    proc.returncode, proc.stderr = 2, lines[0] + "\n"
    _assert_one_line(proc, "No space left on device (errno 28)")
    assert (tmp_path / "before").read_text() == (tmp_path / "after").read_text()
    assert sorted(lines[2:]) == sorted([".", "..", ".t.lock", "t"])  # no partial left behind


@needs_unshare
def test_a_disk_too_full_for_hydras_own_files_is_one_line(workspace, tmp_path):
    proc = _in_small_disk(textwrap.dedent(f"""
        head -c $(( $(df -k --output=avail $DISK | tail -1) * 1024 - 24 * 1024 )) /dev/zero \
            > $DISK/filler
        {PY} -m pipeline.ingest input={workspace}/good.csv paths.data_dir=$DISK/data
        """), tmp_path)
    _assert_one_line(proc, "No space left on device (errno 28)")
