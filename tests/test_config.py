"""Hydra composition of every config group, and clear errors for bad configs."""

import math
import re
import typing
from dataclasses import asdict, fields
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

from pipeline._common import CONF_DIR, engine, estimator_nodes, scenario_nodes
from tests.conftest import compose_cfg, run_stage_here
from tma import options
from tma.config import describe, to_plain
from tma.config_nodes import validate
from tma.errors import ConfigError
from tma.families import (
    NAMES,
    build_estimator,
    estimator_class,
    estimator_names,
    family,
    load_scenario,
)
from tma.scenario import ScenarioConfig

CONF = Path(CONF_DIR)


def _options(group):
    return sorted(p.stem for p in (CONF / group).glob("*.yaml"))


@pytest.mark.parametrize("name", NAMES)
def test_every_scenario_composes_from_its_dataclass_alone(name):
    cfg = compose_cfg([f"scenario={name}"])
    module, scenario = load_scenario(OmegaConf.to_container(cfg.scenario))
    assert module.FAMILY == scenario.family == name
    # one source of truth: the composed defaults are the dataclass's (every field, those left
    # out of hashes while at their default too), no YAML copy exists
    assert OmegaConf.to_container(cfg.scenario) == asdict(module.Config())
    assert not (CONF / "scenario").exists()


@pytest.mark.parametrize("name", estimator_names())
def test_every_estimator_composes_from_its_dataclass_alone(name):
    cfg = compose_cfg([f"estimator={name}"])
    assert cfg.estimator.name == name
    built = build_estimator(OmegaConf.to_container(cfg.estimator))
    assert OmegaConf.to_container(cfg.estimator) == to_plain(built.config)
    assert not (CONF / "estimator").exists()


@pytest.mark.parametrize("name", _options("parallel"))
def test_every_parallel_option_composes(name):
    chosen = engine(compose_cfg([f"parallel={name}"]))
    assert chosen.engine == ("dask" if name == "dask" else "joblib") and chosen.n_jobs >= 1


@pytest.mark.parametrize("name", _options("experiment"))
def test_every_experiment_composes_to_its_points(name):
    cfg = compose_cfg([f"experiment={name}"])
    assert cfg.table
    nodes = scenario_nodes(cfg)
    assert len(nodes) >= 1
    for node in nodes:
        load_scenario(node)
    for node in estimator_nodes(cfg):
        build_estimator(node)


def test_table_experiment_is_the_spec_table():
    cfg = compose_cfg(["experiment=bearings2d_table"])
    assert [n["sigma_deg"] for n in scenario_nodes(cfg)] == [0.0, 0.1, 0.2, 0.3, 0.5, 1.0]
    assert {n["n_tracks"] for n in scenario_nodes(cfg)} == {10000}
    assert [n["name"] for n in estimator_nodes(cfg)] == ["lm", "nbearings"]


def test_joblib_launcher_preset_composes():
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose("config", overrides=["hydra/launcher=parallel"], return_hydra_config=True)
    assert "joblib" in cfg.hydra.launcher._target_.lower()
    assert cfg.hydra.launcher.n_jobs == 2


def test_ingest_config_composes():
    cfg = compose_cfg(["input=x.csv"], config_name="ingest")
    assert cfg.input == "x.csv" and cfg.format == "auto"


def test_unknown_keys_wrong_types_and_names_fail_clearly():
    with pytest.raises(ConfigCompositionException, match="estimator/foo"):
        compose_cfg(["estimator=foo"])
    with pytest.raises(ConfigCompositionException, match="Could not override 'sigma'"):
        compose_cfg(["sigma=0.3"])
    cfg = compose_cfg(["+scenario.sigmaa_deg=0.3"])
    with pytest.raises(ConfigError, match="sigmaa_deg"):
        load_scenario(OmegaConf.to_container(cfg.scenario))
    cfg = compose_cfg(["scenario.sigma_deg=half"])
    with pytest.raises(ConfigError, match=r"^scenario 'bearings2d': sigma_deg must be a number "
                                          r"in \[0, 90\), got 'half'$"):
        load_scenario(OmegaConf.to_container(cfg.scenario))
    cfg = compose_cfg(["scenario.sigma_deg=-1"])
    with pytest.raises(ConfigError, match=r"sigma_deg must be in \[0, 90\)"):
        load_scenario(OmegaConf.to_container(cfg.scenario))


