"""The last hostile inputs (issue 30): each ends accepted and right, or as one line naming the
true cause and a fix that works; in Python as the built-in kind of exception a pandas user
catches. Classes of inputs (contact ids, option values, datetimes) are fuzzed."""

import logging
import string

import numpy as np
import pandas as pd
import pytest
from hydra.core.override_parser.overrides_parser import OverridesParser
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tma
from tests.conftest import run_stage_here
from tests.test_docs import write_logs
from tma.errors import (
    ConfigError,
    ConfigTypeError,
    InputError,
    IntegrityError,
    MissingFileError,
    TmaError,
)

FUZZ = settings(max_examples=25, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    return write_logs(tmp_path_factory.mktemp("hostile"))


@pytest.fixture(scope="module")
def frame(logs):
    return pd.read_csv(logs / "nav_export.csv")


def one_line(exc) -> str:
    text = str(exc.value if hasattr(exc, "value") else exc)
    assert "\n" not in text, text
    return text


def cli(verb, *args, root):
    return run_stage_here(verb, *args, f"paths.data_dir={root / 'data'}",
                          f"paths.tables_dir={root / 'tables'}", "progress=false",
                          check=False)


def refused(proc) -> str:
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    return lines[0]


# -- the kinds of exception -------------------------------------------------------------------

def test_tma_errors_are_the_builtin_kinds_pandas_users_catch(logs):
    assert issubclass(TmaError, ValueError) and issubclass(IntegrityError, InputError)
    assert issubclass(ConfigTypeError, TypeError) and issubclass(ConfigTypeError, ValueError)
    with pytest.raises(FileNotFoundError) as missing:
        tma.read_log(logs / "no_such_log.csv")
    assert isinstance(missing.value, MissingFileError) and "no such file" in one_line(missing)
    with pytest.raises(FileNotFoundError):
        tma.open_dataset("no_such_dataset", data_dir=logs / "data")


def test_cli_still_says_each_error_in_one_line(logs, tmp_path):
    """The error policy turns the new kinds into one line, exit 2, messages unchanged."""
    line = refused(cli("ingest", f"input={logs / 'no_such_log.csv'}", root=tmp_path))
    assert line == f"error: {logs / 'no_such_log.csv'}: no such file"
    line = refused(cli("table", f"input={logs / 'nav_export.csv'}", "estimator.max_iter=0",
                       root=tmp_path))
    assert line == "error: estimator 'lm': max_iter must be >= 1, got 0"  # prefixed once


# -- the Python API checks its arguments as the command line does ------------------------------

@FUZZ
@given(sigma=st.one_of(st.booleans(), st.integers(-5, 200), st.floats(allow_nan=True),
                       st.floats(0, 2e-3), st.text(max_size=5)))
def test_estimate_checks_sigma_deg_as_ingest_does(frame, sigma):
    """One rule for both sides: ingest's declared ``sigma_deg`` in [0.001, 90), a number (a
    sigma so small that its square vanished, 1e-221, divided by zero; one below 0.001 deg
    was used as 0.001 by the motion fit)."""
    good = (isinstance(sigma, int | float) and not isinstance(sigma, bool)
            and 1e-3 <= sigma < 90)
    if good:
        used = tma.estimate(frame, sigma_deg=sigma)["sigma_used_deg"]
        np.testing.assert_allclose(used, float(sigma), rtol=1e-12)
        return
    kind = TypeError if isinstance(sigma, bool | str) else ValueError
    with pytest.raises(kind) as exc:
        tma.estimate(frame, sigma_deg=sigma)
    assert "sigma_deg must be" in one_line(exc)


def test_sigma_deg_refused_alike_by_the_command(logs, tmp_path, frame):
    for value in ("0", "true"):
        line = refused(cli("table", f"input={logs / 'nav_export.csv'}", f"sigma_deg={value}",
                           root=tmp_path))
        with pytest.raises(ValueError) as exc:
            tma.estimate(frame, sigma_deg={"0": 0, "true": True}[value])
        assert line.removeprefix("error: ") == one_line(exc)


def test_name_is_no_option_of_an_estimator(logs, tmp_path, frame):
    with pytest.raises(ValueError) as exc:
        tma.estimate(frame, estimator="nbearings", name="lm")
    assert "choose the estimator with estimator='lm'" in one_line(exc)
    with pytest.raises(ValueError) as exc:
        tma.estimate(frame, name="nbearings")
    assert "estimator='nbearings'" in one_line(exc)
    line = refused(cli("table", f"input={logs / 'nav_export.csv'}", "estimator=nbearings",
                       "estimator.name=lm", root=tmp_path))
    assert line == ("error: estimator.name=lm: name is not an option of an estimator; choose "
                    "the estimator with estimator=lm")


@pytest.mark.parametrize("where", ["input", "navigation"])
def test_a_dataframe_given_as_a_path_is_one_line(logs, frame, where):
    with pytest.raises(TypeError) as exc:
        if where == "input":
            tma.read_log(frame)
        else:
            tma.read_log(logs / "bearings.csv", navigation=frame)
    assert one_line(exc) == (f"{where} must be a file path (str or pathlib.Path), got DataFrame "
                             "(DataFrames are read by tma.Recording.from_frames(bearings, "
                             "navigation))")


def test_durations_are_relative_times_and_datetimes_are_times(frame):
    """A timedelta64 time column is read as relative time; ``time.start_utc`` given as a
    datetime with a zone dates it as the same instant written in ISO-8601 does."""
    absolute = tma.Recording.from_frames(frame)
    start = pd.Timestamp(absolute.start_utc)
    relative = frame.assign(timestamp_utc=pd.to_datetime(frame.timestamp_utc) - start)
    for when in (start.to_pydatetime(), start, start.isoformat()):
        rec = tma.Recording.from_frames(relative, time={"start_utc": when})
        assert rec.start_utc == absolute.start_utc
        pd.testing.assert_frame_equal(rec.bearings, absolute.bearings)
    undated = tma.Recording.from_frames(relative)
    assert undated.start_utc is None
    np.testing.assert_array_equal(undated.bearings.t_s, absolute.bearings.t_s)
    with pytest.raises(ValueError) as exc:  # a datetime without a zone: the zone is named
        tma.Recording.from_frames(relative, time={"start_utc": start.tz_localize(None)})
    assert "time.start_utc" in one_line(exc) and "zone" in str(exc.value)
    with pytest.raises(ValueError) as exc:  # durations are no Unix times
        tma.Recording.from_frames(relative, time={"format": "unix_s"})
    assert "durations" in one_line(exc)


def test_runs_name_unknown_families_and_recorded_runs(logs, tmp_path, caplog):
    cli("table", f"input={logs / 'nav_export.csv'}", root=tmp_path)
    with pytest.raises(ValueError) as exc:
        tma.runs(tmp_path / "data", family="nope")
    assert one_line(exc).startswith("unknown scenario family 'nope' (known: ")
    with caplog.at_level(logging.WARNING, logger="tma"), pytest.raises(ValueError) as exc:
        tma.runs(tmp_path / "data")
    assert "are of recorded logs, which have no truth" in one_line(exc)
    assert "aggregate" not in caplog.text  # never said to need aggregating


def test_estimate_of_another_family_runs_its_estimators():
    """Issue 30 (AttributeError), issue 29 item 5: a radar2d simulation is estimated by its
    family's first tracker (tests/test_api_families.py checks its numbers); a bearings2d
    estimator on it is refused naming the radar2d ones."""
    sim = tma.simulate("radar2d", n_tracks=2, shard_size=2)
    results = tma.estimate(sim)
    assert results.tma.estimator == "alphabeta" and list(results["track_id"]) == [0, 1]
    with pytest.raises(ValueError) as exc:
        tma.estimate(sim, estimator="lm")
    assert one_line(exc) == ("estimator 'lm' reads bearings2d logs, these are radar2d's: "
                             "choose one of alphabeta, fuzzy_mm, imm")


# -- contact ids are kept as written -----------------------------------------------------------

def _ids_frame(written: list) -> pd.DataFrame:
    """A log of ``len(written)`` contacts, each with its own target and 8 bearings at its own
    times, in x/y metres and relative seconds: contact k has id ``written[k]`` as given."""
    rows = []
    for k, ident in enumerate(written):
        for j in range(8):
            t = 10.0 * j + k / (len(written) + 1)
            bearing = (20.0 * k + 3.0 * j) % 360  # the contact's own bearings
            rows.append({"time_s": t, "own_x_m": 5.0 * t, "own_y_m": 0.0,
                         "bearing_deg": bearing, "contact": ident})
    frame = pd.DataFrame(rows).sort_values("time_s", kind="stable").reset_index(drop=True)
    frame["contact"] = pd.Series(list(frame["contact"]), dtype=object)
    return frame


SPELLINGS = st.one_of(
    st.integers(-50, 50).map(str),
    st.text(string.ascii_letters + string.digits + "._-", min_size=1, max_size=4),
    st.sampled_from(["7", " 7", "7 ", " 7 ", "07", "007", "7.0", "1e3", "1000", "NA", "T1",
                     " T1", "T1 "]),
)


def _contacts_of(rec, frame) -> dict:
    """written id -> the bearings read for it (by the contact each row went to)."""
    got = rec.bearings.sort_values("t_s", kind="stable").reset_index(drop=True)
    assert len(got) == len(frame)
    out = {}
    for ident, label in zip(frame["contact"], got["label"], strict=True):
        out.setdefault(ident, set()).add(label)
    return out


@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(written=st.lists(SPELLINGS, min_size=2, max_size=5, unique=True))
def test_ids_are_kept_as_written_and_alike_ids_are_said(written, tmp_path, caplog):
    """Whatever the spellings (spaces around, leading zeros, exponents, NA), every id written
    differently is its own contact, in a CSV file and in a DataFrame; each of them gets all
    its own bearings and no other's; ids alike but written differently are named in a
    warning."""
    frame = _ids_frame(written)
    path = tmp_path / "ids.csv"
    frame.to_csv(path, index=False)
    for read in (lambda: tma.Recording.from_frames(frame), lambda: tma.read_log(path)):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="tma"):
            rec = read()
        contacts = _contacts_of(rec, frame)
        assert all(len(labels) == 1 for labels in contacts.values())  # no contact split
        labels = [next(iter(contacts[w])) for w in written]
        assert len(set(labels)) == len(written)  # and none merged
        alike = {}
        for w in written:
            alike.setdefault(_meaning(w), []).append(w)
        said = [n for n in rec.notes if "alike but written differently" in n]
        assert bool(said) == any(len(g) > 1 for g in alike.values())
        if said:
            assert "alike but written differently" in caplog.text


