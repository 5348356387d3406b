"""``cclog export --to bag`` (export.to_bag): window records out to one rosbag, as rosbag would write them, with
the publishers' connection headers where the windows kept them (bag-lz4: whole; json-xz: callerid and latching)."""
import decimal
import json

import pytest
from conftest import real_data

from cc_log.storage.bag import bag_reader
from cc_log.offline import export
from cc_log.storage import log_format
from cc_log.base import raw_message
from cc_log.storage.formats import bag_lz4, json_xz
from cc_log.base.records import LogWindow

rosbag = pytest.importorskip('rosbag')

HUSKY = 'husky_outdoor_2015.bag'
ODOM, IMU = '/husky_velocity_controller/odom', '/imu/data'


@pytest.fixture(scope='module')
def husky_records():
    """Two seconds of the Husky odometry + IMU as serialized records; the IMU's publisher latches."""
    records = [record for record in bag_reader.read_raw(real_data(HUSKY), [ODOM, IMU])][:300]
    latched = dict(records[0].connection if records[0].topic == IMU else
                   next(r for r in records if r.topic == IMU).connection, latching='1', callerid='/imu_node')
    return [record._replace(connection=latched) if record.topic == IMU else record for record in records]


def windows_of(records, directory, fmt):
    """The records written as two windows of ``fmt`` and read back, in stamp order."""
    read = []
    for part in (records[:150], records[150:]):
        path, _ = log_format.write_window(LogWindow(part, []), str(directory), fmt)
        read.extend(log_format.read_window(path)[1])
    return sorted(read, key=lambda record: record.stamp)


@pytest.mark.parametrize('compression', ['lz4', 'bz2', 'none'])
def test_bag_lz4_windows_export_with_their_bytes_and_connection_headers(husky_records, tmp_path, compression):
    records = windows_of(husky_records, tmp_path / 'logs', 'bag-lz4')
    out = str(tmp_path / 'all.bag')
    ticks = []
    assert export.to_bag(records, out, compression, lambda: ticks.append(1)) == [out]
    assert len(ticks) == len(husky_records)
    with rosbag.Bag(out) as bag:
        assert bag.get_compression_info().compression == compression
        read = [(topic, raw[1], t.to_sec(), header) for topic, raw, t, header in
                bag.read_messages(raw=True, return_connection_header=True)]
    original = sorted(husky_records, key=lambda record: record.stamp)
    assert [(topic, data) for topic, data, _, _ in read] == [(r.topic, r.raw) for r in original]
    assert all(abs(t - r.stamp) < 1e-9 for (_, _, t, _), r in zip(read, original))
    imu = next(header for topic, _, _, header in read if topic == IMU)
    odom = next(header for topic, _, _, header in read if topic == ODOM)
    assert imu['latching'] == b'1' and imu['callerid'] == b'/imu_node'  # rosbag play latches it again
    assert odom.get('latching') != b'1'


def test_json_xz_windows_export_as_their_decoded_messages_with_callerid_and_latching(husky_records, tmp_path):
    records = windows_of(husky_records, tmp_path / 'logs', 'json-xz')
    out = str(tmp_path / 'all.bag')
    export.to_bag(records, out)
    with rosbag.Bag(out) as bag:
        read = [(topic, raw[1], raw[0], header) for topic, raw, _, header in
                bag.read_messages(raw=True, return_connection_header=True)]
    original = sorted(husky_records, key=lambda record: record.stamp)
    assert [(topic, data) for topic, data, _, _ in read] == [(r.topic, r.raw) for r in original]  # lossless
    assert {topic: kind for topic, _, kind, _ in read} == {ODOM: 'nav_msgs/Odometry', IMU: 'sensor_msgs/Imu'}
    imu = next(header for topic, _, _, header in read if topic == IMU)
    odom = next(header for topic, _, _, header in read if topic == ODOM)
    assert imu['latching'] == b'1' and imu['callerid'] == b'/imu_node'  # rosbag play latches it again
    assert odom.get('latching') != b'1'
    for topic, header in ((IMU, imu), (ODOM, odom)):  # what the recording said of its publishers, no more
        first = next(record for record in husky_records if record.topic == topic)
        assert raw_message.publisher_keys(raw_message.text_header(header)) == raw_message.publisher_keys(
            first.connection)


