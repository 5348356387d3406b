"""Cameras and lidars in windows: one file per window however large, per-topic limits, one clock, overload
said and counted. Pure: no roscore (the node's side is in the rostests); rosbag reads what was written."""
import contextlib
import errno
import io
import os

import pytest
import yaml

from conftest import cclog
from cc_log.offline import cli
from cc_log.storage import log_format, recovery
from cc_log.storage.formats import bag_lz4
from cc_log.storage.bag import bag_writer
from cc_log.base.raw_message import class_header, serialized
from cc_log.logger.smart import SmartLogger
from cc_log.buffer.window_prep import HEAVY_BYTES
from cc_log.base.records import LogWindow, Record, Trigger
from cc_log.logger.options import TopicLimits
from cc_log.buffer.window_buffer import WindowBuffer

rosbag = pytest.importorskip('rosbag')
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402

T0 = 1432235498.0
ODOM, CAMERA, LIDAR = '/odom', '/camera/image_raw', '/velodyne_points'


def odometry(stamp):
    msg = Odometry()
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9)) % 1000000000
    msg.header.frame_id = 'odom'
    msg.twist.twist.linear.x = 0.5
    return msg


def image(stamp, size=(160, 120), seed=0):
    msg = Image(height=size[1], width=size[0], encoding='rgb8', step=3 * size[0])
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9)) % 1000000000
    msg.data = bytes((seed + k) % 251 for k in range(3 * size[0] * size[1]))
    return msg


CONNECTIONS = {ODOM: class_header(ODOM, Odometry), CAMERA: class_header(CAMERA, Image),
               LIDAR: class_header(LIDAR, Image)}


def stream(seconds, camera_hz=30, odom_hz=50, size=(160, 120), camera_clock=0.0, t0=T0):
    """Records as the intake hands them over: odometry and camera frames in arrival order; the camera's header
    stamps are ``camera_clock`` seconds off the arrival (another clock)."""
    events = [(t0 + k / float(odom_hz), ODOM) for k in range(int(seconds * odom_hz))]
    events += [(t0 + (k + 0.5) / float(camera_hz), CAMERA) for k in range(int(seconds * camera_hz))]
    records = []
    for arrival, topic in sorted(events):
        msg = odometry(arrival) if topic == ODOM else image(arrival + camera_clock, size, seed=int(arrival * 30))
        records.append(Record(arrival, topic, None, 0, serialized(msg), CONNECTIONS[topic]))
    return records


def feed(logger, records, trigger_at=None, before=2.0, after=2.0, batch=16):
    for k in range(0, len(records), batch):
        logger.on_records(records[k:k + batch])
        if trigger_at is not None and records[k].stamp >= trigger_at:
            ok, why = logger.trigger_now('manual', before, after)
            assert ok, why
            trigger_at = None


def one_window(tmp_path, records, trigger_at, before, after):
    """``(logger, (metadata, records))``: ``records`` through a bag-lz4 logger of ODOM and CAMERA (1 s pre/post) with
    a manual window at ``trigger_at``, closed, and its one window file read."""
    logger = SmartLogger(None, str(tmp_path), 'bag-lz4', '1s', '1s', driving_topic=ODOM, side_topics=[CAMERA],
                         background=False)
    feed(logger, records, trigger_at=trigger_at, before=before, after=after)
    logger.close()
    path, = log_format.window_files(str(tmp_path))
    return logger, log_format.read_window(path)


def bag_counts(path):
    with rosbag.Bag(path) as bag:
        return dict((topic, info.message_count) for topic, info in bag.get_type_and_topic_info().topics.items())


# -- one file per window -------------------------------------------------------------------------------

