"""Windows split at split_mb (rosbag record --split --size): a window written a part at a time goes on in a new
file once its file holds the size; each file is a complete bag on its own, the readers (cclog info, cat, stats)
take the files as one window, and the quota deletes the oldest files first."""
import contextlib
import io
import json
import os
import random
import subprocess

import pytest
import yaml
from conftest import assert_rosbag_spans

from cc_log import sim
from cc_log.base.records import LogWindow, Record, Trigger
from cc_log.base.raw_message import class_header, serialized
from cc_log.offline import cli
from cc_log.offline.stats import run_stats
from cc_log.storage import log_format, window_writer
from cc_log.base.event_kinds import DELETED, SPLIT, WRITTEN
from cc_log.storage.window_writer import Job, WindowWriter

rosbag = pytest.importorskip('rosbag')
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402

T0 = 1432235498.0
CAMERA, ODOM = '/camera/image_raw', '/odom'
FRAMES = 10         # frames per part
FRAME_BYTES = 30000  # random pixels: LZ4 cannot shrink them, so a part is ~300 kB on disk
TRIGGERS = [Trigger(T0 + 0.5, 'collision', -2.0, 'bumper')]
METADATA = {'reason': 'collision', 'trigger': 'bumper'}


def frames(k):
    """Part ``k``: FRAMES camera frames of random pixels, stamped k .. k+1 s after T0, as serialized records."""
    rng = random.Random(k)
    records = []
    for i in range(FRAMES):
        stamp = T0 + k + i / float(FRAMES)
        msg = Image(height=100, width=100, encoding='rgb8', step=300, data=rng.randbytes(FRAME_BYTES))
        msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9)) % 1000000000
        records.append(Record(stamp, CAMERA, None, 0, serialized(msg), class_header(CAMERA, Image)))
    return records


def odometry(k):
    """Part ``k`` of the odometry: 5 messages a second."""
    records = []
    for i in range(5):
        stamp = T0 + k + i / 5.0
        msg = Odometry()
        msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9)) % 1000000000
        msg.pose.pose.position.x = k + i / 5.0
        records.append(Record(stamp, ODOM, None, 0, serialized(msg), class_header(ODOM, Odometry)))
    return records


def write_parts(directory, parts, split_mb, max_disk_mb=0, route=False, key=7):
    """Hand a window of ``parts`` parts (``frames``; with ``route``, ``odometry`` to the json-xz route ``numeric``)
    to a writer with ``split_mb``; its events and stats."""
    writer = WindowWriter(directory, 'bag-lz4', max_disk_mb=max_disk_mb, background=False, split_mb=split_mb)
    events = []
    writer.on_event(events.append)
    name = log_format.WindowName('cc_log_20150521T191138.000Z_bumper')
    for k in range(parts):
        final = k == parts - 1
        writer.submit(Job(LogWindow(frames(k), TRIGGERS, k + 1, final, key), METADATA, name=name,
                          last=final and not route))
        if route:
            writer.submit(Job(LogWindow(odometry(k), TRIGGERS, k + 1, final, key), dict(METADATA, route='numeric'),
                              what=window_writer.ROUTE, fmt='json-xz', route='numeric', name=name, last=final))
    writer.close()
    return events, writer.stats()


def bag_records(path):
    with rosbag.Bag(path) as bag:
        return [(topic, raw[1]) for topic, raw, _ in bag.read_messages(raw=True) if topic != '/cc_log/metadata']


def test_a_window_in_parts_is_split_at_the_size_into_bags_rosbag_reads(tmp_path):
    directory = str(tmp_path)
    part_bytes = FRAMES * FRAME_BYTES
    split_bytes = int(1.5 * part_bytes)  # a file is closed once it holds 2 parts: 7 parts make 4 files
    events, stats = write_parts(directory, 7, split_bytes / 1e6)
    files = log_format.window_files(directory)
    assert [os.path.basename(f)[-8:] for f in files] == ['.001.bag', '.002.bag', '.003.bag', '.004.bag']
    assert not log_format.temporary_files(directory)
    expected = [frames(k) for k in range(7)]
    held = [expected[0] + expected[1], expected[2] + expected[3], expected[4] + expected[5], expected[6]]
    for number, (path, records) in enumerate(zip(files, held), 1):
        assert bag_records(path) == [(CAMERA, r.raw) for r in records]  # rosbag reads each file on its own
        size = os.path.getsize(path)
        assert number == 4 or split_bytes <= size <= split_bytes + part_bytes + 20000
        metadata, read = log_format.read_window(path)  # its crc32 checked
        assert metadata['split'] == number and metadata['window_start'] == T0
        assert metadata['count'] == len(records) and metadata['start'] == records[0].stamp
        assert [t['reason'] for t in metadata['triggers']] == ['collision']
    assert log_format.read_metadata(files[-1])['splits'] == 4
    assert log_format.read_metadata(files[-1])['window_end'] == expected[-1][-1].stamp
    # the readers: one window, every message once, in order
    [one] = log_format.window_sets(files[::-1])
    assert one == files
    metadata, records = log_format.read_window_set(one)
    assert [r.raw for r in records] == [r.raw for part in expected for r in part]
    assert metadata['count'] == 70 and metadata['splits'] == 4 and metadata['files'] == files
    assert (metadata['start'], metadata['end']) == (T0, expected[-1][-1].stamp)
    assert [e.kind for e in events] == [SPLIT, SPLIT, SPLIT, WRITTEN]
    assert [e.path for e in events] == files and events[-1].job.messages == 70  # WRITTEN says the whole window
    assert stats['split_files'] == 3 and stats['windows_saved'] == 1
    assert stats['stored_bytes'] == sum(os.path.getsize(f) for f in files) and stats['messages_kept'] == 70