def test_json_xz_keeps_the_publisher_keys_only_when_the_records_had_a_connection(husky_records, tmp_path):
    decoded = [raw_message.decoded(record)._replace(raw=None, connection=None) for record in husky_records[:20]]
    doc = json_xz.document(decoded, {})
    assert all('connection' not in section for section in doc['topics'])
    doc = json_xz.document(husky_records[:20], {})
    imu = next(section for section in doc['topics'] if section['topic'] == IMU)
    assert imu['connection'] == {'callerid': '/imu_node', 'latching': '1'}


@pytest.mark.parametrize('bad', [['/imu_node'], {'callerid': 1}, {'message_definition': 'int8 x'}])
def test_json_xz_refuses_a_connection_that_is_not_callerid_and_latching_text(husky_records, bad):
    doc = json_xz.document(husky_records[:20], {})
    next(section for section in doc['topics'] if section['topic'] == IMU)['connection'] = bad
    with pytest.raises(ValueError, match='topic %s: "connection" must map callerid and latching to text' % IMU):
        json_xz.from_document(json.loads(json_xz.dumps(doc), parse_float=decimal.Decimal))


def test_a_topic_with_two_message_types_is_refused_and_nothing_is_written(husky_records, tmp_path):
    records = windows_of(husky_records, tmp_path / 'logs', 'bag-lz4')
    imu = next(record for record in records if record.topic == IMU)
    mixed = records + [imu._replace(topic=ODOM, stamp=records[-1].stamp + 1)]  # an Imu on the odometry topic
    out = tmp_path / 'mixed.bag'
    with pytest.raises(ValueError, match='topic %s: messages of two types \\(nav_msgs/Odometry and sensor_msgs/Imu\\)'
                       % ODOM):
        export.to_bag(mixed, str(out))
    assert not out.exists() and list(tmp_path.iterdir()) == [tmp_path / 'logs']
    with pytest.raises(ValueError, match='topic %s: messages of two types' % ODOM):
        bag_lz4.bag_messages(mixed, {})


def test_csv_names_are_unique_sanitized_and_never_overwrite(tmp_path):
    """``/a/b`` and ``/a_b`` both map to ``a_b``: each gets a file of its own, the file already there is left as
    it is, and a topic name never puts a separator, a control character or an unbounded name into a path."""
    import os
    import re
    from std_msgs.msg import String
    from cc_log.base.records import Record
    topics = ['/a/b', '/a_b', '/x/../../escape', '/\x1b[31mred\n', '/' + 'n' * 5000]
    records = [Record(float(number), topic, String(data='of %s' % number)) for number, topic in enumerate(topics)]
    theirs = tmp_path / 'a_b.csv'
    theirs.write_text('not ours\n')
    files = export.to_csv(records, str(tmp_path))
    assert theirs.read_text() == 'not ours\n'
    assert len(set(files)) == len(topics) and str(theirs) not in files
    assert sorted(os.listdir(str(tmp_path))) == sorted([theirs.name] + [os.path.basename(path) for path in files])
    for path in files:
        assert os.path.dirname(path) == str(tmp_path)
        assert re.match(r'^[A-Za-z0-9_-]{1,110}\.csv$', os.path.basename(path)), path
    # files in the order of the sorted topics (as ``cclog export --json`` lists them), each holding its topic
    for path, topic in zip(files, sorted(topics)):
        with open(path) as stream:
            assert stream.read().splitlines()[1].endswith(',of %d' % topics.index(topic)), (path, topic)
