"""A message whose bytes are not of its connection's type (a buggy publisher, two types on one topic in a
replayed bag) is refused where its window file is written: the file stays readable by rosbag, and the refused
messages are counted per topic in the window metadata's ``dropped`` (``cclog info`` says them)."""

import pytest

from conftest import cclog
from cc_log.base.raw_message import class_header, serialized
from cc_log.base.records import LogWindow, Record, Trigger
from cc_log.storage import log_format, payload_check

rosbag = pytest.importorskip('rosbag')
from geometry_msgs.msg import PoseArray, Pose, Twist  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import Imu, PointCloud2, PointField  # noqa: E402
from std_msgs.msg import Empty, String  # noqa: E402

T0 = 1432235498.0
ODOM, IMU = '/odom', '/imu'


def odometry(k):
    msg = Odometry()
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(T0) + k // 10, (k % 10) * 100000000
    msg.header.frame_id, msg.child_frame_id = 'odom', 'base_link'
    msg.pose.pose.position.x = 0.1 * k
    return msg


def imu(k):
    msg = Imu()
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(T0) + k // 10, (k % 10) * 100000000 + 5
    msg.header.frame_id = 'imu_link'
    msg.linear_acceleration.z = 9.81
    return msg


ODOM_CONNECTION = dict(class_header(ODOM, Odometry), callerid='/odometry', latching='0')
IMU_CONNECTION = dict(class_header(IMU, Imu), callerid='/imu_node', latching='0')


def window_records():
    """20 odometry and 20 IMU messages as bytes; 3 of the odometry ones hold bytes of other types (an Imu, a
    String: short; an Odometry with bytes left over), 1 IMU one an Odometry."""
    records = []
    for k in range(20):
        stamp = T0 + k * 0.1
        odom_raw = serialized(odometry(k))
        if k == 3:
            odom_raw = serialized(imu(k))
        elif k == 7:
            odom_raw = serialized(String(data='not odometry'))
        elif k == 11:
            odom_raw += b'\x00\x01\x02\x03'
        imu_raw = serialized(odometry(k)) if k == 5 else serialized(imu(k))
        records.append(Record(stamp, ODOM, None, len(odom_raw), odom_raw, ODOM_CONNECTION))
        records.append(Record(stamp + 0.001, IMU, None, len(imu_raw), imu_raw, IMU_CONNECTION))
    return records


# -- the check -----------------------------------------------------------------------------------------------

@pytest.mark.parametrize('msg', [
    odometry(3), imu(2), Twist(), String(data='ünïcode'), Empty(),
    PoseArray(poses=[Pose(), Pose()]),
    PointCloud2(fields=[PointField(name='x', offset=0, datatype=7, count=1)] * 3, data=b'\x01' * 48, height=1,
                width=4),
], ids=lambda msg: msg._type)
def test_the_bytes_of_a_message_fit_its_class_exactly(msg):
    shape = payload_check.connection_shape(class_header('/t', type(msg)))
    data = serialized(msg)
    assert payload_check.fits(data, shape)
    assert not payload_check.fits(data + b'\0', shape)
    if data:
        assert not payload_check.fits(data[:-1], shape)


def test_a_fixed_size_type_is_checked_by_its_length_and_others_by_their_lengths():
    assert payload_check.connection_shape(class_header('/t', Twist)).size == 48
    odom = payload_check.connection_shape(class_header('/t', Odometry))
    assert odom.size is None
    assert not payload_check.fits(serialized(imu(1)), odom)
    assert not payload_check.fits(b'\xff\xff\xff\xff' * 8, odom)  # a string "longer" than the bytes
    assert not payload_check.fits(b'', odom)
    cloud = payload_check.connection_shape(class_header('/t', PointCloud2))
    huge = bytearray(serialized(PointCloud2()))
    huge[24:28] = b'\xff\xff\xff\x7f'  # 2**31 fields of a message type: refused without a turn per field
    assert not payload_check.fits(bytes(huge), cloud)