def _meaning(written: str):
    try:
        return float(written.strip())
    except ValueError:
        return written.strip()


def test_space_and_number_spellings_of_one_id_in_a_dataframe(frame, caplog):
    """The issue's cases: ' 7' beside '7' (two targets' bearings at the same times) and an
    object column holding int 7 and float 7.0: two contacts each, and said."""
    for ids in ({"T1": " 7", "T2": "7"}, {"T1": 7, "T2": 7.0}):
        mixed = frame.assign(contact=pd.Series([ids[c] for c in frame.contact], dtype=object))
        with caplog.at_level(logging.WARNING, logger="tma"):
            rec = tma.Recording.from_frames(mixed)
        assert sorted(rec.bearings.label.unique()) == sorted(str(v) for v in ids.values())
        assert "alike but written differently" in caplog.text
        per_label = rec.bearings.groupby("label").bearing_deg.apply(sorted)
        for contact, ident in ids.items():  # (turned onto the plane's north: < 0.2 deg)
            np.testing.assert_allclose(per_label[str(ident)],
                                       sorted(frame.bearing_deg[frame.contact == contact]),
                                       rtol=0, atol=0.2)


# -- the command line --------------------------------------------------------------------------

def test_a_device_is_no_log_file(tmp_path):
    line = refused(cli("ingest", "input=/dev/null", root=tmp_path))
    assert line == ("error: /dev/null: not a regular file (a character device), which tma "
                    "cannot read twice as its readers do; write the log to a file and give "
                    "its path")


