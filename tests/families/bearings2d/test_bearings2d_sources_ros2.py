"""ROS 2 MCAP bearing logs, written by mcap-ros2-support with the real message definitions,
read by ``read_mcap`` (raw arrays against what was written) and ingested (the target against
the truth of ``recorded_geometry``)."""

import re
import time

import numpy as np
import pytest
from mcap.writer import Writer as McapWriter
from mcap_ros2.writer import Writer

from tests.families.bearings2d.recorded_geometry import (
    EPOCH_NS,
    check_against_truth,
    estimate,
    ingest,
    recorded,
    source_options,
)
from tma.errors import ConfigError, InputError
from tma.io.dataset import Dataset
from tma.sources.mcap import read_mcap

# -- the ROS 2 message definitions (common_interfaces, Humble), concatenated with their
# dependencies as rosbag2 and mcap-ros2-support store them -----------------------------------

SEPARATOR = "=" * 80
TIME = "int32 sec\nuint32 nanosec"
HEADER = "builtin_interfaces/Time stamp\nstring frame_id"
NAVSATSTATUS = """int8 STATUS_NO_FIX =  -1        # unable to fix position
int8 STATUS_FIX =      0        # unaugmented fix
int8 STATUS_SBAS_FIX = 1        # with satellite-based augmentation
int8 STATUS_GBAS_FIX = 2        # with ground-based augmentation

int8 status

uint16 SERVICE_GPS =     1
uint16 SERVICE_GLONASS = 2
uint16 SERVICE_COMPASS = 4      # includes BeiDou.
uint16 SERVICE_GALILEO = 8

uint16 service"""
NAVSATFIX = """std_msgs/Header header
NavSatStatus status
float64 latitude
float64 longitude
float64 altitude
float64[9] position_covariance
uint8 COVARIANCE_TYPE_UNKNOWN = 0
uint8 COVARIANCE_TYPE_APPROXIMATED = 1
uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN = 2
uint8 COVARIANCE_TYPE_KNOWN = 3

uint8 position_covariance_type"""
XYZ = "float64 x\nfloat64 y\nfloat64 z"
QUATERNION = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1"
POSE = "Point position\nQuaternion orientation"
POSE_WITH_COVARIANCE = "Pose pose\nfloat64[36] covariance"
TWIST = "Vector3  linear\nVector3  angular"
TWIST_WITH_COVARIANCE = "Twist twist\nfloat64[36] covariance"
ODOMETRY = """std_msgs/Header header
string child_frame_id
geometry_msgs/PoseWithCovariance pose
geometry_msgs/TwistWithCovariance twist"""


def msgdef(main: str, *dependencies: tuple[str, str]) -> str:
    return "\n".join([main, *(f"{SEPARATOR}\nMSG: {name}\n{text}"
                              for name, text in dependencies)])