def test_decoded_records_are_not_checked_and_a_definition_that_does_not_build_refuses():
    check = payload_check.PayloadCheck()
    assert not check.refused(Record(T0, ODOM, odometry(0)))
    broken = dict(ODOM_CONNECTION, message_definition='not a definition ][')
    raw = serialized(odometry(0))
    records = [Record(T0, ODOM, None, 0, raw, broken), Record(T0, ODOM, None, 0, raw, ODOM_CONNECTION)]
    kept, refused = check.split(records)
    assert len(kept) == 1 and refused == {ODOM: 1}


# -- bag-lz4 windows -----------------------------------------------------------------------------------------

def read_with_rosbag(path):
    """Every message of the bag decoded by rosbag: {topic: count}."""
    counts = {}
    with rosbag.Bag(path) as bag:
        for topic, msg, _ in bag.read_messages():
            counts[topic] = counts.get(topic, 0) + 1
    return counts


def test_a_bag_lz4_window_refuses_messages_of_another_type_and_counts_them(tmp_path):
    records = window_records()
    path, _ = log_format.write_window(LogWindow(records, [Trigger(T0 + 1.0, 'manual', None)]), str(tmp_path),
                                      'bag-lz4', {'dropped': {IMU: 2}})
    counts = read_with_rosbag(path)
    assert counts[ODOM] == 17 and counts[IMU] == 19
    metadata, back = log_format.read_window(path)
    assert metadata['dropped'] == {ODOM: 3, IMU: 1 + 2}  # with the messages shed before it
    kept = [r for r in records if payload_check.PayloadCheck().refused(r) is False]
    assert [r.raw for r in back] == [r.raw for r in kept]
    info = cclog('info', path)
    assert info.returncode == 0, info.stderr
    assert 'DROPPED    6 messages' in info.stdout and '/odom 3' in info.stdout


def test_a_bag_lz4_window_written_in_parts_refuses_and_counts_them_too(tmp_path):
    records = window_records()
    triggers = [Trigger(T0 + 1.0, 'manual', None)]
    stream_file = log_format.WindowFile(str(tmp_path), 'bag-lz4')
    stream_file.append(LogWindow(records[:20], triggers, 1, False, 7), {'reason': 'manual'})
    stream_file.append(LogWindow(records[20:30], triggers, 2, False, 7), {'reason': 'manual', 'dropped': {IMU: 2}})
    path, _ = stream_file.finish(LogWindow(records[30:], triggers, 3, True, 7), {'reason': 'manual'})
    assert read_with_rosbag(path) == {'/cc_log/metadata': 2, ODOM: 17, IMU: 19}  # provisional and final metadata
    metadata, back = log_format.read_window(path)
    assert metadata['dropped'] == {ODOM: 3, IMU: 3}
    assert len(back) == 36


def test_a_bag_lz4_window_of_nothing_but_refused_messages_is_not_written(tmp_path):
    raw = serialized(String(data='x'))
    window = LogWindow([Record(T0, ODOM, None, 0, raw, ODOM_CONNECTION)], [Trigger(T0, 'manual', None)])
    with pytest.raises(ValueError, match='refused'):
        log_format.write_window(window, str(tmp_path), 'bag-lz4')
    assert not list(tmp_path.iterdir())


# -- json-xz windows -----------------------------------------------------------------------------------------

def test_a_json_xz_window_leaves_out_and_counts_the_messages_it_cannot_decode(tmp_path):
    """json-xz decodes as genpy does (bytes left over are ignored: test_json_xz_bytes.py): what does not decode
    (an Imu and a String on the odometry topic) is left out and counted as a bag-lz4 window counts refusals."""
    records = window_records()
    path, _ = log_format.write_window(LogWindow(records, [Trigger(T0 + 1.0, 'manual', None)]), str(tmp_path),
                                      'json-xz', {'dropped': {IMU: 2}})
    metadata, back = log_format.read_window(path)
    assert metadata['dropped'] == {ODOM: 2, IMU: 2}
    assert metadata['undecodable'] == 2 and metadata['undecodable_topics'] == {ODOM: 2}
    assert [r.topic for r in back].count(ODOM) == 18 and len(back) == 38
    assert all(r.msg.header.frame_id == 'odom' for r in back if r.topic == ODOM)
    info = cclog('info', path)
    assert info.returncode == 0, info.stderr
    assert 'DROPPED    4 messages' in info.stdout and '/odom 2' in info.stdout
