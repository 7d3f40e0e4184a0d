"""Several bearing topics and options that must apply (issue 22, item 3): ``bearing.topic``
takes a list and a glob, each matching topic a contact labelled by its topic name (no doubled
slash in the map topic); an option that does not apply to the input's kind is refused in one
line; ``origin.*`` must lie within ``origin.max_distance_km`` of the own-ship fixes."""

import json

import numpy as np
import pandas as pd
import pytest

from tests.conftest import run_stage_here
from tests.families.bearings2d.recorded_geometry import (
    ORIGIN,
    check_against_truth,
    estimate,
    ingest,
    iso,
    recorded,
    source_options,
)
from tests.families.bearings2d.test_bearings2d_sources_nmea import write_nmea
from tests.families.bearings2d.test_bearings2d_sources_ros2 import (
    float64_messages,
    navsatfix_messages,
    write_ros2,
)
from tma.errors import ConfigError, InputError
from tma.sources.mcap import read_mcap


def _one_topic_per_contact(tmp_path, name="per_contact.mcap"):
    """A recorder that writes each contact on its own topic, /sonar/contact/<label>."""
    rec = recorded(("T1", "T2", "T3"))
    b = rec.bearings
    return rec, write_ros2(tmp_path / name,
                           ("/gps/fix", "sensor_msgs/msg/NavSatFix",
                            navsatfix_messages(rec.navigation)),
                           *((f"/sonar/contact/{label}", "std_msgs/msg/Float64",
                              float64_messages(b[b.track == label])) for label in ("T1", "T2")),
                           ("/sonar/other", "std_msgs/msg/Float64",
                            float64_messages(b[b.track == "T3"])))


@pytest.mark.parametrize("topic", ["/sonar/contact/*", ["/sonar/contact/T1", "/sonar/contact/T2"],
                                   ["/sonar/contact/T?", "/sonar/contact/T1"]])
def test_several_topics_each_a_contact(tmp_path, topic):
    rec, path = _one_topic_per_contact(tmp_path)
    got = read_mcap(path, source_options({"bearing": {"topic": topic}}))
    b = rec.bearings[rec.bearings.track != "T3"]
    expected = b.assign(track="/sonar/contact/" + b.track).sort_values(["t_s", "track"])
    np.testing.assert_array_equal(got.contacts.track, expected.track)
    np.testing.assert_array_equal(got.contacts.values, expected.bearing_deg)
    root = ingest(path, data_dir=tmp_path / "data", options={"bearing": {"topic": topic}})
    est = estimate(root)
    assert sorted(est.label) == ["/sonar/contact/T1", "/sonar/contact/T2"]
    check_against_truth(est, t_offset_s=0.5, labels={"/sonar/contact/T1": "T1",
                                                     "/sonar/contact/T2": "T2"})


def test_a_topic_pattern_that_matches_nothing_lists_the_topics(tmp_path):
    _, path = _one_topic_per_contact(tmp_path)
    with pytest.raises(InputError, match=r"bearing.topic=/sonar/contact/X\*: no topic matches; "
                                         r"topics /gps/fix"):
        read_mcap(path, source_options({"bearing": {"topic": "/sonar/contact/X*"}}))
    with pytest.raises(InputError, match=r"bearing.topic=/sonar/none: no such topic"):
        read_mcap(path, source_options({"bearing": {"topic": ["/sonar/contact/T1",
                                                              "/sonar/none"]}}))
    with pytest.raises(ConfigError, match="bearing.topic must be a topic, a pattern or a list of "
                                          "them, got"):
        source_options({"bearing": {"topic": [{"a": 1}]}})


# -- options that do not apply ---------------------------------------------------------------

def _csv(tmp_path):
    rec = recorded(("T1",))
    b = rec.bearings
    pd.DataFrame({"timestamp_utc": iso(b.t_s), "lat": b.lat, "lon": b.lon,
                  "bearing_deg": b.bearing_deg}).to_csv(tmp_path / "rec.csv", index=False)
    return rec, tmp_path / "rec.csv"