def test_cli_errors_are_one_clear_line(tmp_path):
    proc = run_stage_here("estimate", "estimator=kalman", f"paths.data_dir={tmp_path}",
                          check=False)
    assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1
    assert proc.stderr.startswith("error: estimator=kalman: no estimator 'kalman' (options: ")
    assert "lm" in proc.stderr and "nbearings" in proc.stderr
    proc = run_stage_here("simulate", "scenario.n_tracks=many", f"paths.data_dir={tmp_path}",
                          check=False)
    assert proc.returncode == 2
    assert "error: scenario 'bearings2d'" in proc.stderr and "Traceback" not in proc.stderr
    proc = run_stage_here("estimate", f"paths.data_dir={tmp_path}", "scenario.n_tracks=5",
                          check=False)
    assert proc.returncode == 2
    assert "python -m pipeline.simulate" in proc.stderr


def test_non_finite_values_anywhere_are_refused_naming_the_dotted_key():
    cases = [
        ({"family": "radar2d", "sigma_m": float("nan")}, r"scenario 'radar2d': sigma_m must"),
        ({"family": "radar2d", "radar_xy_m": [0.0, float("-inf")]}, r"radar_xy_m\[1\] must"),
        ({"family": "radar2d", "legs": [{"duration_s": 45.0}, {"duration_s": float("inf")}]},
         r"legs\[1\]\.duration_s must be finite"),
        ({"family": "bearing_doppler3d", "initial": {"heading_sd_rad": float("nan")}},
         r"initial\.heading_sd_rad must be finite"),
        ({"family": "bearing_doppler3d", "sensors_m": [[0.0, 0.0, float("nan")]]},
         r"sensors_m\[0\]\[2\] must be finite"),
    ]
    for node, message in cases:
        with pytest.raises(ConfigError, match=message):
            load_scenario(node)
    for name in estimator_names():  # every estimator, including the bearings-only ones
        for f in fields(estimator_class(name).Config):
            if "float" in str(f.type) and "list" not in str(f.type):
                with pytest.raises(ConfigError,
                                   match=rf"estimator '{name}': {f.name} must be finite"):
                    build_estimator({"name": name, f.name: float("nan")})
    cfg = compose_cfg(["estimator=imm", "estimator.cv_accel_psd=inf"])  # from the CLI
    with pytest.raises(ConfigError, match="cv_accel_psd must be finite"):
        build_estimator(OmegaConf.to_container(cfg.estimator))


def test_fields_declared_nonfinite_accept_inf_but_not_nan():
    from dataclasses import dataclass, field

    from tma.config_nodes import validate

    @dataclass
    class Schema:
        limit: float = field(default=float("inf"), metadata={"nonfinite": True})
        gain: float = 1.0

    assert validate(Schema, {}, "x").limit == float("inf")
    assert validate(Schema, {"limit": float("-inf")}, "x").limit == float("-inf")
    for node, key in (({"limit": float("nan")}, "limit"), ({"gain": float("inf")}, "gain")):
        with pytest.raises(ConfigError, match=f"x: {key} must be finite"):
            validate(Schema, node, "x")


@pytest.mark.parametrize("name", NAMES)
def test_every_scenario_has_the_base_fields_and_their_checks(name):
    config = family(name).scenario.Config
    assert issubclass(config, ScenarioConfig) and config().family == name
    for key, bad in (("n_tracks", 0), ("shard_size", 0), ("seed", -1), ("family", "other"),
                     ("epoch_utc", "noon")):
        with pytest.raises(ConfigError, match=rf"^scenario '{name}': {key}"):
            config(**{key: bad})


