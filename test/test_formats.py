"""Window files: json-xz and bag-lz4 round trips on real robot messages, names, atomic writing, errors,
and the json-xz size target on the Husky odometry."""
import fnmatch
import io
import itertools
import json
import lzma
import os
import re
import shutil
import subprocess
import sys

import pytest

from cc_log.storage import formats, log_format
from cc_log.base.raw_message import serialized
from cc_log.base import msg_codec
from cc_log.storage.formats import json_xz
from cc_log.storage.log_format import Format, read_window, write_window
from cc_log.base.records import LogWindow, Record, Trigger

rosbag = pytest.importorskip('rosbag')

HUSKY = 'husky_outdoor_2015.bag'
HUSKY_ODOM = '/husky_velocity_controller/odom'
SEQUOR = 'sequor_N2_anomalous_jerky_driving.bag'
ALFA = 'alfa_carbonZ_engine_failure.bag'
ALFA_ODOM = '/mavros/local_position/odom'

REAL = os.path.normpath(os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                     '..', 'shared', 'data', 'real'))
NAME = re.compile(r'cc_log_\d{8}T\d{6}\.\d{3}Z_[A-Za-z0-9-]+(_\d+)?(\.\d{3})?\.(json\.xz|bag)')


def real(name):
    """Path of a real bag (module-scoped fixtures cannot use the function-scoped ``real_bag``)."""
    path = os.path.join(REAL, name)
    if not os.path.exists(path):
        pytest.fail('real data missing: %s (tests read ../shared/data/real/)' % path)
    return path


def read_records(path, topics, limit=None, until=None):
    """Records (header stamp) of ``topics`` in a bag, in stamp order (stable: bag order on ties)."""
    records = []
    with rosbag.Bag(path) as bag:
        for topic, msg, time in bag.read_messages(topics=topics):
            stamp = msg.header.stamp.to_sec() if hasattr(msg, 'header') else time.to_sec()
            if until is not None and stamp > until:
                break
            records.append(Record(stamp, topic, msg))
            if limit is not None and len(records) >= limit:
                break
    records.sort(key=lambda record: record.stamp)
    return records


def copy_msg(msg):
    """An independent copy of a message (serialize and deserialize)."""
    buffer = io.BytesIO()
    msg.serialize(buffer)
    return type(msg)().deserialize(buffer.getvalue())


def assert_same_records(written, read):
    assert len(read) == len(written)
    for number, (a, b) in enumerate(zip(written, read)):
        assert b.topic == a.topic, number
        assert b.stamp == a.stamp, (number, a.stamp, b.stamp)  # exact float
        assert b.msg._type == a.msg._type
        assert msg_codec.to_dict(b.msg) == msg_codec.to_dict(a.msg), (number, a.topic)
        assert serialized(b.msg) == serialized(a.msg), (number, a.topic)


@pytest.fixture(scope='module')
def husky_window():
    """300 Husky odometry messages plus the IMU messages of the same time span, with NaN/inf injected."""
    path = real(HUSKY)
    odom = read_records(path, [HUSKY_ODOM], limit=300)
    imu = [record for record in read_records(path, ['/imu/data'], until=odom[-1].stamp)
           if record.stamp >= odom[0].stamp]
    records = sorted(odom + imu, key=lambda record: record.stamp)
    # Non-finite values a real driver can publish: NaN velocity, infinite covariance, -inf orientation.
    for index, patch in ((10, 'nan'), (11, 'inf'), (12, '-inf')):
        record = odom[index]
        msg = copy_msg(record.msg)
        msg.twist.twist.linear.x = float(patch)
        covariance = list(msg.pose.covariance)
        covariance[35] = float(patch)
        msg.pose.covariance = covariance
        records[records.index(record)] = Record(record.stamp, record.topic, msg)
    imu_record = imu[5]
    msg = copy_msg(imu_record.msg)
    msg.orientation.w = float('-inf')
    msg.orientation_covariance = [float('nan')] + list(msg.orientation_covariance[1:])
    records[records.index(imu_record)] = Record(imu_record.stamp, imu_record.topic, msg)
    assert len(imu) > 500
    triggers = [Trigger(odom[100].stamp, 'classifier', -0.1234), Trigger(odom[150].stamp, 'classifier', -0.5)]
    return LogWindow(records, triggers)


@pytest.fixture(scope='module')
def sequor_window():
    """Sequor odometry + LaserScan (+ label strings): equal stamps across topics, zero ranges."""
    path = real(SEQUOR)
    records = read_records(path, ['/odom', '/scan', '/label'], limit=240)
    scan = next(index for index, record in enumerate(records) if record.topic == '/scan')
    msg = copy_msg(records[scan].msg)
    msg.ranges = [float('inf'), float('nan')] + list(msg.ranges[2:])  # out-of-range beams
    records[scan] = Record(records[scan].stamp, '/scan', msg)
    return LogWindow(records, [Trigger(records[0].stamp, 'manual', None)])