def test_a_window_larger_than_the_budget_is_one_bag_that_rosbag_reads_whole(tmp_path):
    records = stream(12, size=(320, 240))  # 30 Hz x 230 kB frames: ~83 MB of frames in all
    logger = SmartLogger(None, str(tmp_path), 'bag-lz4', '2s', '2s', driving_topic=ODOM, side_topics=[CAMERA],
                         background=False, max_buffer_mb=16)
    feed(logger, records, trigger_at=T0 + 3.0, before=2.0, after=7.0)
    logger.close()
    files = log_format.window_files(str(tmp_path))
    assert len(files) == 1 and not log_format.temporary_files(str(tmp_path))
    metadata, kept = log_format.read_window(files[0])  # crc32 of every record checked
    start, end = metadata['start'], metadata['end']
    assert T0 + 0.9 <= start <= T0 + 1.4 and end - start >= 8.5
    counts = bag_counts(files[0])
    for topic in (ODOM, CAMERA):  # every message of the window's span, once
        assert counts[topic] == sum(1 for r in records if r.topic == topic and start <= r.stamp <= end)
    assert counts[CAMERA] * 230400 > 3 * 16e6  # far more than the budget: written a part at a time
    assert metadata['part'] == 0 and metadata['count'] == len(kept) == counts[CAMERA] + counts[ODOM]
    assert [r.stamp for r in kept] == sorted(r.stamp for r in kept)
    assert logger.stats()['messages_lost'] == logger.stats()['messages_shed'] == 0


class FillsUp(io.BytesIO):
    """A file on a disk that is full once it holds ``room`` bytes until ``freed``."""

    def __init__(self, room):
        super().__init__()
        self.room = room

    def write(self, data):
        if self.tell() + len(data) > self.room:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return super().write(data)


def part(k, n=30):
    return [Record(T0 + k + i / float(n), CAMERA, None, 0, serialized(image(T0 + k + i / float(n), seed=k + i)),
                   CONNECTIONS[CAMERA]) for i in range(n)]


def written(tmp_path, data, name='w.bag'):
    path = str(tmp_path / name)
    with open(path, 'wb') as out:
        out.write(data)
    return path


def test_a_part_that_fills_the_disk_is_rolled_back_and_written_again(tmp_path):
    target = FillsUp(room=10 ** 9)
    window = bag_lz4.WindowStream(target)
    window.append(part(0), {'reason': 'x'})
    full = target.room = target.tell() + 1000
    with pytest.raises(OSError):
        window.append(part(1), None)  # 30 more frames do not fit
    assert target.getbuffer().nbytes < full
    target.room = 10 ** 9  # space again
    window.append(part(1), None)
    window.finish({'reason': 'x'})
    metadata, records = bag_lz4.read(written(tmp_path, target.getvalue()))
    assert [r.stamp for r in records] == [r.stamp for r in part(0) + part(1)]  # each once, in order
    assert [r.raw for r in records] == [r.raw for r in part(0) + part(1)]
    assert metadata['reason'] == 'x' and metadata['layout'] == 4


def test_a_rolled_back_bag_stream_reads_as_if_nothing_had_failed(tmp_path):
    messages = [(CAMERA,) + bag_lz4.bag_stamp(r.stamp) + (r.raw,) for r in part(0) + part(1)]
    headers = {CAMERA: CONNECTIONS[CAMERA]}
    out = io.BytesIO()
    bag = bag_writer.BagStream(out)
    for topic, secs, nsecs, data in messages[:20]:
        bag.write(topic, secs, nsecs, data, headers[topic])
    bag.mark()
    for topic, secs, nsecs, data in messages[20:40]:
        bag.write(topic, secs, nsecs, data, headers[topic])
    bag.rollback()  # as if those 20 had failed
    for topic, secs, nsecs, data in messages[20:]:
        bag.write(topic, secs, nsecs, data, headers[topic])
    bag.close()
    with rosbag.Bag(written(tmp_path, out.getvalue())) as read:
        assert [raw[1] for _, raw, _ in read.read_messages(raw=True)] == [m[3] for m in messages]
    again = io.BytesIO()  # the same writes without the failed ones: the same bytes
    bag = bag_writer.BagStream(again)
    for k, (topic, secs, nsecs, data) in enumerate(messages):
        if k == 20:
            bag.mark()
        bag.write(topic, secs, nsecs, data, headers[topic])
    bag.close()
    assert out.getvalue() == again.getvalue()


