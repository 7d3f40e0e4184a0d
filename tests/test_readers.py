"""One registry of log readers (``tma.sources.READERS``): each reader file declares its kind,
extensions, sniffing rule, options and read function, and everything else is derived. A new
format is one file plus one line: a reader written here into a temporary module, added to the
registry, reads a file of a made-up format end to end (ingest, estimate, aggregate; in Python
and as a command), with its own option checked, listed and refused where it does not apply."""

import csv
import json
import subprocess
import sys
import textwrap
from dataclasses import fields

import numpy as np
import pytest

import tma.sources
from tests.conftest import REPO
from tests.families.bearings2d.recorded_geometry import recorded
from tma.config import describe
from tma.errors import ConfigError
from tma.families.bearings2d.ingest import OBSERVATION
from tma.families.bearings2d.log import read_bearings_log
from tma.io.dataset import Dataset
from tma.sources import extensions, kinds, reader, readers, source_kind
from tma.sources.options import groups, inapplicable, options_schema, source_options
from tma.stages.ingest import ingest

# the whole of a new format: this file, and its module's name added to READERS
BRG_READER = '''
"""A made-up format: ``#BRG`` on its first line, then one row per bearing ``t x y contact
bearing`` (seconds, metres east and north, an integer id, the bearing in ``brg.units_per_deg``
units per degree)."""
from dataclasses import dataclass

import numpy as np

from tma.config import param
from tma.sources.base import Contacts, Navigation, Reader, Recording


@dataclass
class BrgOptions:
    units_per_deg: float = param(1.0, "bearing units per degree", "(0, 1e6)")


def read(path, options, *, navigation, contacts, date_hint_ns=None):
    t, x, y, track, value = np.loadtxt(path, comments="#", unpack=True, ndmin=2)
    bearing = value / options.brg.units_per_deg
    return [Recording(Navigation(t, None, str(path), x_m=x, y_m=y) if navigation else None,
                      Contacts(t, None, track.astype(np.int64), bearing, str(path))
                      if contacts else None)]


READER = Reader(kind="brg", name="a BRG file", extensions=(".brg",), read=read,
                sniff=lambda head: head.startswith(b"#BRG"),
                options=lambda observation: {"brg": BrgOptions})
'''


@pytest.fixture
def brg(tmp_path, monkeypatch):
    """The made-up reader registered (its module on the path, one line in READERS) and a
    log in its format: one contact of ``recorded_geometry``, bearings in tenths of a degree,
    in a file whose name says nothing (``log.dat``: the sniffing rule tells it)."""
    (tmp_path / "brg_reader.py").write_text(BRG_READER)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(tma.sources, "READERS", (*tma.sources.READERS, "brg_reader"))
    b = recorded(("T1",)).bearings
    rows = np.c_[b.t_s, b.east_m, b.north_m, np.full(len(b), 7), b.bearing_deg * 10]
    path = tmp_path / "log.dat"
    np.savetxt(path, rows, header="BRG", comments="#", fmt="%.10g")
    yield path, b


def test_every_kind_extension_and_option_scope_is_read_off_the_declarations():
    declared = readers()
    assert kinds() == tuple(r.kind for r in declared) == ("csv", "nmea", "mcap")
    assert extensions() == {e: r.kind for r in declared for e in r.extensions}
    schema = options_schema(OBSERVATION)
    scoped = {key for r in declared for group, part in r.options(OBSERVATION).items()
              for key in (f"{group}.{f.name}" for f in fields(part))}
    assert set(schema.kinds) == scoped  # each reader's options are its own, and only those
    assert schema.kinds["bearing.topic"] == ("mcap",) and "bearing.units" not in schema.kinds
    with pytest.raises(ConfigError, match="format must be auto, csv, nmea or mcap, got 'x'"):
        source_kind("log.csv", "x")


def test_a_new_format_is_one_file_and_one_line(brg, tmp_path):
    path, b = brg
    assert "brg" in kinds() and extensions()[".brg"] == "brg"
    assert source_kind(path) == "brg"  # its sniffing rule, whatever the name says
    assert "brg" in groups(OBSERVATION)
    assert ("brg.units_per_deg", "1", "(0, 1e6)", "bearing units per degree") in describe(
        options_schema(OBSERVATION))
    with pytest.raises(ConfigError, match="brg.units_per_deg must be in"):
        source_options({"brg": {"units_per_deg": -1}}, OBSERVATION)
    table = tmp_path / "x.csv"
    assert inapplicable(source_options({"brg": {"units_per_deg": 10}}, OBSERVATION),
                        {table: "csv"}) == (f"brg.units_per_deg=10.0 does not apply to {table} (a "
                                          "CSV table): it is an option of BRG input; leave it "
                                          "unset")
    assert inapplicable(source_options({"csv": {"delimiter": ";"}}, OBSERVATION),
                        {path: "brg"}).startswith(f"csv.delimiter=; does not apply to {path} "
                                                  "(a BRG file)")
    root = ingest(path, data_dir=tmp_path / "data", family="bearings2d",
                  options={"brg": {"units_per_deg": 10}})
    manifest = Dataset.open(root).manifest
    assert manifest["input"]["kind"] == "brg"
    assert manifest["config"]["options"]["brg"] == {"units_per_deg": 10.0}
    (shard,) = sorted(root.glob("log/*.mcap"))
    log = read_bearings_log(shard)
    assert log.track_id.tolist() == [7]
    np.testing.assert_allclose(log.t_s + (b.t_s.iloc[0] - log.t_s[0]), b.t_s)
    np.testing.assert_allclose(log.bearing_deg[0], b.bearing_deg, atol=1e-7)
    assert reader("brg").name == "a BRG file"


def test_the_new_format_through_the_command(brg, tmp_path):
    """``python -m pipeline.table input=log.dat brg.units_per_deg=10`` with the reader
    registered before the command starts: its option is a key of the command's config, the
    table is written; an option of another kind is one line."""
    path, _ = brg
    run = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(tmp_path)!r})
        import tma.sources
        tma.sources.READERS += ("brg_reader",)
        from pipeline.table import main
        sys.argv[0] = "table"
        main()
    """)
    common = [f"paths.data_dir={tmp_path / 'data'}", f"paths.tables_dir={tmp_path / 'tables'}",
              "progress=false", "parallel=serial"]
    ok = subprocess.run([sys.executable, "-c", run, f"input={path}", "brg.units_per_deg=10",
                         *common], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert ok.returncode == 0, ok.stderr
    (row,) = csv.DictReader((tmp_path / "tables" / "log-lm.csv").read_text().splitlines())
    assert (row["label"], row["status"]) == ("7", "ok")  # its one contact, estimated
    manifest = json.loads((tmp_path / "data" / "datasets" / "log" / "manifest.json").read_text())
    assert manifest["input"]["kind"] == "brg"
    bad = subprocess.run([sys.executable, "-c", run, f"input={path}", "columns.time=t",
                          "name=other", *common], cwd=REPO, capture_output=True, text=True,
                         timeout=600)
    assert bad.returncode == 2
    assert bad.stderr.strip() == (f"error: columns.time=t does not apply to {path} (a BRG "
                                  "file): it is an option of CSV input; leave it unset")
