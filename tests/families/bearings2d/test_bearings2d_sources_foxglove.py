"""Foxglove MCAP bearing logs, written by the Foxglove SDK (``foxglove.LocationFix`` in
protobuf, bearings on a JSON-schema channel) and by mcap-protobuf-support, read by
``read_mcap`` (raw arrays against what was written) and ingested (the target against the truth
of ``recorded_geometry``)."""

import json

import foxglove
import numpy as np
import pytest
from foxglove.channels import LocationFixChannel
from foxglove.messages import LocationFix, Timestamp
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix as LocationFixPb
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from mcap_protobuf.writer import Writer as ProtobufWriter

from tests.families.bearings2d.recorded_geometry import (
    EPOCH_NS,
    check_against_truth,
    estimate,
    ingest,
    recorded,
    source_options,
)
from tests.families.bearings2d.test_bearings2d_sources_ros2 import fuzz
from tma.errors import InputError
from tma.io.dataset import Dataset
from tma.sources.mcap import read_mcap

CONTACT_SCHEMA = {"type": "object", "properties": {
    "track_id": {"type": ["integer", "string"]},
    "bearing_deg": {"type": "number", "description": "clockwise from north"}}}


def ns(t_s) -> np.ndarray:
    return EPOCH_NS + np.round(np.asarray(t_s) * 1e9).astype(np.int64)