def test_rosbag_says_each_bag_of_a_window_spans_its_first_to_its_last_record(tmp_path):
    """rosbag's start and end (of a bag's first and last chunk): a whole window in several chunks, a window written
    a part at a time and each file of a split one end at their last record, not at the metadata written last."""
    writer = WindowWriter(str(tmp_path / 'whole'), 'bag-lz4', background=False)
    writer.submit(Job(LogWindow(frames(0) + frames(1) + frames(2), TRIGGERS), METADATA))
    writer.close()
    write_parts(str(tmp_path / 'parts'), 3, 0)
    write_parts(str(tmp_path / 'split'), 7, 1.5 * FRAMES * FRAME_BYTES / 1e6)
    expected = {}
    for folder in ('whole', 'parts', 'split'):
        for path in log_format.window_files(str(tmp_path / folder)):
            stamps = [record.stamp for record in log_format.read_window(path)[1]]
            expected[path] = (min(stamps), max(stamps))
    assert len(expected) == 6
    assert expected[log_format.window_files(str(tmp_path / 'parts'))[0]] == (T0, T0 + 2.9)
    assert_rosbag_spans(expected)


def test_a_window_below_the_size_or_without_it_is_one_file_of_the_usual_name(tmp_path):
    for split_mb, folder in ((0, 'off'), (100, 'large')):
        directory = str(tmp_path / folder)
        events, stats = write_parts(directory, 3, split_mb)
        path, = log_format.window_files(directory)
        assert os.path.basename(path) == 'cc_log_20150521T191138.000Z_bumper.bag'
        metadata = log_format.read_metadata(path)
        assert 'split' not in metadata and 'splits' not in metadata and metadata['count'] == 30
        assert stats['split_files'] == 0 and [e.kind for e in events] == [WRITTEN]


def test_a_split_window_with_a_route_is_one_window_to_info_cat_and_stats(tmp_path):
    directory = str(tmp_path)
    write_parts(directory, 5, 1.5 * FRAMES * FRAME_BYTES / 1e6, route=True)  # two parts a file
    files = log_format.window_files(directory)
    own = [f for f in files if '+' not in os.path.basename(f)]
    routed = [f for f in files if '+numeric' in os.path.basename(f)]
    assert len(own) == 3 and len(routed) == 5  # bags: parts 1-2, 3-4, 5; json-xz: a file per part
    for path in routed:  # each json-xz file is a whole xz document
        text = subprocess.run(['xz', '-dc', path], check=True, stdout=subprocess.PIPE).stdout
        assert json.loads(text)['metadata']['route'] == 'numeric'
    [one] = log_format.window_sets([routed[2]])
    assert one[:3] == own and sorted(one[3:]) == routed
    metadata, records = log_format.read_window_set(one)
    assert metadata['counts'] == {CAMERA: 50, ODOM: 25} and metadata['splits'] == 3
    assert [r.stamp for r in records] == sorted(r.stamp for r in records)
    assert [r.raw for r in records if r.topic == CAMERA] == [r.raw for k in range(5) for r in frames(k)]
    positions = [r.msg.pose.pose.position.x for r in records if r.topic == ODOM]
    assert positions == [k + i / 5.0 for k in range(5) for i in range(5)]
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        assert cli.main(['info', directory, '--json']) == 0
    info = json.loads(text.getvalue())
    assert info['total']['windows'] == 1 and info['total']['messages'] == 75
    window, = info['windows']
    assert window['topics'] == {CAMERA: 50, ODOM: 25} and window['splits'] == 3 and window['files'] == one
    assert window['bytes'] == sum(os.path.getsize(f) for f in files)
    assert (window['start'], window['end']) == (T0, T0 + 4.9)
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        assert cli.main(['info', directory]) == 0
    assert 'split at split_mb: 3 files of its own' in text.getvalue()
    stats = run_stats(directory)
    assert stats['windows'] == 1 and stats['windows_by_trigger'] == {'bumper': 1}


