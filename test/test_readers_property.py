"""Property-based tests (hypothesis) of the readers of our own window files.

- Any records (odometry and IMU, any float values including NaN and infinities, any order of stamps,
  repeated stamps) round-trip exactly through json-xz and bag-lz4.
- Slowly varying columns (json-xz writes them as exact decimal differences) round-trip bit for bit; with a
  precision (lossy json-xz) every rounded float is within half a step of the original.
- A valid file with bytes flipped or cut off either gives ValueError naming the path, or reads back exactly
  what was written: never another exception, never a silently different result.
"""
import math
import os
import tempfile

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from cc_log.base import msg_codec
from cc_log.storage.log_format import Format, read_window, write_window
from cc_log.base.records import LogWindow, Record, Trigger

pytest.importorskip('rosbag')
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
stamps = st.floats(min_value=1.0, max_value=2e9, allow_nan=False, allow_infinity=False)


@st.composite
def records(draw, sorted_per_topic=False):
    n = draw(st.integers(1, 25))
    out = []
    base = draw(stamps)
    for i in range(n):
        stamp = base + draw(st.floats(-5.0, 5.0))  # out of order, repeated (0.0 offsets) allowed
        stamp = max(stamp, 0.5)
        if draw(st.booleans()):
            msg = Odometry()
            msg.header.seq = i
            msg.header.frame_id = draw(st.sampled_from(['odom', '', 'o\u00e9']))
            msg.pose.pose.position.x = draw(floats)
            msg.twist.twist.linear.x = draw(floats)
            msg.pose.covariance = [draw(floats)] + [0.0] * 35
            topic = '/odom'
        else:
            msg = Imu()
            msg.header.seq = i
            msg.linear_acceleration.z = draw(floats)
            msg.angular_velocity_covariance = [draw(floats)] * 9
            topic = '/imu'
        secs = int(stamp)
        msg.header.stamp.secs, msg.header.stamp.nsecs = secs, min(999999999, int((stamp - secs) * 1e9))
        if draw(st.booleans()):
            stamp = msg.header.stamp.to_sec()
        out.append(Record(stamp, topic, msg))
    if sorted_per_topic:  # each topic's stamps non-decreasing in window order (topics still interleave freely)
        by_topic = {}
        for record in out:
            by_topic.setdefault(record.topic, []).append(record)
        queues = {topic: iter(sorted(recs, key=lambda r: r.stamp)) for topic, recs in by_topic.items()}
        out = [next(queues[record.topic]) for record in out]
    return out


