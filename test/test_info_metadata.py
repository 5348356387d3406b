"""``cclog info`` and ``cclog stats`` read a window's metadata, not its messages: the writer records a summary of the
records in every window's metadata (``window_info.Contents``), ``log_format.read_metadata`` reads it without the
messages, and both commands report from it what they report from the records (``--full``: the recount), falling
back to the records for files without one."""
import collections
import json
import os
import time

import pytest

from cc_log.base import msg_codec, raw_message
from cc_log.base.raw_message import class_header, serialized
from cc_log.base.records import LogWindow, Record, Trigger
from cc_log.offline import cli, stats
from cc_log.storage import log_format, window_info
from cc_log.storage.formats import bag_lz4, json_xz

rosbag = pytest.importorskip('rosbag')
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402
from std_msgs.msg import String  # noqa: E402

T0 = 1432235498.0
ODOM, IMU = '/odom', '/imu'
ODOM_CONNECTION = dict(class_header(ODOM, Odometry), callerid='/odometry', latching='0')
IMU_CONNECTION = dict(class_header(IMU, Imu), callerid='/imu_node', latching='0')
FORMATS = ('bag-lz4', 'json-xz')


def odometry(stamp, k):
    msg = Odometry()
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp - int(stamp)) * 1e9))
    msg.header.frame_id, msg.child_frame_id = 'odom', 'base_link'
    msg.pose.pose.position.x = 0.1 * k + 1.0 / 3
    msg.twist.twist.linear.x = (k % 7) * 0.123456789
    return msg


def imu(stamp, k):
    msg = Imu()
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp - int(stamp)) * 1e9))
    msg.header.frame_id = 'imu_link' if k % 3 else 'imu'
    msg.linear_acceleration.z = 9.81 + k * 1e-3
    return msg


def records(count, start=T0, raw=True):
    """``count`` odometry and ``count`` IMU records from ``start`` at 10 Hz, as bytes with their connection
    headers (as the nodes hand them over) or as messages."""
    found = []
    for k in range(count):
        stamp = start + 0.1 * k
        for topic, msg, connection in ((ODOM, odometry(stamp, k), ODOM_CONNECTION),
                                       (IMU, imu(stamp + 0.01, k), IMU_CONNECTION)):
            if raw:
                found.append(Record(msg.header.stamp.to_sec(), topic, None, 0, serialized(msg), connection))
            else:
                found.append(Record(msg.header.stamp.to_sec(), topic, msg))
    return found


def window(count, start=T0, raw=True, part=0):
    recs = records(count, start, raw)
    return LogWindow(recs, [Trigger(recs[0].stamp, 'classifier', -0.25, 'classifier')], part=part)


class Decodes(object):
    """Counts the calls of the functions that decode or measure one message each, in this process."""

    def __init__(self, monkeypatch):
        self.calls = collections.Counter()
        for module, name in ((bag_lz4, '_deserialized'), (raw_message, 'decode'), (msg_codec, 'from_dict'),
                             (msg_codec, 'row_json_bytes')):
            monkeypatch.setattr(module, name, self._counted(getattr(module, name), name))

    def _counted(self, function, name):
        def counted(*args, **kwargs):
            self.calls[name] += 1
            return function(*args, **kwargs)
        return counted


def info(capsys, *args):
    assert cli.main(['info'] + [str(arg) for arg in args] + ['--json']) == 0
    return json.loads(capsys.readouterr().out)


# -- the regression: no message is decoded -------------------------------------------------------------------

def test_info_of_2000_windows_decodes_no_message(tmp_path, monkeypatch, capsys):
    written = collections.Counter()
    for number in range(2000):
        fmt = FORMATS[number % 10 == 0]  # one in ten json-xz
        path, size = log_format.write_window(window(2, T0 + 10 * number), str(tmp_path), fmt)
        written[fmt] += 1
    decodes = Decodes(monkeypatch)
    started = time.perf_counter()
    document = info(capsys, tmp_path)
    seconds = time.perf_counter() - started
    assert decodes.calls == {}  # today's writer's files: nothing but their metadata read
    assert document['total']['windows'] == 2000 and document['total']['messages'] == 2000 * 4
    assert collections.Counter(w['codec'] for w in document['windows']) == written
    assert seconds < 300  # generous: about 1 ms a window on a laptop
    (recounted,) = info(capsys, path, '--full')['windows']  # the recount does decode
    assert decodes.calls['row_json_bytes'] == 4 and recounted == document['windows'][-1]


# -- the same report from the metadata as from the records -----------------------------------------------------

@pytest.mark.parametrize('fmt', FORMATS)
@pytest.mark.parametrize('raw', [True, False])
def test_info_from_metadata_is_the_full_report(tmp_path, capsys, fmt, raw):
    log_format.write_window(window(10, raw=raw), str(tmp_path), fmt)  # at most JSON_SAMPLE_FIRST a topic: exact
    shuffled = records(6, T0 + 100, raw)
    shuffled[2], shuffled[7] = shuffled[7], shuffled[2]  # not in stamp order: first/last are min/max
    log_format.write_window(LogWindow(shuffled, [Trigger(shuffled[0].stamp, 'rule', None, 'bumper')]),
                            str(tmp_path), fmt, metadata={'dropped': {ODOM: 3}, 'threshold': 0.5})
    fast, full = info(capsys, tmp_path), info(capsys, tmp_path, '--full')
    assert fast == full
    assert fast['windows'][1]['start'] == min(record.stamp for record in shuffled)
    text = [cli.main(['info', str(tmp_path)] + flag) == 0 and capsys.readouterr().out for flag in ([], ['--full'])]
    assert text[0] == text[1] and 'DROPPED    3 messages' in text[0]


@pytest.mark.parametrize('fmt', FORMATS)
def test_a_large_window_differs_only_in_its_estimated_row_json(tmp_path, capsys, fmt):
    log_format.write_window(window(600), str(tmp_path), fmt)
    fast, full = info(capsys, tmp_path), info(capsys, tmp_path, '--full')
    (quick,), (exact,) = fast['windows'], full['windows']
    assert quick['raw_json_bytes'] != exact['raw_json_bytes']  # 600 records a topic: sampled
    assert quick['raw_json_bytes'] == pytest.approx(exact['raw_json_bytes'], rel=0.01)
    for entry in (quick, exact):
        for key in ('raw_json_bytes', 'ratio'):
            del entry[key]
    assert quick == exact and quick['topics'] == {ODOM: 600, IMU: 600}


def test_a_window_written_a_part_at_a_time_has_the_summary_of_all_its_parts(tmp_path, capsys):
    stream = log_format.WindowFile(str(tmp_path), 'bag-lz4')
    stream.append(window(5, part=1), {'dropped': {IMU: 1}})
    stream.append(window(5, T0 + 1, part=2), None)
    path, _ = stream.finish(window(5, T0 + 2, part=3), None)
    summary = window_info.summary_of(log_format.read_metadata(path))
    assert summary.counts == {ODOM: 15, IMU: 15}
    assert summary.topic_spans[ODOM] == (T0, pytest.approx(T0 + 2.4))
    assert info(capsys, path) == info(capsys, path, '--full')


# -- files the summary does not describe: read whole -----------------------------------------------------------

@pytest.mark.parametrize('fmt', FORMATS)
def test_a_file_of_an_older_cc_log_is_read_whole(tmp_path, monkeypatch, capsys, fmt):
    recs = window(4).records
    metadata = window_info.window_metadata(window(4), fmt)
    for key in window_info.SUMMARY_KEYS:
        del metadata[key]
    module = bag_lz4 if fmt == 'bag-lz4' else json_xz
    path = str(tmp_path / ('cc_log_old' + module.EXTENSION))
    with open(path, 'wb') as stream:
        module.encoder(recs if fmt == 'bag-lz4' else raw_message.decoded_records(recs)[0], metadata)(stream)
    assert window_info.summary_of(log_format.read_metadata(path)) is None
    decodes = Decodes(monkeypatch)
    assert info(capsys, path) == info(capsys, path, '--full')
    assert decodes.calls['row_json_bytes'] == 2 * 8  # both read every message


def test_records_refused_by_bag_lz4_leave_the_file_without_a_summary(tmp_path, capsys):
    recs = records(5)
    recs[2] = recs[2]._replace(raw=serialized(String(data='not odometry')))  # bytes not of the topic's type
    path, _ = log_format.write_window(LogWindow(recs, []), str(tmp_path), 'bag-lz4')
    metadata = log_format.read_metadata(path)
    assert metadata['counts'] == {ODOM: 5, IMU: 5} and metadata['dropped'] == {ODOM: 1}
    assert window_info.summary_of(metadata) is None and 'topic_bytes' not in metadata
    fast = info(capsys, path)
    assert fast == info(capsys, path, '--full') and fast['windows'][0]['topics'] == {ODOM: 4, IMU: 5}


def test_records_json_xz_cannot_decode_leave_the_file_without_a_summary(tmp_path):
    recs = records(5)
    recs[3] = recs[3]._replace(raw=recs[3].raw[:10])  # cut: cannot be decoded
    path, _ = log_format.write_window(LogWindow(recs, []), str(tmp_path), 'json-xz')
    metadata = log_format.read_metadata(path)
    assert metadata['undecodable'] == 1 and window_info.summary_of(metadata) is None
    assert not set(window_info.SUMMARY_KEYS) & set(metadata)


# -- read_metadata: what read_window gives, and its errors ------------------------------------------------------

@pytest.mark.parametrize('fmt', FORMATS)
def test_read_metadata_is_read_windows_metadata(tmp_path, fmt):
    path, _ = log_format.write_window(window(40), str(tmp_path), fmt, metadata={'pre': '2 s', 'model': 'm.pkl'})
    metadata, recs = log_format.read_window(path)
    assert log_format.read_metadata(path) == metadata
    summary = window_info.summary_of(metadata)
    assert list(summary.counts) == [ODOM, IMU] and summary.types == {ODOM: 'nav_msgs/Odometry', IMU: 'sensor_msgs/Imu'}
    for topic in (ODOM, IMU):
        mine = [record for record in recs if record.topic == topic]
        assert summary.topic_bytes[topic] == sum(len(serialized(record.msg)) for record in mine)
        assert summary.topic_spans[topic] == (min(r.stamp for r in mine), max(r.stamp for r in mine))


