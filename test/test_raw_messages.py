"""Messages kept as serialized bytes: features from the bytes, lazy decoding, bag-lz4 from the bytes with the
connection headers, latched topics at the start of every window, the memory cost of a buffered record."""
import collections
import os
import tracemalloc

import pytest

from cc_log import features
from cc_log.base.raw_message import serialized
from cc_log.storage import log_format
from cc_log.base import msg_codec, raw_message
from cc_log.features import FeatureConfig, FeatureStream
from cc_log.logger.smart import SmartLogger
from cc_log.base.records import Record
from cc_log.buffer.window_buffer import RAW_RECORD_OVERHEAD, MemoryCost

bagio = pytest.importorskip('cc_log.storage.bag.bagio')  # needs rosbag (a sourced ROS environment)
from geometry_msgs.msg import Twist  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402
from std_msgs.msg import String  # noqa: E402

HUSKY = 'husky_outdoor_2015.bag'
ODOM = '/husky_velocity_controller/odom'
IMU = '/imu/data'
TF_STATIC = '/tf_static'


def connection_of(cls, latching='0', callerid='/robot'):
    """A live connection header of a publisher of ``cls``."""
    return {'type': cls._type, 'md5sum': cls._md5sum, 'message_definition': cls._full_text,
            'callerid': callerid, 'latching': latching}


@pytest.fixture(scope='module')
def husky_raw():
    """The first 30 s of the Husky bag's odometry and IMU, as serialized records (bagio.read_raw)."""
    from conftest import real_data
    records = []
    for record in bagio.read_raw(real_data(HUSKY), [ODOM, IMU]):
        if records and record.stamp > records[0].stamp + 30.0:
            break
        records.append(record)
    return records


def test_feature_sets_read_the_same_numbers_from_the_bytes_as_from_the_messages(husky_raw):
    odometry = [r for r in husky_raw if r.topic == ODOM]
    imu = [r for r in husky_raw if r.topic == IMU]
    assert len(odometry) > 250 and len(imu) > 250
    for name, records in (('motion', odometry), ('raw', odometry), ('progress', odometry), ('command', odometry),
                          ('imu', imu)):
        feature = features.get(name)
        assert feature.reads_raw(records[0].connection)
        config = FeatureConfig(name, '20')
        from_msgs, from_bytes = FeatureStream(config), FeatureStream(config)
        for record in records:
            msg = raw_message.decoded(record).msg
            stamp = raw_message.stamp(record.raw, record.connection, record.stamp)
            assert stamp == features.stamp_of(msg, record.stamp)
            a, b = from_msgs.add(msg, stamp), from_bytes.add_raw(record.raw, stamp)
            assert (a is None) == (b is None)
            if a is not None:
                assert list(a) == list(b)  # the very same floats
        assert from_msgs.features.rejected == from_bytes.features.rejected == 0


def test_a_row_block_is_the_rows_message_by_message_and_leaves_the_same_state(husky_raw):
    odometry = [r for r in husky_raw if r.topic == ODOM]
    stamps = [raw_message.stamp(r.raw, r.connection, r.stamp) for r in odometry]
    stamps[100:110] = [stamps[99]] * 10  # repeated stamps
    stamps[200] = stamps[199] + 5.0      # a gap: the derivatives restart
    for name in ('motion', 'progress', 'dynamics', 'raw'):
        config = FeatureConfig(name, '20')
        one, block = features.get(name)(config), features.get(name)(config)
        rows, covered = [], []
        for record, stamp in zip(odometry, stamps):
            rows.append(one.row_values_raw(record.raw, stamp))
            covered.append(one.covers(config.span, stamp))
        got, got_covered = block.row_block([r.raw for r in odometry[:150]], stamps[:150], True, config.span)
        more, more_covered = block.row_block([r.raw for r in odometry[150:]], stamps[150:], True, config.span)
        assert got.tolist() + more.tolist() == [list(row) for row in rows]  # the very same floats
        assert got_covered.tolist() + more_covered.tolist() == covered
        assert (block.segment_start, block.segment_rows, block.restarts) == (
            one.segment_start, one.segment_rows, one.restarts)
        assert False in covered and covered[-1]