@pytest.fixture(scope='module')
def alfa_window():
    path = real(ALFA)
    records = read_records(path, [ALFA_ODOM])
    return LogWindow(records, [Trigger(records[-1].stamp, 'engine-failure', -2.0)], part=2)


# -- round trips ----------------------------------------------------------------------------------------

@pytest.mark.parametrize('fmt', Format.ALL)
def test_husky_odometry_and_imu_round_trip(fmt, husky_window, tmp_path):
    path, nbytes = write_window(husky_window, str(tmp_path), fmt, {'robot': 'husky', 'rate': 10})
    assert os.path.getsize(path) == nbytes > 0
    metadata, records = read_window(path)
    assert_same_records(husky_window.records, records)
    nan_msgs = [record.msg for record in records if record.topic == HUSKY_ODOM]
    assert sum(1 for msg in nan_msgs if msg.twist.twist.linear.x != msg.twist.twist.linear.x) == 1
    assert any(msg.pose.covariance[35] == float('-inf') for msg in nan_msgs)
    # metadata
    counts = {HUSKY_ODOM: 300, '/imu/data': len(husky_window.records) - 300}
    assert metadata['topics'] == husky_window.topics
    assert metadata['types'] == {HUSKY_ODOM: 'nav_msgs/Odometry', '/imu/data': 'sensor_msgs/Imu'}
    assert metadata['counts'] == counts and metadata['count'] == len(husky_window)
    assert metadata['start'] == husky_window.start and metadata['end'] == husky_window.end
    assert metadata['reasons'] == ['classifier']
    assert [t['score'] for t in metadata['triggers']] == [-0.1234, -0.5]
    assert metadata['triggers'][0]['stamp'] == husky_window.triggers[0].stamp
    assert metadata['codec'] == fmt and metadata['layout'] == formats.get(fmt).LAYOUT_VERSION
    assert metadata['cc_log_version'] == __import__('cc_log').__version__
    assert metadata['robot'] == 'husky' and metadata['rate'] == 10
    assert metadata['start_utc'].startswith('2015-05-21T19:')
    assert NAME.fullmatch(os.path.basename(path)), path


@pytest.mark.parametrize('fmt', Format.ALL)
def test_sequor_laserscan_round_trip_with_equal_stamps(fmt, sequor_window, tmp_path):
    stamps = [record.stamp for record in sequor_window.records]
    assert len(set(stamps)) < len(stamps)  # several topics share a stamp: order must still be exact
    path, _ = write_window(sequor_window, str(tmp_path), fmt)
    metadata, records = read_window(path)
    assert_same_records(sequor_window.records, records)
    scans = [record.msg for record in records if record.topic == '/scan']
    assert scans[0].ranges[0] == float('inf') and scans[0].ranges[1] != scans[0].ranges[1]
    assert metadata['types']['/scan'] == 'sensor_msgs/LaserScan'
    assert metadata['triggers'] == [{'stamp': sequor_window.start, 'reason': 'manual', 'score': None}]
    assert os.path.basename(path).split('_')[3].startswith('manual')


@pytest.mark.parametrize('fmt', Format.ALL)
def test_alfa_odometry_round_trip_and_part_name(fmt, alfa_window, tmp_path):
    path, _ = write_window(alfa_window, str(tmp_path), fmt)
    assert '_engine-failure.002.' in os.path.basename(path)
    metadata, records = read_window(path)
    assert_same_records(alfa_window.records, records)
    assert metadata['part'] == 2 and metadata['count'] == 544


@pytest.mark.parametrize('fmt', Format.ALL)
def test_records_out_of_stamp_order_and_receipt_stamps_survive(fmt, sequor_window, tmp_path):
    # Record stamps that are not header stamps (receipt time), sub-nanosecond digits, and a window whose
    # records are not in stamp order: both must come back exactly as written.
    records = [Record(record.stamp + 0.123456789012 + i * 1e-12, record.topic, record.msg)
               for i, record in enumerate(sequor_window.records[:30])]
    records[3], records[4] = records[4], records[3]
    window = LogWindow(records, [])
    path, _ = write_window(window, str(tmp_path), fmt)
    assert '_window.' in os.path.basename(path)
    _, back = read_window(path)
    assert_same_records(records, back)


def test_json_xz_stamps_stated_once_when_header_stamps(husky_window):
    doc = json_xz.document(husky_window.records, {})
    assert [section['stamps'] for section in doc['topics']] == ['header.stamp', 'header.stamp']
    assert 'order' not in doc
    odom = next(section for section in doc['topics'] if section['topic'] == HUSKY_ODOM)
    assert odom['constant']['header.frame_id'] == 'odom'
    assert len(odom['columns']['pose.pose.position.x']) == 300
    assert odom['columns']['twist.twist.linear.x'][10] == 'NaN'


# -- readable with the usual tools ----------------------------------------------------------------------