def test_the_quota_deletes_a_split_windows_oldest_files_first_and_the_rest_reads_as_the_window(tmp_path):
    directory = str(tmp_path)
    part_bytes = FRAMES * FRAME_BYTES
    events, stats = write_parts(directory, 6, part_bytes / 1e6, max_disk_mb=2.5 * part_bytes / 1e6)
    deleted = [e.path for e in events if e.kind == DELETED]
    closed = [e.path for e in events if e.kind in (SPLIT, WRITTEN)]
    assert len(closed) == 6 and deleted == closed[:len(deleted)] and 2 <= len(deleted) <= 4  # the oldest first
    files = log_format.window_files(directory)
    assert files == closed[len(deleted):] and sum(map(os.path.getsize, files)) <= 2.5 * part_bytes + 20000
    [one] = log_format.window_sets(files)
    metadata, records = log_format.read_window_set(one)  # what is left: the window's end, in order
    assert [r.raw for r in records] == [r.raw for k in range(len(deleted), 6) for r in frames(k)]
    assert metadata['splits'] == 6 and metadata['start'] == T0 + len(deleted)


def test_two_windows_of_one_name_keep_their_files_apart(tmp_path):
    directory = str(tmp_path)
    write_parts(directory, 3, FRAMES * FRAME_BYTES / 1e6)
    write_parts(directory, 3, 0)  # the same window unsplit: not taken for a file of the first
    write_parts(directory, 3, FRAMES * FRAME_BYTES / 1e6)
    names = [os.path.basename(f) for f in log_format.window_files(directory)]
    assert names == ['cc_log_20150521T191138.000Z_bumper.001.bag', 'cc_log_20150521T191138.000Z_bumper.002.bag',
                     'cc_log_20150521T191138.000Z_bumper.003.bag', 'cc_log_20150521T191138.000Z_bumper_1.bag',
                     'cc_log_20150521T191138.000Z_bumper_2.001.bag', 'cc_log_20150521T191138.000Z_bumper_2.002.bag',
                     'cc_log_20150521T191138.000Z_bumper_2.003.bag']
    sets = log_format.window_sets(log_format.window_files(directory))
    assert [len(files) for files in sets] == [3, 1, 3]
    assert all(log_format.read_window_set(files)[0]['count'] == 30 for files in sets)


# -- end to end: cclog replay --split-mb --------------------------------------------------------------------

def test_cclog_replay_splits_windows_and_info_lists_each_once_with_its_total(tmp_path):
    bag = str(tmp_path / 'run.bag')
    sim.simulate_to_bag(bag, sim.SimConfig(seed=3, minutes=0.5, anomalies=0, camera=True))
    cfg = tmp_path / 'split.yaml'
    cfg.write_text(yaml.safe_dump({
        'driving_topic': sim.ODOM_TOPIC, 'topics': ['*'], 'windows': {'pre': '2s', 'post': '2s', 'max': 40},
        'format': 'bag-lz4', 'triggers': [{'name': 'every10s', 'kind': 'periodic', 'every': '10s'}]}))
    whole, split = str(tmp_path / 'whole'), str(tmp_path / 'split')
    assert cli.main(['replay', bag, '--config', str(cfg), '--out', whole]) == 0
    sizes = [os.path.getsize(f) for f in log_format.window_files(whole)]
    split_mb = min(sizes) / 3e6  # every window in about three files or more
    assert cli.main(['replay', bag, '--config', str(cfg), '--out', split, '--split-mb', str(split_mb)]) == 0
    files = log_format.window_files(split)
    assert len(files) >= 3 * len(sizes) and all(log_format.split_number(f) for f in files)
    for path in files:
        with rosbag.Bag(path) as reader:  # each file a bag of its own
            assert reader.get_message_count() > 0

    def info(directory):
        text = io.StringIO()
        with contextlib.redirect_stdout(text):
            assert cli.main(['info', directory, '--json']) == 0
        return json.loads(text.getvalue())
    before, after = info(whole), info(split)
    assert after['total']['windows'] == before['total']['windows'] == len(sizes)
    assert after['total']['messages'] == before['total']['messages']
    for one, other in zip(before['windows'], after['windows']):
        assert other['topics'] == one['topics'] and (other['start'], other['end']) == (one['start'], one['end'])
        assert other['splits'] == len(other['files']) >= 3
    for files_of_one, path in zip(log_format.window_sets(files), log_format.window_files(whole)):
        _, records = log_format.read_window_set(files_of_one)
        assert [r.raw for r in records] == [r.raw for r in log_format.read_window(path)[1]]