def canonical(recs):
    def value(v):
        if isinstance(v, float) and math.isnan(v):
            return 'NaN'
        if isinstance(v, dict):
            return {k: value(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [value(x) for x in v]
        return v
    return [(r.stamp, r.topic, r.msg._type, value(msg_codec.to_dict(r.msg))) for r in recs]


SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.mark.parametrize('fmt', [Format.BAG_LZ4, Format.JSON_XZ])
@SETTINGS
@given(recs=records())
def test_any_records_round_trip_in_any_order(fmt, recs):
    with tempfile.TemporaryDirectory() as directory:
        window = LogWindow(recs, [Trigger(recs[0].stamp, 'classifier', -1.0)])
        path, _ = write_window(window, directory, fmt)
        metadata, back = read_window(path)
    assert canonical(back) == canonical(recs)


@pytest.mark.parametrize('fmt', Format.ALL)
@SETTINGS
@given(recs=records(sorted_per_topic=True))
def test_any_records_round_trip(fmt, recs):
    with tempfile.TemporaryDirectory() as directory:
        window = LogWindow(recs, [Trigger(recs[0].stamp, 'classifier', -1.0)])
        path, _ = write_window(window, directory, fmt)
        metadata, back = read_window(path)
    assert canonical(back) == canonical(recs)
    assert metadata['count'] == len(recs)


@st.composite
def walks(draw):
    """Odometry whose position and velocity drift by small steps from any start (any doubles: subnormal,
    huge, many digits): the columns json-xz writes as differences."""
    n = draw(st.integers(3, 30))
    start = draw(st.floats(-1e12, 1e12, allow_nan=False, allow_infinity=False) | st.floats(-1e-300, 1e-300))
    steps = st.floats(-1.0, 1.0, allow_nan=False) | st.integers(-1000, 1000).map(lambda k: k * 1e-3)
    scale = draw(st.sampled_from([1.0, 1e-3, 1e-9, 1e6]))
    out, x = [], start
    for i in range(n):
        x = x + draw(steps) * scale
        msg = Odometry()
        msg.header.seq = 1000 + i
        msg.header.stamp.secs, msg.header.stamp.nsecs = 1432235498 + i // 10, (i % 10) * 99999999
        msg.pose.pose.position.x = x
        msg.pose.pose.position.y = -x / 3.0
        msg.twist.twist.linear.x = draw(st.sampled_from([x, -x, 0.0, 0.5]))
        out.append(Record(msg.header.stamp.to_sec(), '/odom', msg))
    return out


@SETTINGS
@given(recs=walks())
def test_slowly_varying_columns_round_trip_bit_for_bit(recs):
    with tempfile.TemporaryDirectory() as directory:
        path, _ = write_window(LogWindow(recs, []), directory, Format.JSON_XZ)
        _, back = read_window(path)
    assert [(r.msg.pose.pose.position.x.hex(), r.msg.pose.pose.position.y.hex(), r.msg.twist.twist.linear.x.hex())
            for r in back] == [(r.msg.pose.pose.position.x.hex(), r.msg.pose.pose.position.y.hex(),
                                r.msg.twist.twist.linear.x.hex()) for r in recs]
    assert canonical(back) == canonical(recs)


@SETTINGS
@given(recs=records(sorted_per_topic=True), step=st.sampled_from([1e-4, 1e-5, 0.25, 3e-3, 1e3]))
def test_rounded_floats_within_half_a_step(recs, step):
    with tempfile.TemporaryDirectory() as directory:
        path, _ = write_window(LogWindow(recs, []), directory, Format.JSON_XZ,
                               {'precision': {'pose.pose.position.*': step, 'linear_acceleration.z': step}})
        metadata, back = read_window(path)
    assert metadata['precision'] == {'pose.pose.position.*': step, 'linear_acceleration.z': step}
    for a, b in zip(recs, back):
        if a.topic == '/odom':
            pairs = [(a.msg.pose.pose.position.x, b.msg.pose.pose.position.x)]
            assert b.msg.twist.twist.linear.x == a.msg.twist.twist.linear.x or math.isnan(a.msg.twist.twist.linear.x)
        else:
            pairs = [(a.msg.linear_acceleration.z, b.msg.linear_acceleration.z)]
        for old, new in pairs:
            if not math.isfinite(old):
                assert new == old or (math.isnan(old) and math.isnan(new))
            else:
                assert abs(new - old) <= step / 2 + 1e-15 * max(abs(old), abs(new), 1.0)


_VALID = {}


def valid_file(fmt):
    """One valid window file per format (bytes), written once."""
    if fmt not in _VALID:
        recs = []
        for i in range(40):
            msg = Odometry()
            msg.header.seq = i
            msg.header.stamp.secs, msg.header.stamp.nsecs = 1432235498 + i // 10, (i % 10) * 100000000
            msg.pose.pose.position.x = 0.1 * i + 1e-7 * i * i
            msg.twist.twist.linear.x = math.sin(i)
            recs.append(Record(msg.header.stamp.to_sec(), '/odom', msg))
        with tempfile.TemporaryDirectory() as directory:
            path, _ = write_window(LogWindow(recs, [Trigger(recs[5].stamp, 'manual', None)]), directory, fmt)
            with open(path, 'rb') as stream:
                _VALID[fmt] = (os.path.basename(path), stream.read(), canonical(recs))
    return _VALID[fmt]


def check_damaged(fmt, data):
    name, original, expected = valid_file(fmt)
    assume(data != original)
    with tempfile.TemporaryDirectory() as directory:
        path = os.path.join(directory, name)
        with open(path, 'wb') as stream:
            stream.write(data)
        try:
            _, back = read_window(path)
        except ValueError as error:
            assert path in str(error)
            return 'refused'
    assert canonical(back) == expected, 'a damaged file read back as different records'
    return 'same'


@pytest.mark.parametrize('fmt', Format.ALL)
@SETTINGS
@given(cut=st.floats(0.0, 1.0))
def test_truncated_file_is_refused_naming_the_path(fmt, cut):
    _, original, _ = valid_file(fmt)
    check_damaged(fmt, original[:int(len(original) * cut)])


@pytest.mark.parametrize('fmt', Format.ALL)  # json-xz: xz's CRC64; bag-lz4: the records' crc32 in its metadata
@SETTINGS
@given(flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(1, 255)), min_size=1, max_size=4))
def test_flipped_bytes_are_refused_or_harmless(fmt, flips):
    _, original, _ = valid_file(fmt)
    data = bytearray(original)
    for where, xor in flips:
        data[min(len(data) - 1, int(len(data) * where))] ^= xor
    check_damaged(fmt, bytes(data))