def test_byte_readers_follow_the_variable_frame_ids_and_reject_cut_messages():
    odom = Odometry()
    odom.header.frame_id = 'odom_with_a_long_frame_name'
    odom.child_frame_id = 'b'
    odom.pose.pose.position.x, odom.pose.pose.orientation.w = 1.5, 1.0
    odom.twist.twist.linear.x, odom.twist.twist.angular.z = 0.25, -0.5
    motion = features.get('motion')(FeatureConfig('motion', '5'))
    raw = serialized(odom)
    assert motion.read_raw(raw) == motion.read(odom)
    imu = Imu()
    imu.header.frame_id = 'imu_link'
    imu.linear_acceleration.z, imu.angular_velocity.x = 9.81, 0.125
    imu_set = features.get('imu')(FeatureConfig('imu', '5'))
    assert imu_set.read_raw(serialized(imu)) == imu_set.read(imu)
    command = features.get('command')(FeatureConfig('command', '5'))
    twist = Twist()
    twist.linear.x, twist.angular.z = 0.75, -0.3
    command.observe_raw('cmd_vel', serialized(twist), 3.0)
    assert command._command == (3.0, 0.75, -0.3)
    command.observe_raw('cmd_vel', serialized(twist)[:20], 4.0)  # cut off: counted, never raised
    assert command.rejected == 1 and command._command == (3.0, 0.75, -0.3)
    assert motion.row_values_raw(raw[:len(raw) // 2], 1.0) == (0.0,) * len(motion.columns)
    assert motion.rejected == 1
    other = dict(connection_of(Odometry), md5sum='0' * 32)  # another layout under the same name: decoded
    assert not motion.reads_raw(other) and not motion.reads_raw(None)


def test_header_stamps_from_the_bytes():
    odom = Odometry()
    odom.header.stamp.secs, odom.header.stamp.nsecs = 1432235497, 250000000
    assert raw_message.stamp(serialized(odom), connection_of(Odometry), 7.0) == 1432235497.25
    odom.header.stamp.secs = odom.header.stamp.nsecs = 0
    assert raw_message.stamp(serialized(odom), connection_of(Odometry), 7.0) == 7.0  # zero: the fallback
    assert raw_message.stamp(serialized(Twist()), connection_of(Twist), 8.5) == 8.5  # no header
    assert raw_message.has_header(connection_of(Imu)) and not raw_message.has_header(connection_of(String))


def test_a_buffered_serialized_record_costs_its_length_plus_a_small_constant():
    cost = MemoryCost()
    raw = serialized(Odometry())
    assert cost.of(Record(1.0, '/odom', None, 0, raw, connection_of(Odometry))) == len(raw) + RAW_RECORD_OVERHEAD
    connection = connection_of(Odometry)
    for size in (100, 700, 5000):
        held = collections.deque()
        tracemalloc.start()
        before = tracemalloc.get_traced_memory()[0]
        for i in range(5000):
            held.append(Record(1.5 + i, '/odom', None, 1000 + i, os.urandom(size), connection))
        used = (tracemalloc.get_traced_memory()[0] - before) / len(held)
        tracemalloc.stop()
        assert size < used <= size + RAW_RECORD_OVERHEAD


class AlwaysAnomalous(object):
    """A model that calls every window anomalous (every scored message triggers)."""

    def __init__(self, config):
        self.config = config
        self.threshold = 0.0

    def is_anomalous(self, vector):
        return True, -1.0


def _run(records, directory, fmt, raw, flags, latched=()):
    """SmartLogger over ``records`` (serialized, or decoded when ``raw`` is False) with a manual trigger at the
    driving message numbers in ``flags``; ``latched`` records are fed first."""
    logger = SmartLogger(None, directory, fmt, 10, 10, driving_topic=ODOM, side_topics=[IMU, TF_STATIC],
                         background=False)
    for record in latched:
        logger.on_raw(record.topic, record.raw, record.connection, record.stamp)
    index = -1
    for record in records:
        if raw:
            logger.on_raw(record.topic, record.raw, record.connection, record.stamp)
        else:
            decoded = raw_message.decoded(record)
            logger.on_message(record.topic, decoded.msg, record.stamp, len(record.raw))
        if record.topic == ODOM:
            index += 1
            if index in flags:
                assert logger.trigger_now('test')[0]
    logger.close()
    return [log_format.read_window(path) for path in log_format.window_files(directory)]


def _rows(records):
    return [(r.stamp, r.topic, msg_codec.row_json(r.msg)) for r in records]


@pytest.mark.parametrize('fmt', log_format.Format.ALL)
def test_windows_from_the_bytes_hold_what_windows_from_decoded_messages_hold(husky_raw, tmp_path, fmt):
    flags = {50, 200}
    from_bytes = _run(husky_raw, str(tmp_path / 'bytes'), fmt, True, flags)
    from_msgs = _run(husky_raw, str(tmp_path / 'msgs'), fmt, False, flags)
    assert len(from_bytes) == len(from_msgs) == 2
    for (meta_a, records_a), (meta_b, records_b) in zip(from_bytes, from_msgs):
        assert _rows(records_a) == _rows(records_b)
        assert meta_a['types'] == meta_b['types'] and meta_a['counts'] == meta_b['counts']


def tf_message_class():
    """tf2_msgs/TFMessage built from its definition (tf2_msgs need not be installed)."""
    from geometry_msgs.msg import TransformStamped
    definition = 'geometry_msgs/TransformStamped[] transforms\n%s\nMSG: geometry_msgs/TransformStamped\n%s' % (
        '=' * 80, TransformStamped._full_text)
    return msg_codec.generated_class('tf2_msgs/TFMessage', definition), TransformStamped


def _tf_static(stamp):
    TFMessage, TransformStamped = tf_message_class()
    transform = TransformStamped()
    transform.header.frame_id, transform.child_frame_id = 'base_link', 'imu_link'
    transform.transform.rotation.w = 1.0
    message = TFMessage(transforms=[transform])
    return Record(stamp, TF_STATIC, None, 0, serialized(message),
                  connection_of(TFMessage, latching='1', callerid='/robot_state_publisher'))


@pytest.mark.parametrize('fmt', log_format.Format.ALL)
def test_a_latched_message_published_once_starts_every_window(husky_raw, tmp_path, fmt):
    latched = _tf_static(husky_raw[0].stamp - 100.0)
    windows = _run(husky_raw, str(tmp_path), fmt, True, {50, 200, 280}, latched=[latched])
    assert len(windows) == 3
    for meta, records in windows:
        assert records[0].topic == TF_STATIC and records[0].stamp == meta['start']
        assert records[0].msg.transforms[0].child_frame_id == 'imu_link'
        assert [r.topic for r in records].count(TF_STATIC) == 1 and meta['counts'][TF_STATIC] == 1
        assert records[1].topic in (ODOM, IMU)


def test_a_bag_lz4_window_keeps_the_connection_headers(husky_raw, tmp_path):
    import rosbag
    latched = _tf_static(husky_raw[0].stamp - 1.0)
    records = [Record(r.stamp, r.topic, None, 0, r.raw, dict(r.connection, callerid='/husky_node', latching='0'))
               for r in husky_raw]
    _run(records, str(tmp_path), 'bag-lz4', True, {50}, latched=[latched])
    path, = log_format.window_files(str(tmp_path))
    with rosbag.Bag(path) as bag:
        headers = {c.topic: c.header for c in bag._connections.values()}
    assert headers[TF_STATIC][b'latching' if b'latching' in headers[TF_STATIC] else 'latching'] in (b'1', '1')
    for topic, callerid in ((TF_STATIC, '/robot_state_publisher'), (ODOM, '/husky_node'), (IMU, '/husky_node')):
        header = {k.decode() if isinstance(k, bytes) else k: v.decode() if isinstance(v, bytes) else v
                  for k, v in headers[topic].items()}
        assert header['callerid'] == callerid and header['topic'] == topic
    assert log_format.read_window(path)[1][0].topic == TF_STATIC


def test_json_xz_leaves_out_a_kept_message_that_cannot_be_decoded_and_says_so(husky_raw, tmp_path):
    from cc_log.base.records import LogWindow, Trigger
    records = [r for r in husky_raw if r.topic == ODOM][:5]
    broken = records[2]._replace(raw=records[2].raw[:30])
    window = LogWindow(records[:2] + [broken] + records[3:], [Trigger(records[0].stamp, 'test', None)])
    path, _ = log_format.write_window(window, str(tmp_path), 'json-xz')
    meta, kept = log_format.read_window(path)
    assert meta['undecodable'] == 1 and len(kept) == 4 and meta['count'] == 5


def test_replay_reads_serialized_messages_and_a_truncated_one_is_one_line(tmp_path):
    import rosbag
    bag = str(tmp_path / 'cut.bag')
    odom = Odometry()
    odom.pose.pose.orientation.w = 1.0
    with rosbag.Bag(bag, 'w') as out:
        for i in range(30):
            odom.header.stamp.secs = 100 + i
            out.write('/odom', odom, odom.header.stamp)
        buffer = serialized(odom)[:40]
        out.write('/odom', ('nav_msgs/Odometry', buffer, Odometry._md5sum, Odometry), odom.header.stamp, raw=True)
    records = list(bagio.read_raw(bag, ['/odom']))
    assert len(records) == 31 and records[0].msg is None and records[0].connection['type'] == 'nav_msgs/Odometry'
    from cc_log.triggers import RuleTrigger
    rule = RuleTrigger('fast', '/odom', when='twist.twist.linear.x > 1')  # reads a field: decodes every message
    logger = SmartLogger(None, str(tmp_path / 'out'), triggers=[rule], driving_topic='/odom', background=False)
    from cc_log.offline.replay import replay_into
    with pytest.raises(ValueError, match=r'cut\.bag: a message of /odom cannot be decoded'):
        replay_into(logger, bag)


def test_stamps_of_a_batch_are_each_message_s_stamp_with_and_without_headers(husky_raw):
    records = husky_raw[:300]
    odom = records[0]
    zero, short = Odometry(), String(data='x')
    zero_raw = serialized(zero)  # a header stamp of zero: the fallback
    batch = [(r.raw, r.connection, r.stamp) for r in records] + [(zero_raw, odom.connection, 12.5)]
    raws, connections, fallbacks = zip(*batch)
    expected = [raw_message.stamp(raw, c, f) for raw, c, f in batch]
    assert raw_message.stamps(raws, connections, fallbacks) == expected
    assert expected[-1] == 12.5 and expected[0] != records[0].stamp  # the header stamp, not the bag time
    # a message shorter than a header, and a type without one, mixed in: each its own stamp
    no_header = connection_of(String)
    mixed = batch[:5] + [(serialized(short), no_header, 3.0), (b'\x00' * 8, odom.connection, 4.0)]
    raws, connections, fallbacks = zip(*mixed)
    assert raw_message.stamps(raws, connections, fallbacks) == [raw_message.stamp(*item) for item in mixed]
    assert raw_message.stamps([b'\x00' * 8], [odom.connection], [4.0]) == [4.0]
    assert raw_message.stamps([serialized(short)], [no_header], [3.0]) == [3.0]


def test_the_row_json_estimate_of_a_batch_is_that_of_each_message_in_turn(husky_raw):
    from cc_log.base.raw_json import RawJsonEstimate
    one, batched = RawJsonEstimate(every=7, first=20), RawJsonEstimate(every=7, first=20)
    records = husky_raw[:400]
    for record in records:
        one.count(record.raw, record.connection)
    for start in range(0, len(records), 33):  # batches of both types mixed, across the first/every bounds
        part = records[start:start + 33]
        batched.count_all([r.raw for r in part], [r.connection for r in part])
    assert batched.total == one.total > 0 and batched._types == one._types  # (the samples decoded by total)
    sampled = one._types[records[0].connection['type']]
    assert 0 < sampled[2] < sampled[1]  # sampled after the first 20, not every message


def test_the_row_json_estimate_samples_the_first_messages_of_a_type_only_while_few_bytes_came():
    """A type of large messages (a 200 kB string, as a hostile or binary image can be) decodes its first ones only
    until first_bytes came, then one in every: a burst costs what a few decodes cost, one by one or batched."""
    from std_msgs.msg import String
    from cc_log.base.raw_json import RawJsonEstimate
    connection = connection_of(String)
    raws = [serialized(String(data='x' * 200000)) for _ in range(40)]
    one, batched = RawJsonEstimate(every=16, first=256, first_bytes=1 << 20), RawJsonEstimate(
        every=16, first=256, first_bytes=1 << 20)
    for raw in raws:
        one.count(raw, connection)
    batched.count_all(raws[:5], [connection] * 5)
    batched.count_all(raws[5:], [connection] * 35)
    sampled = 6 + 2  # 6 before 1 MB came (0, 200 kB, ... 1,000,008 bytes), then messages 16 and 32
    assert len(one._pending) == len(batched._pending) == sampled
    assert one.total == batched.total == pytest.approx(40 * len(raws[0]), rel=0.01)


def test_the_row_json_estimate_decodes_its_samples_when_asked_not_when_noted(husky_raw):
    from cc_log.base.raw_json import RawJsonEstimate
    raws, connections = [r.raw for r in husky_raw[:300]], [r.connection for r in husky_raw[:300]]
    lazy, eager = RawJsonEstimate(), RawJsonEstimate(pending_bytes=0)  # eager: decoded as soon as noted
    lazy.count_all(raws, connections)
    eager.count_all(raws, connections)
    assert all(entry[2] == entry[3] == 0 for entry in lazy._types.values())  # nothing decoded on the message path
    assert all(entry[2] > 0 for entry in eager._types.values())
    assert lazy.total == eager.total > 0 and lazy._types == eager._types


def test_the_row_json_estimate_of_a_husky_replay_decodes_374_messages_within_a_tenth_of_a_percent():
    """The summary's ``raw_json_bytes`` of the whole Husky bag (odometry + IMU, 15817 messages): the first 64 of
    each type and one in 64 after are decoded (counted: 374; 752 with the first 256 before), and the estimate
    stays within 0.1% of every message decoded."""
    from conftest import real_data
    from cc_log.base.raw_json import RawJsonEstimate
    records = list(bagio.read_raw(real_data(HUSKY), [ODOM, IMU]))
    estimate, exact = RawJsonEstimate(), RawJsonEstimate(every=1)
    estimate.count_all([r.raw for r in records], [r.connection for r in records])
    for record in records:
        exact.count(record.raw, record.connection)
    assert len(records) == 15817 and len(estimate._pending) == 374
    assert estimate.total == pytest.approx(exact.total, rel=1e-3)