def test_a_window_cut_off_mid_stream_is_recovered_with_its_trigger(tmp_path):
    directory = str(tmp_path)
    triggers = [Trigger(T0 + 0.5, 'collision', -2.0, 'bumper')]
    stream_file = log_format.WindowFile(directory, 'bag-lz4')
    stream_file.append(LogWindow(part(0), triggers, 1, False, 7), {'reason': 'collision', 'trigger': 'bumper'})
    stream_file.append(LogWindow(part(1), triggers, 2, False, 7), {'reason': 'collision', 'trigger': 'bumper'})
    stream_file.abandon()  # the process dies before the last part
    leftover, = log_format.temporary_files(directory)
    dead = leftover.rpartition('.tmp-')[0] + '.tmp-999999999'
    os.rename(leftover, dead)
    outcome = recovery.recover(dead)
    assert outcome.status in (recovery.COMPLETE, recovery.PARTIAL) and outcome.messages == 60
    metadata, records = log_format.read_window(outcome.path)
    assert metadata['trigger'] == 'bumper' and [t['reason'] for t in metadata['triggers']] == ['collision']
    assert [r.raw for r in records] == [r.raw for r in part(0) + part(1)]


# -- per-topic limits ------------------------------------------------------------------------------------

def test_per_topic_pre_and_post_keep_only_their_span_of_a_heavy_topic():
    limits = {CAMERA: TopicLimits(pre=0.5, post=0.25)}
    buffer = WindowBuffer(pre='2s', post='2s', max_buffer_mb=0, topic_limits=limits)
    done = []
    for record in stream(10):
        record = record._replace(stamp=record.stamp, cost=len(record.raw))
        done += buffer.add(record) if record.topic == ODOM else buffer.add_side(record)
        if record.topic == ODOM and abs(record.stamp - (T0 + 5.0)) < 1e-6:
            done += buffer.trigger('manual')
    done += buffer.flush()
    window, = done
    odom = [r.stamp for r in window.records if r.topic == ODOM]
    camera = [r.stamp for r in window.records if r.topic == CAMERA]
    assert odom[0] == pytest.approx(T0 + 3.0) and odom[-1] == pytest.approx(T0 + 7.0)
    assert T0 + 4.5 <= camera[0] < T0 + 4.55 and T0 + 5.2 < camera[-1] <= T0 + 5.25


def test_a_topic_memory_cap_holds_outside_windows():
    cost = len(stream(0.1)[-1].raw)
    limits = {CAMERA: TopicLimits(max_mb=10 * cost / 1e6)}
    buffer = WindowBuffer(pre='2s', post='2s', max_buffer_mb=0, topic_limits=limits)
    for record in stream(5):
        record = record._replace(cost=len(record.raw))
        buffer.add(record) if record.topic == ODOM else buffer.add_side(record)
    assert sum(1 for r in buffer._side[CAMERA]) == 10 and buffer.limited > 100
    assert buffer.trimmed == 0  # its own cap, not the buffer budget (no budget here): no WARN on /diagnostics


# -- one clock ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize('offset', [1.2e9, -3.0e7, 30.0])  # wall clock next to a 2015 bag, far behind, 30 s ahead
def test_a_topic_on_another_clock_neither_stretches_nor_empties_the_window(offset, tmp_path):
    records = stream(8, camera_clock=offset)
    logger, (metadata, kept) = one_window(tmp_path, records, T0 + 4.0, 1.0, 1.0)
    assert metadata['end'] - metadata['start'] <= 2.2  # pre + post, not the distance between the clocks
    assert 55 <= metadata['counts'][CAMERA] <= 65  # the camera's 2 s, by arrival
    stats = logger.stats()
    assert stats['restamped_by_topic'] == {CAMERA: 8 * 30} and stats['messages_restamped'] == 240


def test_a_bag_played_without_its_clock_keeps_its_own_stamps(tmp_path):
    """Every topic stamped 11 years before it arrives (``rosbag play`` without ``--clock``): one clock, the bag's."""
    records = [r._replace(stamp=r.stamp + 3.5e8) for r in stream(6, camera_clock=0.0)]  # arrival: now-ish
    logger, (metadata, kept) = one_window(tmp_path, records, T0 + 3.5e8 + 3.0, 1.0, 1.0)
    assert T0 + 1.9 <= metadata['start'] <= T0 + 2.2 and metadata['end'] - metadata['start'] <= 2.1  # header stamps
    assert logger.stats()['messages_restamped'] == 0 and 55 <= metadata['counts'][CAMERA] <= 65


def test_stamps_a_little_off_the_arrival_are_kept():
    records = stream(4, camera_clock=-0.3)  # a camera pipeline's latency: its own stamps stay
    logger = SmartLogger(None, '/nonexistent-unused', 'bag-lz4', '1s', '1s', driving_topic=ODOM,
                         side_topics=[CAMERA], background=False)
    feed(logger, records)
    assert logger.stats()['messages_restamped'] == 0


