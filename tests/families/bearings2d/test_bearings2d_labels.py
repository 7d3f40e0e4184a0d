"""Contact labels as recorders write them (issue 22, item 7): a 300-character id, a ``|``, a
newline, path separators, a topic name. Every output names a contact by a label made safe for
file names, Markdown and map topics (``tma.sources.labels.shown_labels``), long ones shortened
with a hash; the CSV and the manifest keep the id as written; checked at ingest, so that
aggregate never fails on a name (ENAMETOOLONG)."""

import hashlib
import json
import re

import pandas as pd
import pytest
from mcap.reader import make_reader

from pipeline.aggregate import aggregate_stage
from pipeline.estimate import estimate_stage
from tests.conftest import compose_cfg
from tests.families.bearings2d.recorded_geometry import ingest, iso, recorded
from tests.families.bearings2d.test_bearings2d_topics_and_options import _one_topic_per_contact
from tma.errors import ConfigError
from tma.sources.labels import MAX_SHOWN, shown_labels

LONG = "contact-" + "x" * 292  # 300 characters
AWKWARD = [LONG, "x|y", "line\nbreak", "T1/x", "/sonar/c1", "bravo 2", "T2"]


def _sha8(text):
    return hashlib.sha256(text.encode()).hexdigest()[:8]


def test_shown_labels_are_safe_short_distinct_and_keep_plain_ones():
    shown = shown_labels(AWKWARD)
    assert shown[4:] == ["sonar_c1", "bravo 2", "T2"]  # plain ones as written
    assert shown[1:4] == ["x_y", "line_break", "T1_x"]
    assert len(shown[0]) == MAX_SHOWN and shown[0].endswith("~" + _sha8(LONG))
    assert shown[0].startswith(LONG[:40])
    for s in shown:
        assert not re.search(r"[|/\\\x00-\x1f]", s) and len(s.encode()) <= MAX_SHOWN
    # labels alike once made safe are told apart by the hash of the one changed
    assert shown_labels(["a|b", "a_b", "a/b"]) == [f"a_b~{_sha8('a|b')}", "a_b",
                                                    f"a_b~{_sha8('a/b')}"]
    assert shown_labels(["", " "]) == [f"_~{_sha8('')}", f"_~{_sha8(' ')}"]


def _run(tmp_path, name, table_name=None):
    cfg = compose_cfg([f"paths.data_dir={tmp_path / 'data'}",
                       f"paths.tables_dir={tmp_path / 'tables'}", f"dataset={name}",
                       "estimator.initial_bearing_deg=null", "progress=false", "parallel=serial",
                       *([f"table={table_name}"] if table_name else [])])
    estimate_stage(cfg)
    aggregate_stage(cfg)


def test_awkward_ids_pass_ingest_and_aggregate(tmp_path):
    labels = ("T1", "T2", "T3")
    rec = recorded(labels)
    b = rec.bearings
    ids = dict(zip(labels, [LONG, "x|y", "line\nbreak"], strict=True))
    pd.DataFrame({"timestamp_utc": iso(b.t_s), "lat": b.lat, "lon": b.lon,
                  "bearing_deg": b.bearing_deg, "contact": b.track.map(ids)}).to_csv(
        tmp_path / "rec.csv", index=False)
    root = ingest(tmp_path / "rec.csv", data_dir=tmp_path / "data", name="rec")
    m = json.loads((root / "manifest.json").read_text())
    assert sorted(m["track_labels"].values()) == sorted(ids.values())  # as written
    assert sum("is shown as" in n for n in m["notes"]) == 3
    _run(tmp_path, "rec")
    tables = tmp_path / "tables"
    csv = pd.read_csv(tables / "rec-lm.csv", keep_default_na=False)
    assert sorted(csv.label) == sorted(ids.values())  # the CSV keeps them as written
    md = (tables / "rec-lm.md").read_text().splitlines()
    rows = [line for line in md if line.startswith("| ")]
    assert len(rows) == 1 + 3 and len({line.count(" | ") for line in rows}) == 1  # intact
    shown = dict(zip(ids.values(), shown_labels(list(ids.values())), strict=True))
    assert sorted(r.split(" | ")[0][2:] for r in rows[1:]) == sorted(shown.values())
    pngs = sorted(p.name for p in tables.glob("*.png"))
    assert pngs == sorted(f"rec-lm-{re.sub(r'[^A-Za-z0-9._-]', '_', s)}.png"
                          for s in shown.values())
    with open(tables / "rec-lm.mcap", "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert topics == {"/ownship/location_fix", *(f"/tma/estimate/{s}" for s in shown.values())}


def test_a_long_table_name_still_fits_its_file_names(tmp_path):
    rec = recorded(("T1",))
    b = rec.bearings
    pd.DataFrame({"time_s": b.t_s, "own_x_m": b.east_m, "own_y_m": b.north_m,
                  "bearing_deg": b.bearing_deg, "contact": LONG}).to_csv(tmp_path / "rec.csv",
                                                                          index=False)
    ingest(tmp_path / "rec.csv", data_dir=tmp_path / "data", name="rec")
    _run(tmp_path, "rec", table_name="t" * 200)
    (png,) = (tmp_path / "tables").glob("*.png")
    assert len(png.name.encode()) <= 255 and png.name.startswith("t" * 200 + "-contact-x")


def test_a_dataset_name_that_leaves_no_room_for_its_tables_is_refused_at_ingest(tmp_path):
    rec = recorded(("T1",))
    b = rec.bearings
    pd.DataFrame({"time_s": b.t_s, "own_x_m": b.east_m, "own_y_m": b.north_m,
                  "bearing_deg": b.bearing_deg}).to_csv(tmp_path / "rec.csv", index=False)
    with pytest.raises(ConfigError, match=r"name=n{10}.* is too long: its tables are named "
                                          r"<name>-<estimator>-<contact>.png .* at most \d+ "
                                          r"characters"):
        ingest(tmp_path / "rec.csv", data_dir=tmp_path / "data", name="n" * 200)
    assert not (tmp_path / "data").exists()


def test_topic_named_contacts_on_the_map_without_doubled_slashes(tmp_path):
    _, path = _one_topic_per_contact(tmp_path)
    ingest(path, data_dir=tmp_path / "data", name="rec",
           options={"bearing": {"topic": "/sonar/contact/*"}})
    _run(tmp_path, "rec")
    with open(tmp_path / "tables" / "rec-lm.mcap", "rb") as f:
        topics = sorted(c.topic for c in make_reader(f).get_summary().channels.values())
    assert topics == ["/ownship/location_fix", "/tma/estimate/sonar_contact_T1",
                      "/tma/estimate/sonar_contact_T2"]
    report = pd.read_csv(tmp_path / "tables" / "rec-lm.csv")
    assert list(report.label) == ["/sonar/contact/T1", "/sonar/contact/T2"]  # as written
    assert sorted(p.name for p in (tmp_path / "tables").glob("*.png")) == [
        "rec-lm-sonar_contact_T1.png", "rec-lm-sonar_contact_T2.png"]