@pytest.mark.parametrize("options, message", [
    ({"bearing": {"topic": 123}}, "bearing.topic=123 does not apply to {csv} (a CSV table): it "
                                  "is an option of MCAP input; leave it unset"),
    ({"bearing": {"field": "data"}}, "bearing.field=data does not apply to {csv}"),
    ({"ownship": {"topic": "/gps"}}, "ownship.topic=/gps does not apply to {csv}"),
    ({"nmea": {"date": "2025-06-01"}}, "nmea.date=2025-06-01 does not apply to {csv} (a CSV "
                                       "table): it is an option of NMEA input"),
])
def test_an_option_for_another_kind_of_input_is_refused(tmp_path, options, message):
    _, path = _csv(tmp_path)
    with pytest.raises(ConfigError, match=message.format(csv=path).replace("(", r"\(")
                       .replace(")", r"\)")):
        ingest(path, data_dir=tmp_path / "data", options=options)
    assert not (tmp_path / "data").exists()


def test_options_of_the_navigation_file_kind_apply(tmp_path):
    """nmea.date with NMEA navigation, columns.* with a CSV input: accepted; csv.* with an
    MCAP only: refused."""
    rec = recorded(("T1",))
    b = rec.bearings
    pd.DataFrame({"t": iso(b.t_s), "bearing_deg": b.bearing_deg}).to_csv(
        tmp_path / "brg.csv", index=False)
    nav = write_nmea(tmp_path / "gps.nmea", rec.navigation)
    ingest(tmp_path / "brg.csv", navigation=nav, data_dir=tmp_path / "data",
           options={"nmea": {"date": "2025-06-01"}, "columns": {"time": "t"}})
    _, path = _one_topic_per_contact(tmp_path)
    with pytest.raises(ConfigError, match=r"csv.delimiter=; does not apply to .*per_contact.mcap "
                                          r"\(an MCAP log\): it is an option of CSV input"):
        ingest(path, data_dir=tmp_path / "d2", options={"csv": {"delimiter": ";"},
                                                        "bearing": {"topic": "/sonar/other"}})


def test_on_the_command_line_it_is_one_line(tmp_path):
    _, path = _csv(tmp_path)
    proc = run_stage_here("ingest", f"input={path}", "bearing.topic=123",
                          f"paths.data_dir={tmp_path / 'data'}", "progress=false", check=False)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("error: bearing.topic=123 does not apply to")


# -- the origin near the fixes ---------------------------------------------------------------

def test_an_origin_far_from_every_fix_is_refused(tmp_path):
    rec, path = _csv(tmp_path)
    far = {"lat": ORIGIN[0] + 2.0, "lon": ORIGIN[1]}  # 222 km north
    with pytest.raises(InputError, match=r"origin.lat/origin.lon = 61.9, 10.7 lies 22\d km from "
                                         r"the nearest own-ship fix \(at most "
                                         r"origin.max_distance_km = 100\)"):
        ingest(path, data_dir=tmp_path / "data", options={"origin": far})
    root = ingest(path, data_dir=tmp_path / "data", name="near",
                  options={"origin": {**far, "max_distance_km": 300}})
    m = json.loads((root / "manifest.json").read_text())
    assert m["origin_deg"] == [far["lat"], far["lon"]]
    # own-ship in local metres: the fixes' distance from their 0, 0
    b = rec.bearings
    pd.DataFrame({"time_s": b.t_s, "x": b.east_m + 5e5, "y": b.north_m,
                  "bearing_deg": b.bearing_deg}).to_csv(tmp_path / "xy.csv", index=False)
    with pytest.raises(InputError, match=r"lies 50\d km from the nearest own-ship fix"):
        ingest(tmp_path / "xy.csv", data_dir=tmp_path / "data",
               options={"origin": {"lat": 59.9, "lon": 10.7}})
    with pytest.raises(ConfigError, match="origin.max_distance_km must be"):
        ingest(path, data_dir=tmp_path / "data", options={"origin": {"max_distance_km": 0}})

