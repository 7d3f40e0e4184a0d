"""What every command pays before it does anything: ``import pipeline.<verb>`` (Hydra's
config registry built from every family's dataclasses) loads no module that the stage does not
need, so that a re-run with nothing to compute, and each joblib worker, starts quickly. Checked
in fresh processes by the modules loaded, never by a timing. The light stand-ins for scipy.stats
give its numbers exactly, and compiled kernels are made when first used."""

import importlib.util
import json
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
HEAVY = ("pandas", "matplotlib", "scipy.stats", "scipy.special", "numba", "joblib",
         "pymap3d", "tqdm")


def _loaded(code: str) -> set[str]:
    """The heavy modules loaded (of ``HEAVY``) after running ``code`` in a fresh process."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True,
                         text=True, check=True)
    modules = set(json.loads(out.stdout.splitlines()[-1]))
    return {name for name in HEAVY if name in modules}


@pytest.mark.parametrize("verb", ["simulate", "estimate", "ingest", "aggregate", "table"])
def test_a_command_imports_nothing_heavy_it_does_not_need(verb):
    """Registering every estimator's defaults imports every estimator module: none may load
    numba, scipy, pandas or matplotlib at import (they load where they are used)."""
    assert _loaded(f"import pipeline.{verb}") == set()


# what composing a command's config needs none of (issue 32): the stages' libraries, mcap's
# writer (and the importlib.metadata it loads), Dask's event loop, and the fork server's
# multiprocessing, since --cfg, --help and --info start no worker
NOT_AT_START_UP = (*HEAVY, "scipy", "mcap.writer", "mcap_protobuf", "importlib.metadata",
                   "asyncio", "multiprocessing", "tma.ais.pairs")


@pytest.mark.parametrize("verb", ["table", "estimate"])
def test_composing_a_commands_config_loads_no_stage_library(verb):
    """``python -m pipeline.<verb> --cfg job`` as a user runs it (the start-up ``make bench``
    measures), the modules it imports read off ``-X importtime``."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", f"pipeline.{verb}",
                           "--cfg", "job"], cwd=REPO, capture_output=True, text=True, check=True)
    assert "scenario:" in proc.stdout  # the composed config
    imported = {line.rpartition("|")[2].strip() for line in proc.stderr.splitlines()
                if line.startswith("import time:")}
    assert {"pipeline._common", "tma.families.bearings2d.estimators.base"} <= imported
    assert imported.isdisjoint(NOT_AT_START_UP), sorted(imported & set(NOT_AT_START_UP))


def test_a_worker_simulates_and_estimates_a_shard_without_pandas(tmp_path):
    """A worker writes Parquet (truth, shard estimates) but never needs pandas, which
    pyarrow would import on its first ``pa.array`` or ``pq.read_table`` (0.26 s a worker)."""
    code = f"""
import os
from tma.config import to_plain
from tma.families import build_estimator
from tma.families.bearings2d.scenario import Config
from tma.io.dataset import write_manifest
from tma.stages.estimate import ShardTask, estimate_shard_group
from tma.stages.simulate import ShardTask as SimulateTask, simulate_group

root = r"{tmp_path}"
config = to_plain(Config(n_tracks=20, shard_size=20))
record, = simulate_group([SimulateTask(root, config, 0)])
shard = "log/shard-00000.mcap"
write_manifest(root, family="bearings2d", source="simulate", config=config, name="{tmp_path.name}",
               shards={{shard: {{"sha256": record["sha256"],
                                "bytes": os.path.getsize(os.path.join(root, shard))}}}},
               files={{}})
tasks = [ShardTask(root, shard, to_plain(build_estimator({{"name": n}}).config),
                   f"{{root}}/{{n}}.parquet", "key", root) for n in ("lm", "nbearings")]
assert [r["rows"] for r in estimate_shard_group(tasks)] == [20, 20]
"""
    assert "pandas" not in _loaded(code)


def test_aggregate_imports_neither_scipy_stats_nor_the_compiler():
    assert _loaded("import pipeline.aggregate\nimport tma.families.bearings2d.aggregate") <= {
        "pandas", "matplotlib", "scipy.special"}


def test_registered_defaults_are_omegaconfs_exactly():
    """Every command registers each dataclass's defaults, read off an instance instead of
    OmegaConf's structured node (8 ms each): the same values, of the same types."""
    from omegaconf import OmegaConf

    from tma.config_nodes import defaults
    from tma.families import NAMES, family

    schemas = [family(n).scenario.Config for n in NAMES] + [
        family(n).estimator_class(e).Config for n in NAMES for e in family(n).estimators]
    for schema in schemas:
        expected = OmegaConf.to_container(OmegaConf.structured(schema))
        assert repr(defaults(schema)) == repr(expected), schema.__module__


