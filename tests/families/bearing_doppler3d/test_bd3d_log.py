"""Hydrophone logs: missing and non-finite readings survive a round trip as missing; a log
whose model record claims more sensors than it has channels is refused naming the topic."""

import json

import numpy as np
import pytest

from tma.errors import InputError
from tma.families.bearing_doppler3d.log import (
    SCHEMA,
    read_hydrophone_log,
    topic,
    write_hydrophone_log,
)
from tma.families.bearing_doppler3d.scenario import Config, simulate_shard
from tma.io.mcap_log import Channel, LogWriter


def test_missing_readings_round_trip_and_a_missing_channel_is_refused(tmp_path):
    log, _ = simulate_shard(Config(n_tracks=6, shard_size=6, duration_s=4.0), 0)
    log.obs[1, 3, 5:9] = np.nan  # a sensor's readings missing at one epoch
    log.obs[2, :, 0:3] = np.nan  # one sensor silent for a path
    log.obs[0, 2, 0] = np.inf  # a non-finite reading is written as missing
    write_hydrophone_log(tmp_path / "h.mcap", log)
    back = read_hydrophone_log(tmp_path / "h.mcap")
    np.testing.assert_array_equal(np.isnan(back.obs), ~np.isfinite(log.obs))
    # a log with seven sensor channels whose model record claims eight sensors
    channels = [Channel(topic(i), SCHEMA) for i in range(7)]
    meta = {"tma.model": {k: json.dumps(v) for k, v in log.model.items()}}
    with LogWriter(tmp_path / "seven.mcap", channels, meta) as w:
        for i in range(7):
            w.write(topic(i), 0.0, {"t_s": 0.0, "sensor_id": i, "track_id": log.track_id,
                                    "elevation_sin": log.obs[:, 0, 3 * i],
                                    "bearing_cos": log.obs[:, 0, 3 * i + 1],
                                    "doppler_hz": log.obs[:, 0, 3 * i + 2]})
    with pytest.raises(InputError, match=r"missing topic\(s\) /hydrophones/7"):
        read_hydrophone_log(tmp_path / "seven.mcap")