PARSER = OverridesParser.create()
HYDRA_TEXT = st.text(st.characters(blacklist_categories=("Cs", "Cc", "Zs", "Zl", "Zp")),
                     min_size=1, max_size=12)


@FUZZ
@given(value=HYDRA_TEXT)
def test_any_text_survives_the_command_line(value):
    """Option values as one text: what the command line writes (``override_text``, e.g. in a
    suggestion) Hydra reads back as that text, and a ``key=value`` that Hydra cannot read
    unquoted (non-ASCII, ``~``, ``#``...) is quoted for it (``_readable``); one with Hydra's
    own syntax is left as written."""
    from hydra.errors import HydraException

    from pipeline._common import _SYNTAX, _readable
    from tma.plan.points import override_text

    assert PARSER.parse_override(override_text("name", value)).value() == value
    arguments = _readable([f"name={value}"])
    if _SYNTAX.search(value):
        assert arguments == [f"name={value}"]
        return
    try:
        expected = PARSER.parse_override(f"name={value}").value()  # Hydra's own reading
    except HydraException:
        expected = value
    read = PARSER.parse_override(arguments[0]).value()
    # (Hydra reads nan, NaN, NAN... as the float NaN, which equals nothing, itself included)
    assert read == expected or (isinstance(read, float) and np.isnan(read)
                                and isinstance(expected, float) and np.isnan(expected))


