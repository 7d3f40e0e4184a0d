"""MCAP and Parquet round trips, atomic writes and MCAP error handling."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from tma.errors import InputError
from tma.families.bearings2d.log import CHANNELS, read_bearings_log, write_bearings_log
from tma.families.bearings2d.scenario import Config, simulate_shard
from tma.io.atomic import atomic_path, write_parquet_atomic
from tma.io.mcap_log import LogWriter


def _small_log():
    log, truth = simulate_shard(Config(n_tracks=7, shard_size=7, sigma_deg=0.3), 0)
    return log, truth


def test_mcap_round_trip_is_exact(tmp_path):
    log, _ = _small_log()
    log.bearing_deg[2, 5:9] = np.nan  # gaps: a contact missing at some epochs
    path = tmp_path / "log.mcap"
    n = write_bearings_log(path, log, {"tma.dataset": {"family": "bearings2d"}})
    assert n == 2 * log.t_s.size
    back = read_bearings_log(path)
    np.testing.assert_array_equal(back.t_s, log.t_s)
    np.testing.assert_array_equal(back.own_x_m, log.own_x_m)
    np.testing.assert_array_equal(back.track_id, log.track_id)
    np.testing.assert_array_equal(back.bearing_deg, log.bearing_deg)  # NaN in the same places


def test_mcap_is_a_genuine_log_for_plain_readers(tmp_path):
    log, _ = _small_log()
    path = tmp_path / "log.mcap"
    write_bearings_log(path, log)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == {"/ownship/navigation", "/sonar/bearings"}
        schema = summary.schemas[topics["/sonar/bearings"].schema_id]
        assert schema.encoding == "jsonschema" and schema.name == "tma.BearingBatch"
        assert "clockwise from north" in json.loads(schema.data)["description"]
        assert "convention" in topics["/sonar/bearings"].metadata
        msgs = list(reader.iter_messages(topics=["/sonar/bearings"]))
    assert len(msgs) == log.t_s.size
    first = json.loads(msgs[0][2].data)
    assert first["track_id"] == log.track_id.tolist()
    assert msgs[3][2].log_time == int(log.t_s[3] * 1e9)


def test_mcap_bytes_are_reproducible(tmp_path):
    log, _ = _small_log()
    write_bearings_log(tmp_path / "a.mcap", log)
    write_bearings_log(tmp_path / "b.mcap", log)
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()


def test_parquet_round_trip(tmp_path):
    _, truth = _small_log()
    write_parquet_atomic(tmp_path / "truth.parquet", truth)
    assert pq.read_table(tmp_path / "truth.parquet").equals(truth)


def test_truncated_and_non_mcap_files_are_rejected(tmp_path):
    log, _ = _small_log()
    path = tmp_path / "log.mcap"
    write_bearings_log(path, log)
    data = path.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="cut.mcap"):
        read_bearings_log(tmp_path / "cut.mcap")
    (tmp_path / "text.mcap").write_text("time_s,bearing_deg\n0,1\n")
    with pytest.raises(InputError, match="not a valid MCAP"):
        read_bearings_log(tmp_path / "text.mcap")
    with pytest.raises(InputError, match="no such file"):
        read_bearings_log(tmp_path / "absent.mcap")


def test_mcap_without_expected_topics(tmp_path):
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/imu", "json", sid)
        w.add_message(cid, 0, b"{}", 0)
        w.finish()
    with pytest.raises(InputError, match=r"missing topic\(s\) /ownship/navigation, "
                                         r"/sonar/bearings; the log has: /imu"):
        read_bearings_log(path)


def test_ownship_is_interpolated_to_bearing_epochs(tmp_path):
    # Navigation at 1 Hz, bearings every 4 s offset by 0.5 s, as another tool might log them.
    path = tmp_path / "nav.mcap"
    with LogWriter(path, CHANNELS) as w:
        for t in np.arange(0.0, 41.0):
            w.write("/ownship/navigation", t, {"t_s": t, "x_m": 3.0 * t, "y_m": -2.0 * t})
        for t in np.arange(0.5, 40.0, 4.0):
            w.write("/sonar/bearings", t, {"t_s": t, "track_id": [4, 9],
                                            "bearing_deg": [10.0, 350.0]})
    back = read_bearings_log(path)
    np.testing.assert_allclose(back.t_s, np.arange(0.5, 40.0, 4.0))
    np.testing.assert_allclose(back.own_x_m, 3.0 * back.t_s, rtol=1e-14)
    np.testing.assert_allclose(back.own_y_m, -2.0 * back.t_s, rtol=1e-14)
    np.testing.assert_array_equal(back.track_id, [4, 9])


def test_atomic_path_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.bin"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("killed")
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []
