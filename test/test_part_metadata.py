"""A long window written in parts says each trigger once: a json-xz window (a file per part) says in each part's
metadata the triggers that came since the part before it, not every trigger since the window opened; a bag-lz4
window (one file) says them all once in its final metadata."""
import io
import os

import pytest

from cc_log.base.raw_message import class_header
from cc_log.base.records import Record
from cc_log.buffer.window_buffer import WindowBuffer
from cc_log.storage import log_format
from cc_log.storage.window_writer import Job, WindowWriter

rosbag = pytest.importorskip('rosbag')
from nav_msgs.msg import Odometry  # noqa: E402

T0 = 1432235498.0
ODOM = '/odom'
CONNECTION = class_header(ODOM, Odometry)


def record(k):
    msg = Odometry()
    stamp = T0 + k * 0.1
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9)) % 1000000000
    msg.header.frame_id = 'odom'
    msg.pose.pose.position.x = 0.01 * k
    buff = io.BytesIO()
    msg.serialize(buff)
    return Record(stamp, ODOM, None, len(buff.getvalue()), buff.getvalue(), CONNECTION)


def write_triggered_stream(directory, fmt, messages=600, every=5):
    """A stream where a trigger fires at every ``every``-th message, so one window stays open and is handed on in
    parts of 50 messages; returns the triggers fired."""
    buffer = WindowBuffer(pre='10', post='20', max_window='50')
    writer = WindowWriter(directory, fmt, background=False)
    fired = []
    for k in range(messages):
        windows = buffer.add(record(k))
        if k >= 20 and k % every == 0:
            windows += buffer.trigger('anomaly', score=-float(k), name='classifier')
            fired.append(T0 + k * 0.1)
        for window in windows:
            writer.submit(Job(window, {}))
    for window in buffer.flush():
        writer.submit(Job(window, {}))
    writer.close()
    return fired


def window_files(directory):
    return sorted(os.path.join(directory, name) for name in os.listdir(directory))


def test_each_json_xz_part_says_only_its_own_triggers(tmp_path):
    fired = write_triggered_stream(str(tmp_path), 'json-xz')
    paths = window_files(str(tmp_path))
    assert len(paths) >= 10  # one window, many parts
    said, count = [], 0
    for path in paths:
        metadata, records = log_format.read_window(path)
        assert metadata['part'] >= 1
        stamps = [trigger['stamp'] for trigger in metadata['triggers']]
        assert all(records[0].stamp - 1e-6 <= stamp <= records[-1].stamp + 1e-6 for stamp in stamps), path
        said += stamps
        count += len(records)
        piece = log_format.parse_piece(os.path.basename(path))  # one name, the window's first trigger's
        assert piece.name.endswith('_classifier') and piece.number == metadata['part'] and piece.route is None
    assert sorted(said) == pytest.approx(fired)  # every trigger said once over the parts
    [one] = log_format.window_sets(paths)  # the readers: one window of all its parts
    metadata, records = log_format.read_window_set(one)
    assert len(records) == 590 and [t['stamp'] for t in metadata['triggers']] == pytest.approx(sorted(said))
    assert count == 590  # from 10 messages before the first trigger to the end of the stream


def test_a_bag_lz4_window_in_parts_says_every_trigger_once(tmp_path):
    fired = write_triggered_stream(str(tmp_path), 'bag-lz4')
    path, = window_files(str(tmp_path))
    metadata, records = log_format.read_window(path)
    assert [trigger['stamp'] for trigger in metadata['triggers']] == pytest.approx(fired)
    assert len(records) == 590  # from 10 messages before the first trigger to the end of the stream