def test_the_json_xz_metadata_is_read_from_the_start_of_a_large_document(tmp_path, monkeypatch):
    path, _ = log_format.write_window(window(3000), str(tmp_path), 'json-xz')
    decompressed = []
    original = json_xz.lzma.LZMADecompressor

    class Counting(object):
        def __init__(self, **options):
            self._inner = original(**options)

        def decompress(self, data, max_length=-1):
            part = self._inner.decompress(data, max_length)
            decompressed.append(len(part))
            return part

        def __getattr__(self, name):
            return getattr(self._inner, name)

    monkeypatch.setattr(json_xz.lzma, 'LZMADecompressor', Counting)
    metadata = log_format.read_metadata(path)
    assert metadata['count'] == 6000 and sum(decompressed) == json_xz.METADATA_STEP
    assert metadata == log_format.read_window(path)[0]
    assert sum(decompressed) > 10 * json_xz.METADATA_STEP  # read_window: the whole document


@pytest.mark.parametrize('fmt', FORMATS)
def test_read_metadata_refuses_bad_files_in_one_line(tmp_path, fmt):
    path, _ = log_format.write_window(window(40), str(tmp_path), fmt)
    data = open(path, 'rb').read()
    cases = {'empty': b'', 'garbage': b'not a window at all', 'magic only': data[:16], 'cut': data[:200],
             'no index' if fmt == 'bag-lz4' else 'corrupt': data[:13] + b'\0' * 40 + data[53:]}
    if fmt == 'bag-lz4':
        cases['cut in the messages'] = data[:len(data) // 2]  # its index is gone
    for name, content in cases.items():
        bad = str(tmp_path / ('bad_%s' % name.replace(' ', '_') + os.path.splitext(path)[1]))
        with open(bad, 'wb') as stream:
            stream.write(content)
        with pytest.raises(ValueError) as raised:
            log_format.read_metadata(bad)
        assert str(raised.value).startswith(bad + ': ') and '\n' not in str(raised.value), name
        with pytest.raises(ValueError) as whole:
            log_format.read_window(bad)
        assert str(raised.value) == str(whole.value), name  # read_window's words
    if fmt == 'json-xz':  # cut after its metadata: the metadata is read (read_window sees the cut)
        cut = str(tmp_path / 'cut_after_metadata.json.xz')
        with open(cut, 'wb') as stream:
            stream.write(data[:len(data) * 3 // 4])
        assert log_format.read_metadata(cut) == log_format.read_metadata(path)
        with pytest.raises(ValueError, match='corrupt or truncated xz data'):
            log_format.read_window(cut)
    os.mkfifo(str(tmp_path / 'fifo.bag'))
    with pytest.raises(ValueError, match='is a FIFO'):
        log_format.read_metadata(str(tmp_path / 'fifo.bag'))


def test_bad_metadata_types_are_refused_as_read_window_refuses_them(tmp_path):
    metadata = window_info.window_metadata(window(2), 'bag-lz4')
    metadata['topic_bytes'] = {ODOM: 'many'}
    path = str(tmp_path / 'cc_log_bad.bag')
    bag_lz4.write(path, window(2).records, metadata)
    for reader in (log_format.read_window, log_format.read_metadata):
        with pytest.raises(ValueError, match='metadata: topic_bytes must be an object of counts'):
            reader(path)


# -- stats ------------------------------------------------------------------------------------------------------

def test_stats_from_metadata_is_stats_from_the_records(tmp_path, monkeypatch):
    for number, fmt in enumerate(FORMATS * 3):
        log_format.write_window(window(50 + number, T0 + 100 * number, raw=bool(number % 2)), str(tmp_path), fmt)
    decodes = Decodes(monkeypatch)
    fast = stats.run_stats(str(tmp_path))
    assert decodes.calls == {}
    monkeypatch.setattr(window_info, 'summary_of', lambda metadata: None)  # as for files of an older cc_log
    full = stats.run_stats(str(tmp_path))
    assert decodes.calls['_deserialized'] > 0 and fast == full
    assert fast['windows'] == 6 and fast['topics'][ODOM]['rate_hz'] == pytest.approx(10.0, rel=0.05)


# -- the bench script -------------------------------------------------------------------------------------------

def test_info_speed_bench_quick():
    import subprocess
    import sys
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    done = subprocess.run([sys.executable, os.path.join(root, 'bench', 'info_speed.py'), '--quick'], cwd=root,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:]
    assert done.stdout.startswith('# ') and '\nmachine: ' in done.stdout and '\ndata: ' in done.stdout
    assert '| cclog info ' in done.stdout and '| cclog stats ' in done.stdout and 'total ' in done.stdout