# -- overload ------------------------------------------------------------------------------------------------

def test_a_writer_that_falls_behind_drops_heavy_frames_counted_never_light_ones(tmp_path):
    """json-xz compresses frames at a few MB/s: far slower than they come. Within the budget, the frames that do
    not fit are dropped evenly and counted per topic; every odometry message of the window is kept."""
    records = stream(10, size=(320, 240))
    assert len(records[-1].raw) >= HEAVY_BYTES or len(records[-2].raw) >= HEAVY_BYTES
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '1s', '1s', driving_topic=ODOM, side_topics=[CAMERA],
                         max_buffer_mb=12)
    feed(logger, records, trigger_at=T0 + 1.5, before=1.0, after=30.0)
    peak = logger.stats()['buffered_bytes'] + logger.stats()['bytes_queued']
    assert peak <= 12e6 + 2 * 230400
    assert logger.close(120)
    stats = logger.stats()
    assert stats['messages_shed'] > 0 and set(stats['shed_by_topic']) == {CAMERA}
    kept = [log_format.read_window(path) for path in log_format.window_files(str(tmp_path))]
    start = min(meta['start'] for meta, _ in kept)
    assert T0 + 0.5 <= start <= T0 + 1.0
    in_window = [r for r in records if start <= r.stamp]  # open to the end of the stream
    odom_kept = sum(meta['counts'].get(ODOM, 0) for meta, _ in kept)
    assert odom_kept == sum(1 for r in in_window if r.topic == ODOM)  # every light message
    camera_kept = sum(meta['counts'].get(CAMERA, 0) for meta, _ in kept)
    dropped = sum(meta.get('dropped', {}).get(CAMERA, 0) for meta, _ in kept)
    assert dropped == stats['shed_by_topic'][CAMERA]
    assert camera_kept + dropped == sum(1 for r in in_window if r.topic == CAMERA)  # each frame kept or counted
    info = cclog('info', str(tmp_path))
    sets = log_format.window_sets(log_format.window_files(str(tmp_path)))  # a window's parts are one window
    dropping = sum(1 for files in sets if any(log_format.read_metadata(path).get('dropped') for path in files))
    assert info.returncode == 0 and info.stdout.count('DROPPED') == dropping > 0
    assert sum(int(line.split()[1]) for line in info.stdout.splitlines() if 'DROPPED' in line) == dropped


def test_an_offline_replay_waits_for_the_writer_and_keeps_every_frame(tmp_path):
    """cclog replay has no live stream to keep up with: a writer slower than the reading (json-xz of 67 kB frames
    within 4 MB) makes the reading wait. Each window file holds every message of its span; nothing DROPPED."""
    records = stream(6, size=(160, 140))
    assert min(len(r.raw) for r in records if r.topic == CAMERA) >= HEAVY_BYTES
    bag = str(tmp_path / 'camera.bag')
    with open(bag, 'wb') as out:
        bag_writer.write_bag(out, map(bag_lz4.bag_message, records), CONNECTIONS)
    cfg = tmp_path / 'camera.yaml'
    cfg.write_text(yaml.safe_dump({'driving_topic': ODOM, 'topics': [CAMERA], 'format': 'json-xz',
                                   'windows': {'pre': '1s', 'post': '1s'},
                                   'triggers': [{'name': 'every2s', 'kind': 'periodic', 'every': '2s'}]}))
    out, said = str(tmp_path / 'out'), io.StringIO()
    with contextlib.redirect_stdout(said):
        assert cli.main(['replay', bag, '--config', str(cfg), '--out', out, '--max-buffer-mb', '4']) == 0
        assert cli.main(['info', out]) == 0
    files = log_format.window_files(out)
    assert len(files) > 3  # windows in parts: the budget holds about 60 frames
    for path in files:
        metadata, kept = log_format.read_window(path)
        for topic in (ODOM, CAMERA):
            span = [r.stamp for r in records if r.topic == topic and metadata['start'] <= r.stamp <= metadata['end']]
            assert [r.stamp for r in kept if r.topic == topic] == pytest.approx(span, abs=1e-6), path
        assert 'dropped' not in metadata
    assert sum(r.topic == CAMERA for path in files for r in log_format.read_window(path)[1]) >= 110
    assert 'DROPPED' not in said.getvalue()