def test_defaults_of_a_dataclass_without_every_default_are_omegaconfs():
    from dataclasses import dataclass, field

    from tma.config_nodes import defaults

    @dataclass
    class Partial:
        name: str
        sizes: tuple = (1, 2)
        nested: dict = field(default_factory=lambda: {"a": [1.5]})

    assert defaults(Partial) == {"name": "???", "sizes": [1, 2], "nested": {"a": [1.5]}}


def test_a_process_skips_the_collections_of_its_shutdown():
    """``quick_exit``: at exit every object is frozen out of the collector's reach (an atexit
    handler registered before it runs after it and sees them frozen); the output is flushed."""
    code = """
import atexit, gc
atexit.register(lambda: print("frozen", gc.get_freeze_count() > 0, flush=True))
from tma.runtime.forkserver import quick_exit
quick_exit()
quick_exit()  # once per process
print("done")
"""
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                         text=True, check=True)
    assert out.stdout.split("\n")[:2] == ["done", "frozen True"]


def test_every_estimator_and_report_module_imports_without_scipy_stats_or_numba():
    code = """
from tma.families import NAMES, family
for name in NAMES:
    fam = family(name)
    fam.scenario, fam.aggregate
    for estimator in fam.estimators:
        fam.estimator_class(estimator)
"""
    assert not _loaded(code) & {"scipy.stats", "numba", "joblib"}


def test_the_scipy_special_stand_ins_are_scipy_stats_exactly():
    from scipy.stats import chi2, norm

    from tma.families.bearing_doppler3d.metrics import nees_band
    from tma.families.bearings2d.metrics import NEES_95

    assert NEES_95 == float(chi2.ppf(0.95, 4))
    for n_paths in (1, 7, 100, 10_000):
        for level in (0.9, 0.95, 0.99):
            expected = (chi2.ppf((1 - level) / 2, 6 * n_paths) / n_paths,
                        chi2.ppf((1 + level) / 2, 6 * n_paths) / n_paths)
            assert nees_band(n_paths, level=level) == expected
    from scipy.special import ndtri

    for confidence in np.linspace(0.01, 0.99, 99):
        assert ndtri(0.5 + confidence / 2) == norm.ppf(0.5 + confidence / 2)


KERNELS = """
from tma.runtime.jit import njit

@njit()
def twice(x):
    return 2.0 * x

@njit()
def quadruple(x):
    return twice(twice(x))  # a kernel calling another before either was made
"""


def test_a_kernel_is_made_when_first_used(tmp_path, monkeypatch):
    """Decorating loads no numba; the first call makes the kernel, inner kernels included,
    and a kernel pickles by reference like a function."""
    (tmp_path / "kernels_probe.py").write_text(KERNELS)
    code = (f"import sys; sys.path.insert(0, {str(tmp_path)!r})\nimport kernels_probe\n"
            "assert 'numba' not in sys.modules\n"
            "assert kernels_probe.quadruple(1.5) == 6.0\n"
            "assert 'numba' in sys.modules\n"
            "assert kernels_probe.twice.signatures  # the dispatcher's, once made\n")
    subprocess.run([sys.executable, "-c", code], cwd=REPO, check=True, env={
        **os.environ, "PYTHONPATH": str(REPO), "NUMBA_CACHE_DIR": str(tmp_path / "cache")})
    spec = importlib.util.spec_from_file_location("kernels_probe", tmp_path / "kernels_probe.py")
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "kernels_probe", module)
    spec.loader.exec_module(module)
    assert pickle.loads(pickle.dumps(module.twice)) is module.twice
    assert "numba" not in _loaded(f"import sys; sys.path.insert(0, {str(tmp_path)!r})\n"
                                  "import pickle, kernels_probe\n"
                                  "pickle.loads(pickle.dumps(kernels_probe.twice))")


def test_in_threads_keeps_item_order_and_raises_the_first_failure_in_item_order():
    """What every stage verifies (datasets, runs) is checked several files at a time: the
    results and the error must be those of the plain loop."""
    import time

    from tma.runtime.parallel import in_threads

    def check(i):
        time.sleep(0.02 * (5 - i))  # later items finish first
        if i in (2, 4):
            raise ValueError(f"item {i}")
        return i * i

    assert in_threads(check, [0, 1, 3]) == [0, 1, 9]
    with pytest.raises(ValueError, match="item 2"):
        in_threads(check, range(5))
    assert in_threads(check, []) == []