STAMPED = (("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME))
POSE_DEPS = (("geometry_msgs/Pose", POSE), ("geometry_msgs/Point", XYZ),
             ("geometry_msgs/Quaternion", QUATERNION))
MSGDEFS = {
    "sensor_msgs/msg/NavSatFix": msgdef(NAVSATFIX, *STAMPED,
                                        ("sensor_msgs/NavSatStatus", NAVSATSTATUS)),
    "std_msgs/msg/Float64": "float64 data",
    "geometry_msgs/msg/Vector3Stamped": msgdef("std_msgs/Header header\nVector3 vector",
                                               *STAMPED, ("geometry_msgs/Vector3", XYZ)),
    "geometry_msgs/msg/PoseStamped": msgdef("std_msgs/Header header\nPose pose", *STAMPED,
                                            *POSE_DEPS),
    "nav_msgs/msg/Odometry": msgdef(
        ODOMETRY, *STAMPED, ("geometry_msgs/PoseWithCovariance", POSE_WITH_COVARIANCE),
        *POSE_DEPS, ("geometry_msgs/TwistWithCovariance", TWIST_WITH_COVARIANCE),
        ("geometry_msgs/Twist", TWIST), ("geometry_msgs/Vector3", XYZ)),
}
LATENCY_NS = 40_000_000  # log_time = receive time, after header.stamp


def write_ros2(path, *topics):
    """``topics``: (topic, type, [(log_time_ns, message dict), ...]), written one topic after
    the other (so log times are not in order across topics)."""
    with open(path, "wb") as f:
        writer = Writer(f)
        for topic, datatype, messages in topics:
            schema = writer.register_msgdef(datatype, MSGDEFS[datatype])
            for seq, (log_time, message) in enumerate(messages):
                writer.write_message(topic, schema, message, log_time=int(log_time),
                                     sequence=seq)
        writer.finish()
    return path


def ns(t_s) -> np.ndarray:
    return EPOCH_NS + np.round(np.asarray(t_s) * 1e9).astype(np.int64)


def header(t_ns, frame="gps") -> dict:
    return {"stamp": {"sec": int(t_ns) // 10**9, "nanosec": int(t_ns) % 10**9},
            "frame_id": frame}


def navsatfix_messages(nav, status=None):
    status = np.zeros(len(nav), int) if status is None else status
    return [(t + LATENCY_NS, {"header": header(t), "status": {"status": int(s), "service": 1},
                              "latitude": lat, "longitude": lon, "altitude": 0.0,
                              "position_covariance": [0.0] * 9, "position_covariance_type": 0})
            for t, s, lat, lon in zip(ns(nav.t_s), status, nav.lat, nav.lon, strict=True)]


def float64_messages(bearings, scale=1.0):
    return [(t, {"data": b * scale}) for t, b in zip(ns(bearings.t_s), bearings.bearing_deg,
                                                     strict=True)]


def vector_messages(bearings):
    b = np.deg2rad(bearings.bearing_deg.to_numpy())
    return [(t + LATENCY_NS, {"header": header(t, "sonar"),
                              "vector": {"x": np.sin(a), "y": np.cos(a), "z": 0.0}})
            for t, a in zip(ns(bearings.t_s), b, strict=True)]


def gps_and_float64(tmp_path, rec, name="ros2.mcap", status=None):
    return write_ros2(tmp_path / name,
                      ("/gps/fix", "sensor_msgs/msg/NavSatFix",
                       navsatfix_messages(rec.navigation, status)),
                      ("/bearing", "std_msgs/msg/Float64", float64_messages(rec.bearings)))


def options(**groups):
    return source_options(groups)


def ingest_and_check(path, tmp_path, opts, labels):
    root = ingest(path, data_dir=tmp_path / "data", name=path.stem, options=opts)
    epoch = Dataset.open(root).manifest["epoch_utc_ns"]
    check_against_truth(estimate(root), t_offset_s=(epoch - EPOCH_NS) / 1e9, labels=labels)


def test_navsatfix_and_float64_bearings(tmp_path):
    rec = recorded()
    path = gps_and_float64(tmp_path, rec)
    got = read_mcap(path, options(bearing={"topic": "/bearing"}))
    nav, obs = got.navigation, got.contacts
    # header.stamp, not log_time, for the fixes; log_time for Float64 (no header)
    assert nav.epoch_utc_ns == obs.epoch_utc_ns == EPOCH_NS  # the first fix, at t = 0
    np.testing.assert_allclose(nav.t_s, rec.navigation.t_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(nav.lat_deg, rec.navigation.lat)
    np.testing.assert_array_equal(nav.lon_deg, rec.navigation.lon)
    assert nav.x_m is None and "/gps/fix (sensor_msgs/msg/NavSatFix)" in nav.source
    np.testing.assert_allclose(obs.t_s, rec.bearings.t_s, rtol=0, atol=1e-9)
    np.testing.assert_allclose(obs.values, rec.bearings.bearing_deg, rtol=0, atol=1e-9)
    assert set(obs.track) == {"/bearing"} and not obs.units_stated
    assert any("/bearing: no time stamp" in n for n in got.notes)
    ingest_and_check(path, tmp_path, {"bearing": {"topic": "/bearing"}}, {"/bearing": "T1"})


def test_vector3stamped_direction_vectors(tmp_path):
    rec = recorded()
    path = write_ros2(tmp_path / "vectors.mcap",
                      ("/gps/fix", "sensor_msgs/msg/NavSatFix",
                       navsatfix_messages(rec.navigation)),
                      ("/sonar/direction", "geometry_msgs/msg/Vector3Stamped",
                       vector_messages(rec.bearings)))
    opts = {"bearing": {"topic": "/sonar/direction", "field": "vector"}}
    obs = read_mcap(path, options(**opts)).contacts
    np.testing.assert_allclose(obs.t_s, rec.bearings.t_s, rtol=0, atol=1e-9)  # header.stamp
    wrapped = (obs.values - rec.bearings.bearing_deg + 180) % 360 - 180
    np.testing.assert_allclose(wrapped, 0, atol=1e-9)
    assert np.all((obs.values >= 0) & (obs.values < 360)) and obs.units_stated
    ingest_and_check(path, tmp_path, opts, {"/sonar/direction": "T1"})
    # the field found without bearing.field; a unit makes no sense for a vector
    auto = read_mcap(path, options(bearing={"topic": "/sonar/direction"}))
    np.testing.assert_array_equal(auto.contacts.values, obs.values)
    assert any("bearings from the field 'vector'" in n for n in auto.notes)
    with pytest.raises(ConfigError, match="direction vector, which has no units"):
        read_mcap(path, options(bearing={"topic": "/sonar/direction", "units": "deg"}))


def test_bearings_in_radians(tmp_path):
    rec = recorded()
    path = write_ros2(tmp_path / "rad.mcap",
                      ("/gps/fix", "sensor_msgs/msg/NavSatFix",
                       navsatfix_messages(rec.navigation)),
                      ("/bearing", "std_msgs/msg/Float64",
                       float64_messages(rec.bearings, np.pi / 180)))
    obs = read_mcap(path, options(bearing={"topic": "/bearing", "units": "rad"})).contacts
    np.testing.assert_allclose(obs.values, rec.bearings.bearing_deg, rtol=1e-12)
    assert obs.units_stated
    # unstated units: read as degrees, and said so (assemble's radians guard then refuses)
    unstated = read_mcap(path, options(bearing={"topic": "/bearing"}))
    np.testing.assert_allclose(unstated.contacts.values,
                               np.deg2rad(rec.bearings.bearing_deg), rtol=1e-12)
    assert not unstated.contacts.units_stated
    assert any("'data' read as degrees" in n for n in unstated.notes)
    with pytest.raises(InputError, match="look like radians. Set bearing.units=rad"):
        ingest(path, data_dir=tmp_path / "data", options={"bearing": {"topic": "/bearing"}})


@pytest.mark.parametrize("datatype", ["nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped"])
def test_local_frame_ownship(tmp_path, datatype):
    rec = recorded()
    nav = rec.navigation
    position = [{"position": {"x": x, "y": y, "z": 0.0},
                 "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
                for x, y in zip(nav.east_m, nav.north_m, strict=True)]
    if datatype == "nav_msgs/msg/Odometry":
        zero = {"x": 0.0, "y": 0.0, "z": 0.0}
        messages = [{"header": header(t, "map"), "child_frame_id": "base_link",
                     "pose": {"pose": p, "covariance": [0.0] * 36},
                     "twist": {"twist": {"linear": zero, "angular": zero},
                               "covariance": [0.0] * 36}}
                    for t, p in zip(ns(nav.t_s), position, strict=True)]
    else:
        messages = [{"header": header(t, "map"), "pose": p}
                    for t, p in zip(ns(nav.t_s), position, strict=True)]
    path = write_ros2(tmp_path / "local.mcap",
                      ("/ownship/pose", datatype,
                       [(t + LATENCY_NS, m) for t, m in zip(ns(nav.t_s), messages,
                                                            strict=True)]),
                      ("/bearing", "std_msgs/msg/Float64", float64_messages(rec.bearings)))
    got = read_mcap(path, options(bearing={"topic": "/bearing", "units": "deg"}))
    np.testing.assert_allclose(got.navigation.t_s, nav.t_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(got.navigation.x_m, nav.east_m)
    np.testing.assert_array_equal(got.navigation.y_m, nav.north_m)
    assert got.navigation.lat_deg is None
    assert any("frame 'map' taken as x east, y north" in n for n in got.notes)
    ingest_and_check(path, tmp_path, {"bearing": {"topic": "/bearing"}}, {"/bearing": "T1"})


def test_no_fix_and_nan_fixes_are_dropped_and_counted(tmp_path):
    rec = recorded()
    nav = rec.navigation.copy()
    status = np.zeros(len(nav), int)
    status[[10, 11, 12]] = -1  # STATUS_NO_FIX
    status[20] = -2  # STATUS_UNKNOWN (newer ROS 2): the default of drivers that do not set it
    nav.loc[[30, 31], "lat"] = np.nan
    path = gps_and_float64(tmp_path, rec, status=status)
    got = read_mcap(path, options(bearing={"topic": "/bearing"}))
    kept = np.setdiff1d(np.arange(len(nav)), [10, 11, 12])
    np.testing.assert_allclose(got.navigation.t_s, nav.t_s.to_numpy()[kept], atol=1e-9)
    assert got.dropped.reasons["own-ship fix flagged no fix"]["count"] == 3
    path = write_ros2(tmp_path / "nan.mcap",
                      ("/gps/fix", "sensor_msgs/msg/NavSatFix", navsatfix_messages(nav)),
                      ("/bearing", "std_msgs/msg/Float64", float64_messages(rec.bearings)))
    got = read_mcap(path, options(bearing={"topic": "/bearing"}))
    assert got.navigation.t_s.size == len(nav) - 2
    assert got.dropped.reasons["own-ship position missing or not a number"]["count"] == 2
    # every fix unusable: said, not an empty recording
    path = gps_and_float64(tmp_path, rec, "nofix.mcap", status=np.full(len(nav), -1))
    with pytest.raises(InputError, match="no usable own-ship fix on /gps/fix"):
        read_mcap(path, options(bearing={"topic": "/bearing"}))


def test_unordered_messages_are_sorted_and_duplicate_times_refused(tmp_path):
    rec = recorded()
    order = np.random.default_rng(3).permutation(len(rec.bearings))
    shuffled = [float64_messages(rec.bearings)[i] for i in order]
    path = write_ros2(tmp_path / "shuffled.mcap",
                      ("/bearing", "std_msgs/msg/Float64", shuffled),
                      ("/gps/fix", "sensor_msgs/msg/NavSatFix",
                       navsatfix_messages(rec.navigation)[::-1]))
    got = read_mcap(path, options(bearing={"topic": "/bearing"}))
    np.testing.assert_allclose(got.contacts.t_s, rec.bearings.t_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(got.contacts.values, rec.bearings.bearing_deg)
    np.testing.assert_allclose(got.navigation.t_s, rec.navigation.t_s, rtol=0, atol=1e-9)

    twice = float64_messages(rec.bearings)
    twice.insert(5, (twice[7][0], {"data": 1.0}))  # a second bearing at the 8th bearing's time
    path = write_ros2(tmp_path / "twice.mcap", ("/bearing", "std_msgs/msg/Float64", twice),
                      ("/gps/fix", "sensor_msgs/msg/NavSatFix",
                       navsatfix_messages(rec.navigation)))
    when = "2025-06-01T08:00:42.5Z"  # 0.5 + 7 * 6 s after the start
    with pytest.raises(InputError, match=f"two bearings of contact /bearing at {when}"):
        read_mcap(path, options(bearing={"topic": "/bearing"}))


def test_unset_header_stamps_fall_back_to_log_time(tmp_path):
    rec = recorded()
    messages = [(t, {**m, "header": header(0, "sonar")})
                for t, m in vector_messages(rec.bearings)]
    path = write_ros2(tmp_path / "unset.mcap",
                      ("/gps/fix", "sensor_msgs/msg/NavSatFix",
                       navsatfix_messages(rec.navigation)),
                      ("/dir", "geometry_msgs/msg/Vector3Stamped", messages))
    got = read_mcap(path, options(bearing={"topic": "/dir"}))
    np.testing.assert_allclose(got.contacts.t_s, rec.bearings.t_s + LATENCY_NS / 1e9, atol=1e-9)
    assert "/dir: header.stamp is 0 (unset) in every message: log_time used" in got.notes


def test_simulation_clock(tmp_path):
    """Stamps before 2000 are a relative clock (simulation time): no UTC epoch. With bearings
    logged on the wall clock the two cannot be related: refused."""
    rec = recorded()
    sim = [(t - EPOCH_NS, {**m, "header": header(t - EPOCH_NS - LATENCY_NS)})
           for t, m in navsatfix_messages(rec.navigation)]
    bearings = [(t - EPOCH_NS, m) for t, m in float64_messages(rec.bearings)]
    path = write_ros2(tmp_path / "sim.mcap", ("/gps/fix", "sensor_msgs/msg/NavSatFix", sim),
                      ("/bearing", "std_msgs/msg/Float64", bearings))
    got = read_mcap(path, options(bearing={"topic": "/bearing"}))
    assert got.navigation.epoch_utc_ns is None and got.contacts.epoch_utc_ns is None
    np.testing.assert_allclose(got.navigation.t_s, rec.navigation.t_s, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.contacts.t_s, rec.bearings.t_s, rtol=0, atol=1e-9)
    path = write_ros2(tmp_path / "mixed.mcap", ("/gps/fix", "sensor_msgs/msg/NavSatFix", sim),
                      ("/bearing", "std_msgs/msg/Float64", float64_messages(rec.bearings)))
    with pytest.raises(InputError, match="times of /bearing are UTC but those of /gps/fix are "
                                         "before 2000 \\(a relative clock\\)"):
        read_mcap(path, options(bearing={"topic": "/bearing"}))


def test_what_the_file_holds_and_the_option_that_selects_it(tmp_path):
    rec = recorded()
    path = gps_and_float64(tmp_path, rec)
    n_nav, n_obs = len(rec.navigation), len(rec.bearings)
    holds = (f"topics /gps/fix (sensor_msgs/msg/NavSatFix, {n_nav}), "
             f"/bearing (std_msgs/msg/Float64, {n_obs})")
    with pytest.raises(InputError) as err:
        read_mcap(path, options(), need=("navigation", "contacts"))
    assert str(err.value) == (f"{path}: no bearings selected: set bearing.topic=<topic> "
                              f"[bearing.field=data]; {holds}")
    # not needed (a navigation file): no bearings, said in a note
    nav_only = read_mcap(path, options(), need=("navigation",))
    assert nav_only.contacts is None and nav_only.navigation.t_s.size == n_nav
    with pytest.raises(InputError, match=re.escape(f"bearing.topic=/sonar: no such topic; "
                                                   f"{holds}")):
        read_mcap(path, options(bearing={"topic": "/sonar"}))
    with pytest.raises(InputError, match=r"\(std_msgs/msg/Float64\) has no field 'value' "
                                         r"\(bearing.field\); its fields: data; set bearing.fi"):
        read_mcap(path, options(bearing={"topic": "/bearing", "field": "value"}))
    with pytest.raises(InputError, match="ownship.topic=/bearing has schema 'std_msgs/msg/Floa"
                                         "t64'; own-ship is read from tma.OwnshipNavigation, "
                                         "sensor_msgs/msg/NavSatFix, foxglove.LocationFix"):
        read_mcap(path, options(ownship={"topic": "/bearing"}))
    bearings_only = write_ros2(tmp_path / "b.mcap", ("/bearing", "std_msgs/msg/Float64",
                                                     float64_messages(rec.bearings)))
    with pytest.raises(InputError, match="no own-ship navigation: own-ship is read from a topic "
                                         "of schema .*; set ownship.topic=<topic> or give "
                                         r"navigation=FILE; topics /bearing \(std_msgs/msg/Fl"):
        read_mcap(bearings_only, options(bearing={"topic": "/bearing"}),
                  need=("navigation", "contacts"))


def test_damaged_and_undecodable_files_are_one_line(tmp_path):
    rec = recorded()
    good = gps_and_float64(tmp_path, rec).read_bytes()
    opts = options(bearing={"topic": "/bearing"})
    cases = {"truncated": good[:len(good) // 2],
             "flipped": good[:300] + bytes([good[300] ^ 0xFF]) + good[301:],
             "empty": b"", "text": b"time_s,bearing_deg\n1,2\n"}
    for name, data in cases.items():
        path = tmp_path / f"{name}.mcap"
        path.write_bytes(data)
        with pytest.raises(InputError, match=f"^{path}: not a valid MCAP log") as err:
            read_mcap(path, opts)
        assert "\n" not in str(err.value)
    # a message that is not CDR of its schema (written by the plain mcap writer)
    path = tmp_path / "garbage.mcap"
    with open(path, "wb") as f:
        writer = McapWriter(f)
        writer.start(profile="ros2")
        schema = writer.register_schema("std_msgs/msg/Float64", "ros2msg", b"float64 data")
        channel = writer.register_channel("/bearing", "cdr", schema)
        writer.add_message(channel, log_time=EPOCH_NS, publish_time=EPOCH_NS, data=b"\x00\x01")
        writer.finish()
    with pytest.raises(InputError, match=f"^{path}: the message on /bearing at log time "
                                         f"{EPOCH_NS} ns does not decode as std_msgs/msg/Float64"):
        read_mcap(path, opts)


def same_recording(a, b) -> bool:
    parts = [(a.navigation, b.navigation, ("t_s", "lat_deg", "lon_deg")),
             (a.contacts, b.contacts, ("t_s", "track", "values"))]
    return all(np.array_equal(getattr(x, f), getattr(y, f)) for x, y, names in parts
               for f in names)


def fuzz(path, read, n=200, seed=2026):
    """Flip a bit or overwrite 16 bytes anywhere, ``n`` times: every read raises one-line
    InputError or gives exactly the clean recording (damage in bytes nothing reads); a
    traceback fails the test. Returns the share rejected."""
    clean = path.read_bytes()
    reference = read(path)
    rng = np.random.default_rng(seed)
    rejected = 0
    for i in range(n):
        data = bytearray(clean)
        if i % 2:
            at = int(rng.integers(len(data) - 16))
            data[at:at + 16] = rng.bytes(16)
        else:
            bit = int(rng.integers(8 * len(data)))
            data[bit // 8] ^= 1 << (bit % 8)
        damaged = path.with_name("damaged.mcap")
        damaged.write_bytes(bytes(data))
        try:
            got = read(damaged)
        except InputError as exc:
            assert "\n" not in str(exc) and str(exc).startswith(str(damaged))
            rejected += 1
            continue
        assert same_recording(got, reference), f"damage {i} read as different data"
    return rejected / n


def test_damaged_ros2_files_never_give_a_traceback_or_other_data(tmp_path):
    rec = recorded()
    rec.navigation, rec.bearings = rec.navigation.iloc[:120], rec.bearings.iloc[:20]
    path = gps_and_float64(tmp_path, rec)
    share = fuzz(path, lambda p: read_mcap(p, options(bearing={"topic": "/bearing"})))
    assert share > 0.6  # chunk and summary CRCs (mcap-ros2-support writes no data CRC)


def test_decoding_speed(tmp_path):
    """Not a limit: prints the cost per 10,000 ROS 2 messages (NavSatFix + Float64)."""
    n = 10_000
    t = np.arange(n) * 0.1
    nav = recorded().navigation.iloc[:1].reindex([0] * n).assign(t_s=t).reset_index(drop=True)
    bearings = nav.assign(bearing_deg=np.linspace(0, 359, n))
    path = write_ros2(tmp_path / "speed.mcap",
                      ("/gps/fix", "sensor_msgs/msg/NavSatFix", navsatfix_messages(nav)),
                      ("/bearing", "std_msgs/msg/Float64", float64_messages(bearings)))
    start = time.perf_counter()
    got = read_mcap(path, options(bearing={"topic": "/bearing"}))
    seconds = time.perf_counter() - start
    assert got.contacts.t_s.size == n and got.navigation.t_s.size == n
    print(f"\nROS 2: {seconds / 2 * 1e3:.0f} ms per 10k messages (NavSatFix + Float64, "
          f"{2 * n} read in {seconds:.2f} s)")