# -- configuration -------------------------------------------------------------------------------------------

def test_topic_limits_from_the_configuration_and_from_a_launch_argument():
    from cc_log.logger import config, options
    text = '{camera/image_raw: {pre: 2s, post: 500ms, max_mb: 64}, /scan: {post: 1s}}'
    for value in (text, {'camera/image_raw': {'pre': '2s', 'post': '500ms', 'max_mb': 64}, '/scan': {'post': '1s'}}):
        limits = options.parse_topic_limits(value)
        assert limits == {'camera/image_raw': TopicLimits(2.0, 0.5, 64.0), '/scan': TopicLimits(None, 1.0, 0.0)}
    cfg = config.Config.from_dict({'topic_limits': text, 'driving_topic': 'odom'})
    options = cfg.logger_options([], config.global_name)
    assert options['topic_limits'] == {'/camera/image_raw': TopicLimits(2.0, 0.5, 64.0),
                                       '/scan': TopicLimits(None, 1.0, 0.0)}


@pytest.mark.parametrize('value, error', [
    ('{camera: {pre: soon}}', "topic_limits.camera.pre: 'soon' is not a duration"),
    ('{camera: {size: 1}}', "topic_limits.camera: unknown key 'size'"),
    ('[camera]', 'topic_limits: a mapping of topic names to {pre, post, max_mb}, not list'),
    ('{camera: {max_mb: lots}}', 'topic_limits.camera.max_mb'),
    ('{camera: {pre: [1', 'topic_limits: not YAML'),
])
def test_bad_topic_limits_are_one_line_naming_the_key(value, error):
    from cc_log.logger import options
    with pytest.raises(ValueError) as raised:
        options.parse_topic_limits(value)
    assert error in str(raised.value) and '\n' not in str(raised.value)


def test_a_latched_message_opens_a_window_in_parts_once(tmp_path):
    from std_msgs.msg import String
    latched = dict(class_header('/tf_static', String), latching='1', callerid='/robot_state_publisher')
    static = Record(T0 - 10.0, '/tf_static', None, 0, serialized(String(data='base_link->camera')), latched)
    records = [static] + stream(6, size=(320, 240))
    logger = SmartLogger(None, str(tmp_path), 'bag-lz4', '1s', '1s', driving_topic=ODOM,
                         side_topics=[CAMERA, '/tf_static'], background=False, max_buffer_mb=8)
    feed(logger, records, trigger_at=T0 + 1.5, before=1.0, after=3.0)
    logger.close()
    path, = log_format.window_files(str(tmp_path))
    metadata, kept = log_format.read_window(path)
    assert metadata['counts']['/tf_static'] == 1 and kept[0].topic == '/tf_static'  # once, first, as rosbag
    assert kept[0].stamp == metadata['start'] and kept[0].connection['latching'] == '1'
    assert metadata['counts'][CAMERA] * 230400 > 2 * 8e6  # written in several parts


@pytest.mark.parametrize('before, after', [(1.0, 1e12), (1e9, 1.0), (1.0, float('inf')), (-1.0, 1.0)])
def test_a_manual_window_asks_for_at_most_a_day(before, after, tmp_path):
    logger = SmartLogger(None, str(tmp_path), 'bag-lz4', '1s', '1s', driving_topic=ODOM, background=False)
    feed(logger, stream(1, camera_hz=1))
    ok, why = logger.trigger_now('x', before, after)
    assert not ok and 'seconds from 0 to 86400' in why and len(why) < 120
    assert logger.trigger_now('x', 1.0, 86400.0)[0]


def test_a_window_still_open_at_the_end_keeps_the_frames_after_the_last_odometry(tmp_path):
    records = stream(3)
    records.append(Record(T0 + 3.01, CAMERA, None, 0, serialized(image(T0 + 3.01)), CONNECTIONS[CAMERA]))
    logger, (metadata, kept) = one_window(tmp_path, records, T0 + 1.0, 0.5, 60.0)
    assert kept[-1].topic == CAMERA and kept[-1].stamp == pytest.approx(T0 + 3.01)
    assert metadata['counts'][CAMERA] == sum(1 for r in records if r.topic == CAMERA and r.stamp >= metadata['start'])