def _schemas():
    return ([(f"scenario '{n}'", family(n).scenario.Config) for n in NAMES]
            + [(f"estimator '{n}'", estimator_class(n).Config) for n in estimator_names()])


def _declared(schema, path):
    """The dataclass field at dotted ``path`` of ``schema`` (nested configs included)."""
    *parents, last = path.split(".")
    for part in parents:
        schema = type(getattr(schema(), part))
    return schema.__dataclass_fields__[last]


def _beyond(interval, field_type):
    """A value just outside each finite end of ``interval``."""
    for bound, side in ((interval.lo, -1), (interval.hi, 1)):
        if bound not in ("inf", "-inf"):
            value = float(bound) + side * max(1.0, abs(float(bound))) * 0.5
            whole = field_type is int or int in typing.get_args(field_type)
            yield (math.floor if side < 0 else math.ceil)(value) if whole else value


def _nest(parts, value):
    return value if not parts else {parts[0]: _nest(parts[1:], value)}


@pytest.mark.parametrize("where, schema", _schemas(), ids=lambda v: v if isinstance(v, str)
                         else "")
def test_every_parameter_says_what_it_is_and_refuses_what_it_does_not_allow(where, schema):
    """Declared once (``tma.config.param``): a doc for every key, and for each declared
    interval with a bound, a value beyond it refused in one line naming the key, the value
    and the interval."""
    rows = describe(schema)
    assert all(doc for *_, doc in rows), [key for key, *_, doc in rows if not doc]
    checked = 0
    for key, *_ in rows:
        if "[i]" in key:
            continue
        declared = _declared(schema, key)
        interval = declared.metadata.get("range")
        for bad in _beyond(interval, declared.type) if interval else ():
            checked += 1
            with pytest.raises(ConfigError, match=rf"^{where}: {re.escape(key)} must be "
                                                  rf".*{re.escape(str(interval))}, got "):
                validate(schema, _nest(key.split("."), bad), where)
    assert checked


def test_the_options_of_everything_are_listed(capsys):
    assert options.main([]) == 0
    text = capsys.readouterr().out
    for where, schema in _schemas():
        for key, *_ in describe(schema):
            if key not in ("family", "name"):
                assert key in text, (where, key)
    assert options.main(["nope"]) == 2
    assert capsys.readouterr().err.startswith("error: no scenario or estimator 'nope', nor "
                                              "ingest or parallel")


# -- the ingest and parallel options: declared, listed and checked as the others --------------

def _option_schemas():
    """``(what, schema, check)`` of every declared group of ingest and parallel options:
    ``check(key, value)`` builds it from one value as a command line would give it."""
    from tma.runtime.parallel import Engine, engine_from
    from tma.sources.options import options_schema, source_options

    out = []
    for name in options.ingest_families():
        reader = family(name).ingest
        out += [(f"ingest settings of {name}", reader.Settings,
                 lambda key, value, reader=reader: reader.Settings(**{key: value})),
                (f"reading options of {name}", options_schema(reader.OBSERVATION),
                 lambda key, value, reader=reader: source_options(
                     _nest(key.split("."), value), reader.OBSERVATION))]
    from tma.ais.options import TruthOptions, truth_options

    out.append(("truth options", TruthOptions, lambda key, value: truth_options(
        {"file": "ais.csv", key: value} if key != "file" else {key: value})))
    return out + [("parallel", Engine, lambda key, value: engine_from({key: value}))]


# a value not of its form, for each option declared with a form (a new one comes with its own)
NOT_OF_THE_FORM = {"bearing.topic": [], "ownship.topic": [], "csv.delimiter": "::",
                   "time.start_utc": "yesterday",
                   "nmea.date": "1.6.2025", "address": "tcp://localhost", "match": "T1",
                   "time.format": "bogus", "time.zone": "Mars/Olympus"}
WRONG_TYPE = {bool: "maybe", int: "abc", float: "abc", str: ["a", "b"]}


