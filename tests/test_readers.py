"""One registry of log readers (``tma.sources.READERS``): each reader file declares its kind,
extensions, sniffing rule, options and read function, and everything else is derived. A new
format is one file plus one line: a reader written here into a temporary module, added to the
registry, reads a file of a made-up format end to end (ingest, estimate, aggregate; in Python
and as a command), with its own option checked, listed and refused where it does not apply."""

import csv
import importlib
import json
import re
import subprocess
import sys
import textwrap
from dataclasses import fields, is_dataclass, replace

import numpy as np
import pytest

import tma.sources
from tests.conftest import REPO
from tests.families.bearings2d.recorded_geometry import recorded
from tma.config import describe
from tma.errors import ConfigError, InputError
from tma.families.bearings2d.ingest import OBSERVATION
from tma.families.bearings2d.log import read_bearings_log
from tma.io.dataset import Dataset
from tma.sources import extensions, kinds, read_source, reader, readers, source_kind
from tma.sources.base import (
    SNIFF_BYTES,
    ReaderContractError,
    Recording,
    read_signature_fault,
)
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


def kinds_text(join: str = "or") -> str:
    """The registered kinds as messages list them (``csv, nmea or mcap``)."""
    *rest, last = kinds()
    return f"{', '.join(rest)} {join} {last}" if rest else last


def reader_faults(r) -> list[str]:
    """What of reader ``r``'s declaration breaks the contract (``tma.sources.base.Reader``,
    ``ReadLog``): empty for a conforming one. Applied to every registered reader, the
    made-up one of ``brg`` included, without naming any."""
    faults = []
    if not re.fullmatch(r"[a-z][a-z0-9_]*", r.kind):
        faults.append(f"kind {r.kind!r} is not a plain lower-case name")
    if not r.name.startswith(("a ", "an ")):
        faults.append(f"name {r.name!r} does not read 'a ...' / 'an ...' in messages")
    if not r.extensions or any(not re.fullmatch(r"\.[a-z0-9]+", e) for e in r.extensions):
        faults.append(f"extensions {r.extensions} are not lower-case '.ext'")
    if fault := read_signature_fault(r.read):
        faults.append(fault)
    if r.sniff is not None and not all(isinstance(r.sniff(h), bool | np.bool_)
                                       for h in (b"", b"\x00" * SNIFF_BYTES, b"time,x\n")):
        faults.append("sniff(head) is not True or False")
    for group, part in r.options(OBSERVATION).items():
        if not is_dataclass(part) or any("doc" not in f.metadata for f in fields(part)):
            faults.append(f"options group {group} is not a dataclass of tma.config.param")
    for what in (r.selects_contacts, r.selects_navigation):
        if what is not None and not (isinstance(what, str) and what.strip()):
            faults.append(f"selects_* {what!r}: None (the kind holds none) or the options")
    return faults


@pytest.mark.parametrize("declared", readers(), ids=lambda r: r.kind)
def test_every_registered_reader_keeps_the_contract(declared):
    assert reader_faults(declared) == []


def test_every_kind_extension_and_option_scope_is_read_off_the_declarations():
    declared = readers()
    assert len(set(kinds())) == len(declared)  # one kind a reader
    assert set(kinds()) >= {"csv", "nmea", "mcap"}  # the registry holds the shipped readers
    assert extensions() == {e: r.kind for r in declared for e in r.extensions}
    schema = options_schema(OBSERVATION)
    scoped = {key for r in declared for group, part in r.options(OBSERVATION).items()
              for key in (f"{group}.{f.name}" for f in fields(part))}
    assert set(schema.kinds) == scoped  # each reader's options are its own, and only those
    assert schema.kinds["bearing.topic"] == ("mcap",) and "bearing.units" not in schema.kinds
    with pytest.raises(ConfigError, match=f"format must be auto, {kinds_text()}, got 'x'"):
        source_kind("log.csv", "x")


def test_what_a_reader_returns_is_held_to_the_declared_type(brg, tmp_path, monkeypatch):
    """``read_source`` checks every reader's answer (``checked_recordings``): a reader that
    returns fixes out of time order, or arrays of different lengths, or no list, fails in
    one line naming it and the fault, not somewhere in the alignment."""
    path, _ = brg
    (good,) = read_source(path, "brg", source_options({}, OBSERVATION), navigation=True,
                          contacts=True)
    (tmp_path / "bad_reader.py").write_text(
        "from tma.sources.base import Reader\n"
        "ANSWER = None\n"
        "def read(path, options, *, navigation, contacts, date_hint_ns=None):\n"
        "    return ANSWER\n"
        "READER = Reader(kind='bad', name='a bad file', extensions=('.bad',), read=read)\n")
    monkeypatch.setattr(tma.sources, "READERS", (*tma.sources.READERS, "bad_reader"))
    module = importlib.import_module("bad_reader")
    nav, con = good.navigation, good.contacts
    broken = {
        "not sorted by time": [Recording(replace(nav, t_s=nav.t_s[::-1].copy()), con)],
        "contacts.values is not an array of": [Recording(nav, replace(con,
                                                                      values=con.values[1:]))],
        "not exactly one of (x_m, y_m) and (lat_deg, lon_deg)": [
            Recording(replace(nav, lat_deg=nav.x_m, lon_deg=nav.y_m), con)],
        "read returned dict": {"navigation": nav},
        "read returned an empty list": [],
    }
    for fault, answer in broken.items():
        monkeypatch.setattr(module, "ANSWER", answer)
        with pytest.raises(ReaderContractError, match=re.escape(fault)) as raised:
            read_source(path, "bad", source_options({}, OBSERVATION), navigation=True,
                        contacts=True)
        assert str(raised.value).startswith("the bad reader does not keep its contract")
    assert read_signature_fault(lambda path, options: []).startswith("read(path, options) is "
                                                                     "not read(path: ")
    # a kind that declares no option selecting the own-ship (selects_navigation None) and
    # finds none says what to do, no empty option name ("name them with , or give ...")
    monkeypatch.setattr(module, "ANSWER", [Recording(None, con)])
    with pytest.raises(InputError) as raised:
        ingest(path, data_dir=tmp_path / "data", family="bearings2d", fmt="bad")
    assert str(raised.value) == (f"{path}: no own-ship fixes found (bad); give them in a "
                                 "separate file with navigation=FILE")


def test_a_new_format_is_one_file_and_one_line(brg, tmp_path):
    path, b = brg
    assert "brg" in kinds() and extensions()[".brg"] == "brg"
    assert [reader_faults(r) for r in readers()] == [[] for _ in readers()]  # brg among them
    with pytest.raises(ConfigError, match=f"format must be auto, {kinds_text()}, got 'x'"):
        source_kind(path, "x")  # the messages list it: ..., mcap or brg
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