def test_json_xz_opens_with_xz_and_jq(husky_window, tmp_path):
    for tool in ('xz', 'jq'):
        if shutil.which(tool) is None:
            pytest.skip('%s is not installed' % tool)
    path, _ = write_window(husky_window, str(tmp_path), Format.JSON_XZ)
    text = subprocess.run(['xz', '-dc', path], stdout=subprocess.PIPE, check=True, timeout=60).stdout
    shown = subprocess.run(['jq', '.'], input=text, stdout=subprocess.PIPE, timeout=60)
    assert shown.returncode == 0 and b'"pose.pose.position.x"' in shown.stdout
    query = ['jq', '-r', '.topics[] | select(.topic == "%s") | .columns["pose.pose.position.x"][0]' % HUSKY_ODOM]
    first = subprocess.run(query, input=text, stdout=subprocess.PIPE, check=True, timeout=60).stdout
    odom = next(record.msg for record in husky_window.records if record.topic == HUSKY_ODOM)
    assert float(first) == odom.pose.pose.position.x


def test_bag_opens_with_rosbag(husky_window, tmp_path):
    path, _ = write_window(husky_window, str(tmp_path), Format.BAG_LZ4)
    with rosbag.Bag(path) as bag:
        info = bag.get_type_and_topic_info()
        assert info.topics[HUSKY_ODOM].message_count == 300
        assert info.topics[HUSKY_ODOM].msg_type == 'nav_msgs/Odometry'
        assert info.topics['/cc_log/metadata'].message_count == 1
        assert bag.get_compression_info().compression == 'lz4'
        assert abs(bag.get_start_time() - husky_window.start) < 1e-6
    if shutil.which('rosbag') is None:
        pytest.skip('rosbag command not on PATH')
    result = subprocess.run(['rosbag', 'info', path], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert b'lz4' in result.stdout and b'nav_msgs/Odometry' in result.stdout


def test_a_window_of_decoded_messages_is_the_bag_rosbag_writes(husky_window, tmp_path):
    # out of stamp order, two topics, decoded messages: the bag written without rosbag is the one rosbag
    # writes for the same messages (its own connection headers and serialization), byte for byte
    import genpy
    from cc_log.storage.formats import bag_lz4
    records = list(reversed(husky_window.records[:400]))
    ours, _ = write_window(LogWindow(records, husky_window.triggers), str(tmp_path / 'ours'), Format.BAG_LZ4)
    with rosbag.Bag(ours) as bag:
        _, metadata, when = next(bag.read_messages(topics=[bag_lz4.METADATA_TOPIC]))
    theirs = str(tmp_path / 'rosbag.bag')
    with rosbag.Bag(theirs, 'w', compression=rosbag.Compression.LZ4) as bag:
        bag.write(bag_lz4.METADATA_TOPIC, metadata, when)
        for record in records:
            bag.write(record.topic, record.msg, genpy.Time(*bag_lz4.bag_stamp(record.stamp)))
    with open(ours, 'rb') as a, open(theirs, 'rb') as b:
        assert a.read() == b.read()
    _, back = read_window(ours)
    assert_same_records(records, back)


# -- size -------------------------------------------------------------------------------------------------

def test_json_xz_size_on_husky_odometry(real_bag):
    """The json-xz file against the row-per-message JSON of the same messages (docs/FORMAT.md): the 4% target
    on the whole topic (3.94% measured with layout 2; layout 1: 4.46%), and a quarter below row JSON + LZMA-6."""
    records = read_records(real_bag(HUSKY), [HUSKY_ODOM])
    assert len(records) == 3952
    raw = sum(msg_codec.row_json_bytes(record.msg) for record in records)
    whole = len(json_xz.encode(records, {}))
    rows = len(lzma.compress(b''.join(msg_codec.row_json(record.msg).encode() + b'\n' for record in records),
                             preset=6))
    assert 100.0 * whole / raw <= 4.0
    assert whole <= 0.70 * rows
    windows = [records[i:i + 300] for i in range(0, 3900, 300)]
    window_bytes = sum(len(json_xz.encode(chunk, {})) for chunk in windows)
    window_raw = sum(msg_codec.row_json_bytes(record.msg) for chunk in windows for record in chunk)
    assert 100.0 * window_bytes / window_raw <= 4.6  # 4.51% measured (layout 1: 4.96%)


def test_json_xz_delta_columns_and_jq_sums(real_bag, tmp_path):
    """Slowly varying columns are written as differences; jq's running sum gives the values back (as doubles)."""
    records = read_records(real_bag(HUSKY), [HUSKY_ODOM], limit=300)
    doc = json_xz.document(records, {})
    section = doc['topics'][0]
    assert {'header.seq', 'header.stamp.nsecs', 'pose.pose.position.x'} <= set(section['delta'])
    assert 'pose.pose.orientation.z' not in section['delta']  # its values recur: plain is smaller
    assert section['columns']['header.seq'][1:] == [1] * 299
    path = str(tmp_path / 'w.json.xz')
    with open(path, 'wb') as stream:
        stream.write(json_xz.encode(records, {}))
    assert_same_records(records, json_xz.read(path)[1])
    if shutil.which('xz') is None or shutil.which('jq') is None:
        pytest.skip('xz or jq is not installed')
    text = subprocess.run(['xz', '-dc', path], stdout=subprocess.PIPE, check=True, timeout=60).stdout
    query = '.topics[0].columns["pose.pose.position.x"] | [foreach .[] as $d (0; . + $d)] | .[]'
    sums = subprocess.run(['jq', query], input=text, stdout=subprocess.PIPE, check=True, timeout=60).stdout.split()
    assert len(sums) == 300
    for line, record in zip(sums, records):
        assert abs(float(line) - record.msg.pose.pose.position.x) < 1e-12


HUSKY_PRECISION = {'pose.pose.position.*': 1e-4, 'pose.pose.orientation.*': 1e-5, 'twist.twist.linear.*': 1e-4,
                   'twist.twist.angular.*': 1e-5}


def test_json_xz_precision_on_husky_odometry(real_bag, tmp_path):
    """Opt-in lossy: 1e-4 m / 1e-5 rad (and m/s, rad/s) on the Husky odometry: at most 2% of row JSON (whole
    topic and 300-message windows), the steps in the metadata, every field within half its step."""
    records = read_records(real_bag(HUSKY), [HUSKY_ODOM])
    raw = sum(msg_codec.row_json_bytes(record.msg) for record in records)
    data = json_xz.encode(records, {'precision': HUSKY_PRECISION})
    assert 100.0 * len(data) / raw <= 2.0  # 1.27% measured
    windows = [records[i:i + 300] for i in range(0, 3900, 300)]
    window_bytes = sum(len(json_xz.encode(chunk, {'precision': HUSKY_PRECISION})) for chunk in windows)
    window_raw = sum(msg_codec.row_json_bytes(record.msg) for chunk in windows for record in chunk)
    assert 100.0 * window_bytes / window_raw <= 2.0  # 1.71% measured
    path = str(tmp_path / 'w.json.xz')
    with open(path, 'wb') as stream:
        stream.write(data)
    metadata, back = json_xz.read(path)
    assert metadata['precision'] == HUSKY_PRECISION
    worst = json_xz.max_errors(records, back)[HUSKY_ODOM]
    for a, b in zip(records, back):
        assert msg_codec.to_dict(a.msg)['header'] == msg_codec.to_dict(b.msg)['header'] and a.stamp == b.stamp
    assert all(error == 0.0 for key, error in worst.items() if not any(
        fnmatch.fnmatchcase(key, pattern) for pattern in HUSKY_PRECISION))  # other fields untouched
    for pattern, step in HUSKY_PRECISION.items():
        fields = [key for key in worst if fnmatch.fnmatchcase(key, pattern)]
        assert fields and all(worst[key] <= step / 2 * (1 + 1e-9) for key in fields), (pattern, worst)
    assert worst['pose.pose.position.x'] > 1e-5  # the values did change: it is lossy


@pytest.mark.parametrize('values', [
    [1e300, 1e-300, 5.0, 6.0, 7.0],              # differences beyond exact decimal arithmetic: plain column
    [0.5, -0.0, 0.25, 0.125, 0.0625],            # -0.0 (a sum of differences gives +0.0): plain column
    [8.0, 9.0, 10.0, 11.0, 12.5],                # differences that are JSON integers
    [1.0000000000000002, 1.0000000000000004, 1.0000000000000007, 1.000000000000001, 1.0000000000000013]])
def test_json_xz_float_columns_round_trip_bit_for_bit(values, tmp_path):
    from std_msgs.msg import Float64
    records = [Record(float(i), '/x', Float64(value)) for i, value in enumerate(values)]
    path = str(tmp_path / 'w.json.xz')
    with open(path, 'wb') as stream:
        stream.write(json_xz.encode(records, {}))
    back = [record.msg.data for record in json_xz.read(path)[1]]
    assert [value.hex() for value in back] == [value.hex() for value in values]


def test_json_xz_bad_delta_columns_are_one_line_errors(tmp_path):
    from std_msgs.msg import Float64
    values = [100.12345678901, 100.12445678901, 100.12545678901, 100.12645678901, 100.12745678901]
    records = [Record(float(i), '/x', Float64(value)) for i, value in enumerate(values)]
    doc = json_xz.document(records, {})
    assert doc['topics'][0]['delta'] == ['data']
    text = json_xz.dumps(doc)
    for old, new, says in (('"delta":["data"]', '"delta":["nothing"]', 'names a column'),
                           ('"layout":2', '"layout":3', 'layout 3 is not supported (this cc_log reads layouts 1, 2)'),
                           ('"data":[100.12345678901,', '"data":["1",', 'other than numbers'),
                           ('"data":[100.12345678901,', '"data":[1e999,', 'do not add up'),
                           ('"data":[100.12345678901,', '"data":[1e9999999999999999999,', 'out of range')):
        assert old in text
        path = str(tmp_path / 'bad.json.xz')
        with open(path, 'wb') as stream:
            stream.write(json_xz.compress(text.replace(old, new).encode()))
        with pytest.raises(ValueError) as error:
            json_xz.read(path)
        assert str(error.value).startswith(path + ': ') and says in str(error.value), str(error.value)


# -- files: names, atomic writing, collisions, permissions ---------------------------------------------

def test_no_temporary_file_left_and_collisions_do_not_overwrite(alfa_window, tmp_path):
    directory = str(tmp_path / 'logs' / 'deep')  # created on demand
    first, _ = write_window(alfa_window, directory, Format.JSON_XZ)
    with open(first, 'rb') as stream:
        first_bytes = stream.read()
    second, _ = write_window(alfa_window, directory, Format.JSON_XZ, {'attempt': 2})
    third, _ = write_window(alfa_window, directory, Format.JSON_XZ, {'attempt': 3})
    assert len({first, second, third}) == 3
    with open(first, 'rb') as stream:
        assert stream.read() == first_bytes
    assert read_window(second)[0]['attempt'] == 2 and read_window(third)[0]['attempt'] == 3
    assert all(NAME.fullmatch(os.path.basename(path)) for path in (first, second, third))
    assert not [name for name in os.listdir(directory) if '.tmp-' in name]
    assert log_format.temporary_files(directory) == []
    assert log_format.window_files(directory) == sorted([first, second, third])


def test_window_files_sorted_by_time_and_leftovers_listed(sequor_window, alfa_window, tmp_path):
    directory = str(tmp_path)
    late, _ = write_window(sequor_window, directory, Format.BAG_LZ4)      # 2025
    early, _ = write_window(alfa_window, directory, Format.JSON_XZ)       # 2018
    leftover = os.path.join(directory, os.path.basename(early) + '.tmp-4242')
    with open(leftover, 'wb') as stream:
        stream.write(b'half a file')
    with open(os.path.join(directory, 'notes.txt'), 'w') as stream:
        stream.write('not a window')
    assert log_format.window_files(directory) == [early, late]
    assert log_format.temporary_files(directory) == [leftover]


def test_file_name_is_utc_of_first_stamp_and_first_reason(tmp_path):
    msg_class = msg_codec.generated_class('std_msgs/Float64', 'float64 data\n')
    stamp = 1432235498.0279760  # 2015-05-21 19:11:38.027976 UTC
    window = LogWindow([Record(stamp, '/x', msg_class(data=1.5)), Record(stamp + 1, '/x', msg_class(data=2.5))],
                       [Trigger(stamp, 'odd reason/1', 0.0), Trigger(stamp + 1, 'classifier', 0.0)])
    path, _ = write_window(window, str(tmp_path), Format.JSON_XZ)
    assert os.path.basename(path) == 'cc_log_20150521T191138.027Z_odd-reason-1.json.xz'
    metadata, records = read_window(path)
    assert metadata['reasons'] == ['odd reason/1', 'classifier']
    assert [record.msg.data for record in records] == [1.5, 2.5]


def test_files_never_world_writable(alfa_window, tmp_path):
    old = os.umask(0)
    try:
        directory = str(tmp_path / 'fresh')
        for fmt in Format.ALL:
            path, _ = write_window(alfa_window, directory, fmt)
            assert os.stat(path).st_mode & 0o002 == 0, (fmt, oct(os.stat(path).st_mode))
            assert os.stat(path).st_mode & 0o020  # group-writable
        assert os.stat(directory).st_mode & 0o002 == 0
    finally:
        os.umask(old)


def test_failed_write_leaves_nothing(tmp_path):
    class NotAMessage(object):
        _type = 'x/Y'
        _md5sum = '0' * 32
        _full_text = 'int32 a\n'
        __slots__ = ()
        _slot_types = ()
    window = LogWindow([Record(1.0, '/a', NotAMessage()), Record(2.0, '/a', object())], [])
    with pytest.raises(Exception):
        write_window(window, str(tmp_path), Format.JSON_XZ)
    assert os.listdir(str(tmp_path)) == []


# -- errors -----------------------------------------------------------------------------------------------

def test_unknown_format_is_one_line_error(alfa_window, tmp_path):
    with pytest.raises(ValueError) as error:
        Format.check('xyz')
    assert str(error.value) == "format: 'xyz' is not one of: bag-lz4, json-xz"
    with pytest.raises(ValueError) as error:
        Format.check('zip', 'format_param')
    assert str(error.value) == "format_param: 'zip' is not one of: bag-lz4, json-xz"
    with pytest.raises(ValueError) as error:
        write_window(alfa_window, str(tmp_path), 'xyz')
    assert str(error.value) == "format: 'xyz' is not one of: bag-lz4, json-xz"
    assert Format.check('bag-lz4') == 'bag-lz4'
    assert os.listdir(str(tmp_path)) == []


@pytest.mark.parametrize('fmt', Format.ALL)
def test_truncated_and_corrupt_files_name_the_path(fmt, alfa_window, tmp_path):
    path, nbytes = write_window(alfa_window, str(tmp_path), fmt)
    with open(path, 'rb') as stream:
        data = stream.read()
    damaged = {
        'truncated': data[:nbytes // 2],
        'header-only': data[:20],
        'empty': b'',
        'flipped': data[:nbytes // 2] + bytes(b ^ 0x5A for b in data[nbytes // 2:nbytes // 2 + 64])
        + data[nbytes // 2 + 64:],
    }
    for what, content in damaged.items():
        bad = os.path.join(str(tmp_path), 'cc_log_%s%s' % (what, Format.EXTENSIONS[fmt]))
        with open(bad, 'wb') as stream:
            stream.write(content)
        with pytest.raises(ValueError) as error:
            read_window(bad)
        assert str(error.value).startswith(bad + ': '), (what, str(error.value))
        assert '\n' not in str(error.value)


def test_foreign_files_are_rejected(tmp_path, real_bag):
    text = tmp_path / 'cc_log_notes.json.xz'
    text.write_bytes(b'{"hello": "world"}\n')
    xz_other = tmp_path / 'other.json.xz'
    xz_other.write_bytes(lzma.compress(json.dumps({'hello': 'world'}).encode()))
    xz_bad_json = tmp_path / 'bad.json.xz'
    xz_bad_json.write_bytes(lzma.compress(b'{not json'))
    for path in (str(text), str(xz_other), str(xz_bad_json), real_bag(HUSKY), str(tmp_path / 'missing.bag')):
        with pytest.raises(ValueError) as error:
            read_window(path)
        assert str(error.value).startswith(path + ': '), str(error.value)


def test_json_xz_with_mismatched_columns_is_rejected(alfa_window, tmp_path):
    doc = json_xz.document(alfa_window.records[:5], {})
    doc['topics'][0]['columns']['pose.pose.position.x'].pop()
    path = str(tmp_path / 'cc_log_short.json.xz')
    with open(path, 'wb') as stream:
        stream.write(lzma.compress(json_xz.dumps(doc).encode()))
    with pytest.raises(ValueError) as error:
        read_window(path)
    assert 'pose.pose.position.x' in str(error.value) and str(error.value).startswith(path)


def test_empty_window_is_refused(tmp_path):
    with pytest.raises(ValueError):
        write_window(LogWindow([], []), str(tmp_path), Format.JSON_XZ)


# -- msg_codec ------------------------------------------------------------------------------------------

ALL_TYPES = '''uint8[] blob
uint8[4] fixed
char[] chars
int8 small
uint64 big
bool flag
string text
float32 single
float64[] doubles
time t
duration d
time[] times
geometry_msgs/Point[] points
std_msgs/Empty nothing
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
================================================================================
MSG: std_msgs/Empty
'''


def test_msg_codec_every_kind_of_field():
    import genpy
    cls = msg_codec.generated_class('cc_log_test/AllTypes', ALL_TYPES)
    classes = msg_codec.message_classes('cc_log_test/AllTypes', ALL_TYPES)
    msg = cls(blob=b'\x00\xff\x10', fixed=b'abcd', chars=b'xy', small=-5, big=2 ** 64 - 1, flag=True,
              text='h\u00e9llo # not a comment', single=0.10000000149011612,
              doubles=[float('nan'), float('inf'), float('-inf'), -0.0, 1e-308, 5e-324],
              t=genpy.Time(1432235498, 27976030), d=genpy.Duration(-3, 500),
              times=[genpy.Time(1, 2)], points=[classes['geometry_msgs/Point'](1.0, 2.0, float('nan'))])
    row = msg_codec.to_dict(msg)
    assert row['blob'] == 'AP8Q' and row['fixed'] == 'YWJjZA=='
    assert row['t'] == {'secs': 1432235498, 'nsecs': 27976030} and row['d'] == {'secs': -3, 'nsecs': 500}
    assert row['doubles'][:3] == ['NaN', 'Infinity', '-Infinity']
    assert row['points'][0]['z'] == 'NaN' and row['nothing'] == {}
    line = json.dumps(row, allow_nan=False)  # valid JSON
    assert msg_codec.row_json_bytes(msg) == len(line.encode('utf-8')) + 1
    back = msg_codec.from_dict(json.loads(line), 'cc_log_test/AllTypes', ALL_TYPES)
    assert serialized(back) == serialized(msg)
    assert back.blob == b'\x00\xff\x10' and back.big == 2 ** 64 - 1 and back.d == genpy.Duration(-3, 500)
    assert str(back.doubles[3]) == '-0.0' and back.doubles[5] == 5e-324
    assert msg_codec.generated_class('cc_log_test/AllTypes', ALL_TYPES) is cls  # cached


def test_msg_codec_errors_name_the_field():
    definition = 'float64 x\nuint8[2] pair\n'
    with pytest.raises(ValueError) as error:
        msg_codec.from_dict({'x': 'fast', 'pair': 'AAA='}, 'cc_log_test/P', definition)
    assert 'x' in str(error.value) and 'fast' in str(error.value)
    with pytest.raises(ValueError) as error:
        msg_codec.from_dict({'x': 1.0, 'pair': 'AAAA'}, 'cc_log_test/P', definition)
    assert 'pair' in str(error.value)
    with pytest.raises(ValueError) as error:
        msg_codec.from_dict({'x': 1.0}, 'cc_log_test/P', definition)
    assert 'pair' in str(error.value) and 'missing' in str(error.value)


def test_compact_definition_keeps_md5(real_bag):
    with rosbag.Bag(real_bag(SEQUOR)) as bag:
        for _, msg, _ in bag.read_messages(topics=['/scan']):
            break
    compact = msg_codec.compact_definition(msg._full_text)
    assert len(compact) < len(msg._full_text) / 2 and '#' not in compact
    assert msg_codec.generated_class(msg._type, compact)._md5sum == msg._md5sum
    assert msg_codec.compact_definition('string S=a # b\nint32 X=1 # one\n') == 'string S=a # b\nint32 X=1\n'


@pytest.mark.parametrize('module', ['cc_log.base.msg_codec', 'cc_log.storage.formats.json_xz',
                                    'cc_log.storage.log_format', 'cc_log.storage.formats.bag_lz4',
                                    'cc_log.storage.bag.bag_salvage', 'cc_log.storage.codecs',
                                    'cc_log.storage.directory', 'cc_log.offline.export'])
def test_pure_modules_do_not_import_rospy(module):
    code = ('import sys, %s\n'
            'bad = sorted(m for m in sys.modules if m.split(".")[0] in ("rospy", "rosbag", "roslib"))\n'
            'print(",".join(bad))\nsys.exit(1 if bad else 0)\n' % module)
    env = dict(os.environ)
    src = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'src')
    env['PYTHONPATH'] = src + os.pathsep + env.get('PYTHONPATH', '')
    result = subprocess.run([sys.executable, '-c', code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=env, timeout=60)
    assert result.returncode == 0, (result.stdout, result.stderr)


def test_float32_fields_written_short_and_read_back_exact(real_bag):
    with rosbag.Bag(real_bag(SEQUOR)) as bag:
        for _, scan, _ in bag.read_messages(topics=['/scan']):
            break
    row = msg_codec.to_dict(scan, short_float32=True)
    full = msg_codec.to_dict(scan)
    assert full['scan_time'] == 0.10000000149011612 and row['scan_time'] == 0.1
    assert len(json.dumps(row['ranges'])) < 0.7 * len(json.dumps(full['ranges']))
    back = msg_codec.from_dict(json.loads(json.dumps(row)), scan._type, scan._full_text)
    assert back.scan_time == scan.scan_time and back.ranges == scan.ranges
    assert serialized(back) == serialized(scan)
    # A float32 field set in Python to a value float32 cannot hold reads back as its float32 (wire) value.
    scan.scan_time = 0.1
    back = msg_codec.from_dict(msg_codec.to_dict(scan, short_float32=True), scan._type, scan._full_text)
    assert back.scan_time == 0.10000000149011612 and serialized(back) == serialized(scan)
    assert msg_codec.short_float32(float('nan')) != msg_codec.short_float32(float('nan'))
    assert msg_codec.short_float32(3.4028234663852886e+38) == 3.4028235e+38


@pytest.mark.parametrize('name', ['husky_outdoor_2015.bag', 'sequor_N2_anomalous_jerky_driving.bag',
                                  'alfa_carbonZ_engine_failure.bag'])
def test_row_json_bytes_counts_exactly_the_row_json(name):
    import rosbag
    counted = 0
    with rosbag.Bag(real(name)) as bag:
        for _, msg, _ in bag.read_messages():
            assert msg_codec.row_json_bytes(msg) == len(msg_codec.row_json(msg).encode('utf-8')) + 1
            counted += 1
    assert counted > 1000


def test_row_json_bytes_with_non_finite_and_int_values():
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import LaserScan
    odom = Odometry()
    odom.header.frame_id = 'odom "quoted" \u00e9'
    odom.pose.pose.position.x = float('nan')
    odom.pose.pose.position.y = 3  # an int in a float64 field is written as 3.0
    odom.twist.covariance = [float('-inf')] + [0] * 35
    scan = LaserScan(ranges=[1.5, float('inf'), 2], intensities=[])
    for msg in (odom, scan, Odometry()):
        assert msg_codec.row_json_bytes(msg) == len(msg_codec.row_json(msg).encode('utf-8')) + 1


# -- older layouts ---------------------------------------------------------------------------------------

LAYOUT1_FIXTURE = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'fixtures', 'json_xz_layout1.json.xz')
BAG_LAYOUT1_FIXTURE = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'fixtures', 'bag_lz4_layout1.bag')


def test_json_xz_layout_1_file_still_read(real_bag):
    """A file written by the layout-1 encoder (committed before layout 2): the first 40 Husky odometry + IMU
    records with records 3 and 4 swapped; read back bit for bit."""
    records = read_records(real_bag(HUSKY), [HUSKY_ODOM, '/imu/data'], limit=40)
    records[3], records[4] = records[4], records[3]
    metadata, back = json_xz.read(LAYOUT1_FIXTURE)
    assert metadata['layout'] == 1
    assert_same_records(records, back)


def test_bag_lz4_layout_1_file_still_read(real_bag):
    """A file written by the layout-1 encoder (no crc32; committed before layout 2): the same 40 records with
    records 3 and 4 swapped; read back bit for bit."""
    records = read_records(real_bag(HUSKY), [HUSKY_ODOM, '/imu/data'], limit=40)
    records[3], records[4] = records[4], records[3]
    metadata, back = read_window(BAG_LAYOUT1_FIXTURE)
    assert metadata['layout'] == 1 and metadata['codec'] == 'bag-lz4'
    assert_same_records(records, back)


def test_bag_lz4_refuses_records_that_do_not_match_their_crc32(husky_window, tmp_path):
    # a message one byte longer than when the window was encoded (a flipped bit of its bytes on disk: its chunk's
    # LZ4 checksum, test_bag_writer.py)
    from cc_log.storage.formats import bag_lz4
    from cc_log.storage.bag import bag_writer
    messages, headers = bag_lz4.bag_messages(husky_window.records, {})
    messages = list(messages)
    good = tmp_path / 'good.bag'
    good.write_bytes(bag_writer.bag_bytes(messages, headers))
    assert len(read_window(str(good))[1]) == len(husky_window.records)
    topic, secs, nsecs, data = messages[100]
    messages[100] = (topic, secs, nsecs, data + b'\0')
    bad = tmp_path / 'bad.bag'
    bad.write_bytes(bag_writer.bag_bytes(messages, headers))
    with rosbag.Bag(str(bad)) as bag:
        assert bag.get_message_count() == len(messages)  # rosbag reads it without a complaint
    with pytest.raises(ValueError, match='do not match their crc32') as error:
        read_window(str(bad))
    assert str(bad) in str(error.value)


def test_a_json_xz_replay_that_left_messages_out_says_so_not_0_windows_not_written(tmp_path):
    """Issue 42 item 20: a json-xz replay whose windows were all written, some messages left out of them (bytes
    that cannot be decoded), said "0 window(s) (N messages) not written ... M window(s) written"."""
    from cc_log.logger.smart import SmartLogger
    from cc_log.offline import replay
    from cc_log.storage.bag.bag_reader import read_raw
    from cc_log.triggers.periodic import PeriodicTrigger
    records = [record._replace(raw=record.raw[:20]) if record.topic == '/imu/data' else record
               for record in itertools.islice(read_raw(real(HUSKY), [HUSKY_ODOM, '/imu/data']), 2000)]
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '1s', '1s', driving_topic=HUSKY_ODOM,
                         side_topics=('/imu/data',), triggers=[PeriodicTrigger('every', '10s')], wait_for_writer=True)
    with pytest.raises(OSError) as error:
        replay.replay_records(logger, records, source='the bag')
    stats = logger.stats()
    written = len(log_format.window_files(str(tmp_path)))
    assert stats['windows_lost'] == 0 and stats['messages_lost'] > 0 and written >= 2
    assert str(error.value).startswith('%s: %d messages not written, left out of the windows written: '
                                       % (tmp_path, stats['messages_lost'])), str(error.value)
    assert str(error.value).endswith('; %d window(s) written' % written) and 'window(s) (' not in str(error.value)


def test_json_xz_rows_that_cannot_be_decoded_are_counted_lost_per_topic(tmp_path):
    """Serialized messages whose bytes are cut short cannot be decoded into a json-xz window: left out, named per
    topic in the window's metadata and counted in the writer's ``messages_lost`` (not ``messages_kept``)."""
    from cc_log.storage import window_writer
    from cc_log.storage.bag.bag_reader import read_raw
    records = [record for record in read_raw(real(HUSKY), [HUSKY_ODOM, '/imu/data'])][:40]
    odom = [index for index, record in enumerate(records) if record.topic == HUSKY_ODOM]
    imu = [index for index, record in enumerate(records) if record.topic == '/imu/data']
    broken = {odom[1]: 30, odom[5]: 12, imu[2]: 20}  # index -> bytes kept
    records = [record._replace(raw=record.raw[:broken[index]]) if index in broken else record
               for index, record in enumerate(records)]
    writer = window_writer.WindowWriter(str(tmp_path), 'json-xz', background=False)
    writer.submit(window_writer.Job(LogWindow(records, [Trigger(records[0].stamp, 'test', None)])))
    writer.close()
    stats = writer.stats()
    assert stats['windows_saved'] == 1 and stats['jobs_lost'] == 0
    assert stats['messages_lost'] == 3 and stats['messages_kept'] == len(records) - 3
    [path] = log_format.window_files(str(tmp_path))
    meta, kept = read_window(path)
    assert len(kept) == len(records) - 3 and meta['undecodable'] == 3
    assert meta['undecodable_topics'] == {HUSKY_ODOM: 2, '/imu/data': 1}