def _bad_values(declared):
    """``(kind, value)`` of each kind of value ``declared`` (a field) refuses: of a wrong
    type, beyond each finite end of its range, not among its choices, not of its form."""
    types = [t for t in typing.get_args(declared.type) or (declared.type,)
             if t is not type(None)]
    yield "type", WRONG_TYPE.get(types[0], {"a": 1}) if len(types) == 1 else {"a": 1}
    interval = declared.metadata.get("range")
    for bad in _beyond(interval, declared.type) if interval else ():
        yield "range", bad
    if "choices" in declared.metadata:
        yield "choices", "bogus"


def _shown(value) -> list[str]:
    return [f"{value:g}"] if isinstance(value, float) else [repr(value), str(value)]


@pytest.mark.parametrize("what, schema, check", _option_schemas(),
                         ids=lambda v: v if isinstance(v, str) else "")
def test_every_ingest_and_parallel_option_says_what_it_is_and_refuses_bad_values(what, schema,
                                                                                 check):
    """Each has a doc (with its units), and a value of each kind it refuses (a wrong type,
    beyond its range, not a choice, not of its form) is one line naming the key as the
    command line writes it (``csv.delimiter``, ``parallel.n_jobs``), the value and what is
    allowed."""
    rows = describe(schema)
    assert all(doc for *_, doc in rows), [key for key, *_, doc in rows if not doc]
    prefix = {"parallel": "parallel.", "truth options": "truth."}.get(what, "")
    kinds = set()
    for key, *_ in rows:
        declared = _declared(schema, key)
        bads = list(_bad_values(declared))
        if "form" in declared.metadata:
            bads.append(("form", NOT_OF_THE_FORM[key]))
        for kind, bad in bads:
            kinds.add(kind)
            with pytest.raises(ConfigError) as caught:
                check(key, bad)
            message = str(caught.value)
            assert "\n" not in message, message
            named = f"{prefix}{key} must be " in message or f"{prefix}{key}={bad}: " in message
            assert named, (kind, message)
            assert any(shown in message for shown in _shown(bad)), (kind, message)
    assert kinds >= {"type", "range"} | (set() if what.startswith("ingest settings") else
                                         {"form"} if what == "truth options" else
                                         {"choices", "form"}), kinds


def test_the_ingest_and_parallel_options_are_listed_with_their_declared_defaults(capsys):
    """``python -m tma.options ingest parallel`` lists every key; the ingest stage's config
    takes every ingest option from its declaration (``conf/ingest.yaml`` restates none: the
    ConfigStore's ``reading`` group), and the ``parallel`` presets set only declared keys."""
    from tma.ais.options import TruthOptions
    from tma.runtime.parallel import Engine
    from tma.sources.options import options_schema
    from tma.stages.ingest import option_groups, setting_names

    assert options.main(["ingest", "parallel"]) == 0
    text = capsys.readouterr().out
    for what, schema, _ in _option_schemas():
        for key, *_ in describe(schema):
            shown = {"parallel": "parallel.", "truth options": "truth."}.get(what, "") + key
            assert re.search(rf"^  {re.escape(shown)} ", text, re.M), (what, key)
    conf = OmegaConf.load(CONF / "ingest.yaml")
    reader = family(conf.family).ingest
    declared = {**to_plain(reader.Settings()), **to_plain(options_schema(reader.OBSERVATION)()),
                "truth": to_plain(TruthOptions())}
    assert not set(conf) & set(declared), "conf/ingest.yaml restates ingest options"
    composed = compose_cfg(["input=log.csv"], config_name="ingest")
    assert {k: OmegaConf.to_container(composed)[k] for k in declared} == declared
    assert set(option_groups(conf.family)) | set(setting_names(conf.family)) | {"truth"} \
        == set(declared)
    for name in _options("parallel"):
        preset = OmegaConf.to_container(OmegaConf.load(CONF / "parallel" / f"{name}.yaml"))
        assert set(preset) <= {f.name for f in fields(Engine)}, name