def stamp(t_ns: int) -> Timestamp:
    return Timestamp(sec=int(t_ns) // 10**9, nsec=int(t_ns) % 10**9)


def write_foxglove(path, rec, nav_topic="/gps", bearing_topic="/contacts", timestamps=True,
                   track=lambda label: 1):
    """Own-ship as ``foxglove.LocationFix`` (protobuf) and one JSON message per bearing
    ``{"track_id": ..., "bearing_deg": ...}`` with the Foxglove SDK (log_time = the time)."""
    context = foxglove.Context()
    with foxglove.open_mcap(path, allow_overwrite=True, context=context):
        gps = LocationFixChannel(nav_topic, context=context)
        contacts = foxglove.Channel(
            bearing_topic, message_encoding="json", context=context,
            schema=foxglove.Schema(name="contact_bearing", encoding="jsonschema",
                                   data=json.dumps(CONTACT_SCHEMA).encode()))
        nav = rec.navigation
        for t, lat, lon in zip(ns(nav.t_s), nav.lat, nav.lon, strict=True):
            fix = LocationFix(timestamp=stamp(t) if timestamps else None, frame_id="gps",
                              latitude=lat, longitude=lon, altitude=0.0)
            gps.log(fix, log_time=int(t))
        for t, label, b in zip(ns(rec.bearings.t_s), rec.bearings.track,
                               rec.bearings.bearing_deg, strict=True):
            contacts.log({"track_id": track(label), "bearing_deg": b}, log_time=int(t))
    return path


def ingest_and_check(path, tmp_path, opts, labels=None):
    root = ingest(path, data_dir=tmp_path / "data", name=path.stem, options=opts)
    epoch = Dataset.open(root).manifest["epoch_utc_ns"]
    estimates = estimate(root)
    check_against_truth(estimates, t_offset_s=(epoch - EPOCH_NS) / 1e9, labels=labels)
    return estimates


def test_location_fix_and_json_bearings(tmp_path):
    rec = recorded()
    path = write_foxglove(tmp_path / "foxglove.mcap", rec)
    opts = {"bearing": {"topic": "/contacts", "field": "bearing_deg"}}
    got = read_mcap(path, source_options(opts))
    nav, obs = got.navigation, got.contacts
    assert nav.epoch_utc_ns == obs.epoch_utc_ns == EPOCH_NS
    np.testing.assert_allclose(nav.t_s, rec.navigation.t_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(nav.lat_deg, rec.navigation.lat)
    np.testing.assert_array_equal(nav.lon_deg, rec.navigation.lon)
    assert "/gps (foxglove.LocationFix)" in nav.source
    np.testing.assert_allclose(obs.t_s, rec.bearings.t_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(obs.values, rec.bearings.bearing_deg)
    assert obs.track.dtype == np.int64 and set(obs.track) == {1}
    assert not obs.units_stated  # a name ending in _deg states nothing (radians guard)
    assert "/contacts: contacts from the field 'track_id'" in got.notes
    ingest_and_check(path, tmp_path, opts, labels={"1": "T1"})


def test_our_topic_names_with_foxglove_schemas_need_no_option(tmp_path):
    """LocationFix on /ownship/navigation is read by its schema, not refused for its name."""
    rec = recorded(("T1", "T2"))
    path = write_foxglove(tmp_path / "named.mcap", rec, nav_topic="/ownship/navigation",
                          bearing_topic="/sonar/bearings", track=str)
    got = read_mcap(path, source_options({}))
    assert got.navigation.lat_deg is not None
    np.testing.assert_array_equal(got.contacts.track, rec.bearings.track)  # text labels
    np.testing.assert_array_equal(got.contacts.values, rec.bearings.bearing_deg)
    assert "bearings: /sonar/bearings (contact_bearing, 800) (bearing.topic)" in got.notes
    estimates = ingest_and_check(path, tmp_path, None)
    assert sorted(estimates.label) == ["T1", "T2"]


def test_json_arrays_one_message_per_epoch(tmp_path):
    """``{"contacts": {"track_id": [...], "bearing_deg": [...]}}``: a nested field path, arrays."""
    rec = recorded(("T1", "T2"))
    context = foxglove.Context()
    path = tmp_path / "arrays.mcap"
    epochs = rec.bearings.groupby("t_s", sort=True)
    with foxglove.open_mcap(path, context=context):
        channel = foxglove.Channel("/batch", message_encoding="json", context=context)
        for t, rows in epochs:
            ids = list(rows.track) + (["T3"] if t == 42.5 else [])  # one id too many
            channel.log({"contacts": {"track_id": ids, "bearing_deg": list(rows.bearing_deg)}},
                        log_time=int(ns(t)))
        LocationFixChannel("/gps", context=context).log(LocationFix(latitude=59.9,
                                                                    longitude=10.7))
    opts = {"bearing": {"topic": "/batch", "field": "contacts.bearing_deg"}}
    with pytest.raises(InputError, match="/batch: 'contacts.track_id' and "
                                         "'contacts.bearing_deg' differ in length in a message"):
        read_mcap(path, source_options(opts))
    with foxglove.open_mcap(path, context=context, allow_overwrite=True):
        for t, rows in epochs:
            channel.log({"contacts": {"track_id": list(rows.track),
                                      "bearing_deg": list(rows.bearing_deg)}},
                        log_time=int(ns(t)))
    got = read_mcap(path, source_options(opts), need=("contacts",))
    assert got.navigation is None
    np.testing.assert_array_equal(got.contacts.track, rec.bearings.track)
    np.testing.assert_array_equal(got.contacts.values, rec.bearings.bearing_deg)
    np.testing.assert_allclose(got.contacts.t_s, rec.bearings.t_s - 0.5, rtol=0, atol=1e-9)


def test_unset_timestamps_use_log_time_and_nan_fixes_are_dropped(tmp_path):
    rec = recorded()
    rec.navigation.loc[[3, 4], "lon"] = np.nan
    path = write_foxglove(tmp_path / "nostamp.mcap", rec, timestamps=False)
    got = read_mcap(path, source_options({"bearing": {"topic": "/contacts"}}))
    keep = np.setdiff1d(np.arange(len(rec.navigation)), [3, 4])
    np.testing.assert_allclose(got.navigation.t_s, rec.navigation.t_s.to_numpy()[keep],
                               atol=1e-9)
    assert "/gps: timestamp is 0 (unset) in every message: log_time used" in got.notes
    assert got.dropped.reasons["own-ship position missing or not a number"]["count"] == 2


def test_json_location_fix(tmp_path):
    """LocationFix in Foxglove's JSON encoding (timestamp as ``{sec, nsec}``)."""
    nav = recorded().navigation
    context = foxglove.Context()
    path = tmp_path / "json_fix.mcap"
    with foxglove.open_mcap(path, context=context):
        channel = foxglove.Channel("/fix", message_encoding="json", context=context,
                                   schema=foxglove.Schema(name="foxglove.LocationFix",
                                                          encoding="jsonschema",
                                                          data=b'{"type": "object"}'))
        for t, lat, lon in zip(ns(nav.t_s), nav.lat, nav.lon, strict=True):
            channel.log({"timestamp": {"sec": int(t) // 10**9, "nsec": int(t) % 10**9},
                         "latitude": lat, "longitude": lon}, log_time=int(t) + 10**8)
    got = read_mcap(path, source_options({}), need=("navigation",))
    np.testing.assert_allclose(got.navigation.t_s, nav.t_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(got.navigation.lon_deg, nav.lon)


def test_protobuf_writer_navigation_file(tmp_path):
    """A navigation-only file from mcap-protobuf-support with Foxglove's own LocationFix."""
    nav = recorded().navigation
    path = tmp_path / "nav.mcap"
    with open(path, "wb") as f, ProtobufWriter(f) as writer:
        for t, lat, lon in zip(ns(nav.t_s), nav.lat, nav.lon, strict=True):
            fix = LocationFixPb(latitude=lat, longitude=lon)
            fix.timestamp.FromNanoseconds(int(t))
            writer.write_message("/fix", fix, log_time=int(t) + 10**8, publish_time=int(t))
    got = read_mcap(path, source_options({}), need=("navigation",))
    assert got.contacts is None and got.navigation.epoch_utc_ns == EPOCH_NS
    np.testing.assert_allclose(got.navigation.t_s, nav.t_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(got.navigation.lat_deg, nav.lat)
    with pytest.raises(InputError, match="no bearings selected: set bearing.topic=<topic>"):
        read_mcap(path, source_options({}), need=("contacts",))


def test_undecodable_and_malformed_messages_are_one_line(tmp_path):
    rec = recorded()
    good = write_foxglove(tmp_path / "good.mcap", rec)
    schema = next(s for s in _schemas(good) if s.name == "foxglove.LocationFix")
    path = tmp_path / "garbage.mcap"
    with open(path, "wb") as f:
        writer = McapWriter(f)
        writer.start()
        sid = writer.register_schema(schema.name, schema.encoding, schema.data)
        channel = writer.register_channel("/gps", "protobuf", sid)
        writer.add_message(channel, log_time=EPOCH_NS, publish_time=EPOCH_NS, data=b"\xff\xff")
        writer.finish()
    with pytest.raises(InputError, match=f"^{path}: the message on /gps at log time {EPOCH_NS} "
                                         "ns does not decode as foxglove.LocationFix"):
        read_mcap(path, source_options({}), need=("navigation",))

    bearings = rec.bearings.bearing_deg.to_numpy()
    one_text = bearings.astype(object)
    one_text[9] = "12.5"
    rec.bearings["bearing_deg"] = one_text
    path = write_foxglove(tmp_path / "text.mcap", rec)  # one bearing as text
    with pytest.raises(InputError, match=f"^{path}: a message on /contacts does not follow its "
                                         "schema \\(expected numbers, got a string\\)$"):
        read_mcap(path, source_options({"bearing": {"topic": "/contacts"}}))
    rec.bearings["bearing_deg"] = bearings.astype(str)  # every one
    path = write_foxglove(tmp_path / "texts.mcap", rec)
    with pytest.raises(InputError, match=f"^{path}: 'bearing_deg' of /contacts holds str values, "
                                         "not numbers, arrays of numbers or direction vectors"):
        read_mcap(path, source_options({"bearing": {"topic": "/contacts"}}))


def test_damaged_foxglove_files_are_always_rejected(tmp_path):
    rec = recorded()
    rec.navigation, rec.bearings = rec.navigation.iloc[:120], rec.bearings.iloc[:20]
    path = write_foxglove(tmp_path / "small.mcap", rec)
    share = fuzz(path, lambda p: read_mcap(p, source_options({"bearing": {"topic": "/contacts"}})))
    assert share == 1.0  # the Foxglove SDK writes every CRC: each byte is covered


def _schemas(path):
    with open(path, "rb") as f:
        return list(make_reader(f).get_summary().schemas.values())