def test_non_ascii_paths_and_values_are_read(logs, tmp_path):
    folder = tmp_path / "über"
    folder.mkdir()
    (folder / "journal_é.csv").write_bytes((logs / "nav_export.csv").read_bytes())
    proc = cli("ingest", f"input={folder / 'journal_é.csv'}", "name=journal", root=tmp_path)
    assert proc.returncode == 0, proc.stderr
    proc = cli("ingest", str(folder / "journal_é.csv"), "name=journal2", root=tmp_path)
    assert proc.returncode == 0, proc.stderr
    line = refused(cli("ingest", f"input={logs / 'nav_export.csv'}", "columns.lon=Länge",
                       "name=x", root=tmp_path))
    assert "columns.lon=Länge: no such column" in line  # read, and named as given
    line = refused(cli("ingest", f"input={logs / 'nav_export.csv'}", "columns.lon=[Länge]",
                       root=tmp_path))
    assert "Hydra reads 'ä' only inside quotes" in line


def test_mcap_units_stated_wrongly_name_the_option(logs, tmp_path):
    line = refused(cli("ingest", f"input={logs / 'run.mcap'}", "bearing.topic=/bearing",
                       "bearing.field=data", "bearing.units=rad", root=tmp_path))
    assert "bearing.units=rad" in line and "set bearing.units=deg" in line
    assert "does not follow its schema" not in line


@pytest.mark.parametrize("verb", ["estimate", "aggregate"])
def test_a_log_given_to_a_dataset_stage_points_to_ingest(logs, tmp_path, verb):
    line = refused(cli(verb, str(logs / "nav_export.csv"), root=tmp_path))
    assert f"python -m pipeline.ingest input={logs / 'nav_export.csv'}" in line
    assert f"python -m pipeline.table input={logs / 'nav_export.csv'}" in line
    assert "dataset=" + str(logs) not in line


@FUZZ
@given(value=st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6))
def test_a_float_for_a_whole_number_is_named_with_its_fix(value):
    from tma.families import build_estimator

    with pytest.raises(TypeError) as exc:
        build_estimator({"name": "lm", "max_iter": value})
    assert f"got the float {value!r}" in one_line(exc)
    if value.is_integer():
        assert one_line(exc).endswith(f"; write {int(value)}")


def test_max_iter_1e3_says_what_it_is(logs, tmp_path):
    line = refused(cli("table", f"input={logs / 'nav_export.csv'}", "estimator.max_iter=1e3",
                       root=tmp_path))
    assert line == ("error: estimator 'lm': max_iter must be a whole number >= 1, got the "
                    "float 1000.0; write 1000")


def test_options_a_log_table_would_ignore_are_refused(logs, tmp_path):
    line = refused(cli("table", f"input={logs / 'nav_export.csv'}", "dataset=other",
                       root=tmp_path))
    assert "give input=FILE [name=NAME] or dataset=NAME, not both" in line
    line = refused(cli("table", f"input={logs / 'nav_export.csv'}", "table_kind=benchmark",
                       root=tmp_path))
    assert "nav_export is a recorded log (no truth)" in line and "drop table_kind=" in line


def test_config_errors_keep_one_prefix():
    """A check's own ConfigError (a ValueError now) is not wrapped again by ``validate``."""
    from tma.families import build_estimator

    with pytest.raises(ConfigError) as exc:
        build_estimator({"name": "last_leg", "max_iter": 0})
    assert one_line(exc) == "estimator 'last_leg': max_iter must be >= 1, got 0"
