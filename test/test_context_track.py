"""The context track: topic/rate parsing, thinning, rotation, raw writes, quota and crash leftovers (real rosbag)."""
import os

import pytest
import rosbag
from conftest import assert_rosbag_spans, fill_disk
from nav_msgs.msg import Odometry
from std_msgs.msg import String

from cc_log.base import event_kinds, safe_files
from cc_log.storage import context_track, window_writer
from cc_log.storage.context_track import ContextTrack, Tee, parse_topics
from cc_log.base.records import Record


def odom(stamp):
    msg = Odometry()
    msg.header.stamp.secs = int(stamp)
    msg.header.stamp.nsecs = int(round((stamp - int(stamp)) * 1e9))
    msg.pose.pose.position.x = stamp
    return msg


def serialized_odom(stamp, callerid, latching):
    """(message, its serialized bytes, a publisher's connection header) of an odometry message."""
    import io
    msg = odom(stamp)
    buffer = io.BytesIO()
    msg.serialize(buffer)
    return msg, buffer.getvalue(), {'topic': '/odom', 'type': Odometry._type, 'md5sum': Odometry._md5sum,
                                    'message_definition': Odometry._full_text, 'callerid': callerid,
                                    'latching': latching}


def files(directory):
    folder = os.path.join(str(directory), context_track.SUBDIRECTORY)
    return sorted(os.path.join(folder, name) for name in os.listdir(folder))


def read(path):
    with rosbag.Bag(path) as bag:
        return [(topic, msg, t.to_sec()) for topic, msg, t in bag.read_messages()]


def test_parse_topics_rates_aliases_and_errors():
    assert parse_topics('odom:1 amcl_pose /diagnostics') == {'odom': 1.0, 'amcl_pose': None, '/diagnostics': None}
    assert parse_topics(['scan:0.5hz'], 'x') == {'scan': 0.5}
    assert parse_topics({'odom': 2}) == {'odom': 2.0}
    assert parse_topics('odom_1hz amcl_pose', aliases=context_track.BWI_ALIASES) == {'odom': 1.0, 'amcl_pose': None}
    for bad in ('odom:0', 'odom:fast', 'a:b:c', 5):
        with pytest.raises(ValueError, match='^context_topics'):
            parse_topics(bad)


def test_thins_100hz_odometry_to_exactly_one_message_per_second(tmp_path):
    track = ContextTrack(tmp_path, parse_topics('odom:1 chatter'))
    for i in range(3000):  # 30 s at 100 Hz
        track.on_message('odom', odom(1000.0 + i * 0.01), None)
    track.on_message('chatter', String(data='x'), 1029.5)
    track.on_message('other', String(data='not tracked'), 1010.0)
    track.close()
    [path] = files(tmp_path)
    assert os.path.basename(path).startswith('cc_log_context_') and path.endswith('.bag')
    messages = read(path)
    stamps = [t for topic, _, t in messages if topic == 'odom']
    assert len(stamps) == 30
    assert all(abs(b - a - 1.0) < 1e-6 for a, b in zip(stamps, stamps[1:]))
    assert [topic for topic, _, _ in messages].count('chatter') == 1
    assert 'other' not in [topic for topic, _, _ in messages]
    assert track.stats()['messages_thinned'] == 3000 - 30
    with rosbag.Bag(path) as bag:
        assert bag.get_compression_info().compression == 'lz4'


def test_bwi_odom_1hz_is_stored_under_its_own_name(tmp_path):
    names = {}
    rates = parse_topics('odom_1hz amcl_pose', aliases=context_track.BWI_ALIASES, names=names)
    assert (rates, names) == ({'odom': 1.0, 'amcl_pose': None}, {'odom': 'odom_1hz'})
    track = ContextTrack(tmp_path, rates, names=names)
    for i in range(300):
        track.on_message('odom', odom(1000.0 + i * 0.01), None)
    track.close()
    [path] = files(tmp_path)
    assert [(topic, t) for topic, _, t in read(path)] == [('odom_1hz', 1000.0), ('odom_1hz', 1001.0),
                                                          ('odom_1hz', 1002.0)]


def test_rotates_by_stamps_and_on_a_jump_back(tmp_path):
    track = ContextTrack(tmp_path, {'odom': None}, rotate=10)
    for second in list(range(25)) + [3, 4]:  # 0-9, 10-19, 20-24, then time goes back
        track.on_message('odom', odom(100.0 + second), None)
    track.close()
    paths = files(tmp_path)
    # named by their first stamps: 100 (10 messages), 103 (2, after the jump back), 110 (10), 120 (5)
    assert [len(read(path)) for path in paths] == [10, 2, 10, 5]
    assert track.stats()['files_closed'] == 4


def test_raw_records_keep_bytes_and_connection_header(tmp_path):
    msg, raw, connection = serialized_odom(5.0, '/sim', '1')
    track = ContextTrack(tmp_path, {'/odom': None})
    assert track.add(Record(5.0, '/odom', msg, 0, raw, connection))
    track.close()
    [path] = files(tmp_path)
    with rosbag.Bag(path) as bag:
        [(topic, got, _)] = list(bag.read_messages())
        [info] = bag._connections.values()
    assert got.pose.pose.position.x == 5.0
    assert info.header['callerid'] == b'/sim' and info.header['latching'] == b'1'


def test_closed_files_go_through_the_writer_and_share_the_quota(tmp_path):
    old = tmp_path / 'cc_log_20000101T000000.000Z_old.json.xz'
    old.write_bytes(b'x' * 3000000)
    os.utime(old, (1, 1))
    writer = window_writer.WindowWriter(str(tmp_path / context_track.SUBDIRECTORY), max_disk_mb=1, background=False)
    writer.guard.directories.append(str(tmp_path))
    events = []
    writer.on_event(events.append)
    track = ContextTrack(tmp_path, {'odom': None}, submit=writer.submit)
    for i in range(20):
        track.on_message('odom', odom(10.0 + i), None)
    track.close()
    writer.close()
    kinds = [(event.kind, event.job.what if event.job else None) for event in events]
    assert (event_kinds.WRITTEN, window_writer.CONTEXT) in kinds
    assert (event_kinds.DELETED, None) in kinds and not old.exists()  # the window beyond the quota went
    [written] = [event.path for event in events if event.kind == event_kinds.WRITTEN]
    assert os.path.exists(written) and len(read(written)) == 20


def test_a_failing_write_is_counted_and_the_track_goes_on(tmp_path):
    track = ContextTrack(tmp_path, {'odom': None})
    track.on_message('odom', odom(1.0), None)
    track.add(Record(float('inf'), 'odom', odom(2.0)))  # not a bag time
    track.on_message('odom', odom(3.0), None)
    track.close()
    stats = track.stats()
    assert stats['write_errors'] == 1 and 'odom' in stats['last_error'] and stats['messages_kept'] == 2


def test_tee_feeds_every_sink_and_raises_the_first_failure(tmp_path):
    seen = []

    class Sink(object):
        def on_message(self, topic, msg, stamp=None, size=None):
            seen.append(topic)
            raise RuntimeError('bad')
    tee = Tee(Sink(), None, Sink())
    with pytest.raises(RuntimeError):
        tee.on_message('a', String(), 1.0)
    assert seen == ['a', 'a']


def test_serialized_messages_reach_the_track_as_bytes_through_a_raw_tee(tmp_path):
    _, raw, connection = serialized_odom(7.0, '/base', '0')
    seen = []

    class RawSink(object):
        def on_message(self, topic, msg, stamp=None, size=None):
            seen.append(('message', topic))

        def on_raw(self, topic, raw, connection, stamp=None):
            seen.append(('raw', topic))
    track = ContextTrack(tmp_path, {'/odom': None})
    assert not hasattr(context_track.tee(object(), track), 'on_raw')  # a sink that takes only messages: decoded
    sink = context_track.tee(RawSink(), track)
    sink.on_raw('/odom', raw, connection, 99.0)
    track.close()
    [path] = files(tmp_path)
    with rosbag.Bag(path) as bag:
        [(_, got, when)] = list(bag.read_messages())
        [info] = bag._connections.values()
    assert seen == [('raw', '/odom')]
    assert got.pose.pose.position.x == 7.0 and when.to_sec() == 7.0  # stamped by its header, not the receipt
    assert info.header['callerid'] == b'/base'


def test_recover_salvages_a_crashed_file(tmp_path):
    track = ContextTrack(tmp_path, {'odom': None})
    for i in range(5):
        track.on_message('odom', odom(1.0 + i), None)
    bag = track._bag
    bag.bag._stop_writing_chunk()  # the data reached the file; the index never did (a crash)
    bag.bag._file.flush()
    dead = bag.tmp.replace('.tmp-%d' % os.getpid(), '.tmp-999999999')
    os.rename(bag.tmp, dead)
    recovered, kept = context_track.recover(tmp_path)
    assert kept == [] and len(recovered) == 1
    assert len(read(recovered[0])) == 5


def test_topics_on_different_clocks_are_not_a_jump_back(tmp_path):
    track = ContextTrack(tmp_path, {'odom': None, 'chatter': None}, rotate=100)
    for second in range(20):  # odometry stamps lag the receipt times of a header-less topic by 5 s
        track.on_message('odom', odom(1000.0 + second), None)
        track.on_message('chatter', String(data='x'), 1005.0 + second)
    track.close()
    assert len(files(tmp_path)) == 1 and len(read(files(tmp_path)[0])) == 40


def test_rosbag_says_each_rotated_file_spans_its_first_to_its_last_message(tmp_path):
    track = ContextTrack(tmp_path, {'odom': None, 'chatter': None}, rotate=20)
    for i in range(3000):  # two clocks 5 s apart, in files of several chunks
        track.on_message('odom', odom(1000.0 + i * 0.01), None)
        track.on_message('chatter', String(data='x' * 200), 1005.0 + i * 0.01)
    track.close()
    paths = files(tmp_path)
    spans = {path: (min(t for _, _, t in read(path)), max(t for _, _, t in read(path))) for path in paths}
    assert len(paths) == 2 and spans[paths[0]] == (1000.0, pytest.approx(1019.99))
    assert_rosbag_spans(spans)


def test_a_looping_bag_never_collides_on_temporary_names_and_loses_nothing(tmp_path):
    """``rosbag play -l``: the clock goes back to the same stamps while the writer has not yet closed the file
    of the previous loop (jobs run later, as on a busy writer thread): every loop is one file, nothing lost."""
    jobs = []
    track = ContextTrack(tmp_path, {'odom': None}, submit=jobs.append)
    for loop in range(3):
        for second in range(5):
            track.on_message('odom', odom(100.0 + second), None)
    track.close()
    for job in jobs:
        job.write()
    stats = track.stats()
    assert stats['write_errors'] == 0 and stats['last_error'] == '' and stats['messages_kept'] == 15
    paths = files(tmp_path)
    assert len(paths) == 3 and all(path.endswith('.bag') for path in paths)  # no temporary file left
    assert [len(read(path)) for path in paths] == [5, 5, 5]


def test_a_full_disk_backs_off_counts_the_lost_messages_and_leaves_no_file(small_tmpfs):
    """A real full file system: one attempt per retry period (not one empty ``.tmp`` file per message), every
    message not written counted as lost, no file left behind; once space returns, messages are kept again."""
    disk = small_tmpfs('1m')
    fill_disk(os.path.join(disk, 'filler'))
    now = [0.0]
    track = ContextTrack(disk, {'odom': None}, retry=5.0, clock=lambda: now[0])
    for i in range(1000):  # 10 s at 100 Hz: attempts at 0 s and 5 s only
        now[0] = i * 0.01
        assert not track.on_message('odom', odom(100.0 + i * 0.01), None)
    stats = track.stats()
    assert stats['write_errors'] == 2 and 'No space left' in stats['last_error']
    assert stats['messages_lost'] == 1000 and stats['messages_kept'] == 0
    folder = os.path.join(disk, context_track.SUBDIRECTORY)
    assert not os.path.isdir(folder) or os.listdir(folder) == []
    os.unlink(os.path.join(disk, 'filler'))
    now[0] = 10.0  # the next retry (the last attempt was at 5 s)
    assert track.on_message('odom', odom(110.0), None)
    track.close()
    [path] = files(disk)
    assert path.endswith('.bag') and len(read(path)) == 1
    assert track.stats()['messages_lost'] == 1000


def test_a_file_that_fails_to_close_is_never_published_half_closed(small_tmpfs):
    """rosbag cannot close a file twice: a close that failed (disk full) is not retried into a final name that
    would hold a bag without its index; the retry salvages what reached the disk (``recovery``), or says how many
    messages were lost."""
    disk = small_tmpfs('1m')
    jobs = []
    track = ContextTrack(disk, {'odom': None}, submit=jobs.append)
    for i in range(50):
        track.on_message('odom', odom(100.0 + i), None)
    track.close()
    fill_disk(os.path.join(disk, 'filler'))
    [job] = jobs
    with pytest.raises(OSError):
        job.write()
    os.unlink(os.path.join(disk, 'filler'))
    try:
        path = job.write()  # space is back: what reached the disk is salvaged into a bag of its own
    except RuntimeError as error:  # nothing of them reached the disk
        assert 'closing failed' in str(error) and '50 messages lost' in str(error)
    else:
        assert path.endswith('_recovered.bag') and 0 < len(read(path)) <= 50
        assert [t for _, _, t in read(path)] == [100.0 + i for i in range(len(read(path)))]
    for path in files(disk):  # every file under a final name is a whole bag
        assert safe_files.TMP_MARK not in path
        if path.endswith('.bag'):
            read(path)


DEAD_PID = 999999999  # no such process


@pytest.fixture(scope='module')
def context_bag(tmp_path_factory):
    """A closed context file of 4000 odometry messages in several of rosbag's chunks: its bytes, the messages and
    (data end, messages) of each chunk from rosbag's own index."""
    directory = tmp_path_factory.mktemp('context')
    track = ContextTrack(directory, {'odom': None}, rotate=1e6)
    for i in range(4000):
        track.on_message('odom', odom(1000.0 + i * 0.01), None)
    track.close()
    [path] = files(directory)
    with rosbag.Bag(path) as bag:
        chunks = [(bag._chunk_headers[info.pos].data_pos + bag._chunk_headers[info.pos].compressed_size,
                   sum(info.connection_counts.values())) for info in bag._chunks]
    assert len(chunks) >= 3
    with open(path, 'rb') as stream:
        return stream.read(), read(path), chunks


def leftover(directory, data):
    folder = directory / context_track.SUBDIRECTORY
    folder.mkdir(parents=True)
    path = folder / ('cc_log_context_19700101T001640.000Z.bag.tmp-%d.3' % DEAD_PID)
    path.write_bytes(data)
    return path


def test_recover_keeps_every_complete_chunk_of_a_cut_off_file(context_bag, tmp_path):
    """A leftover cut off after any chunk (before the index that follows it) gives back every message of every
    complete chunk, stamps and connection headers as written (``rosbag reindex`` dropped the last one)."""
    data, messages, chunks = context_bag
    complete = 0
    for number, (end, count) in enumerate(chunks):
        complete += count
        for cut in (end, end + 40):  # just the chunk; the chunk and part of its index records
            directory = tmp_path / ('%d-%d' % (number, cut))
            path = leftover(directory, data[:cut])
            recovered, kept = context_track.recover(directory)
            assert len(recovered) == 1 and kept == [], (cut, kept)
            got = read(recovered[0])
            assert [(topic, t) for topic, _, t in got] == [(topic, t) for topic, _, t in messages[:complete]], cut
            assert got[-1][1].pose.pose.position.x == messages[complete - 1][1].pose.pose.position.x
            assert not path.exists() and files(directory) == recovered, cut


def test_recover_removes_leftovers_that_hold_no_message(context_bag, tmp_path):
    """An empty leftover (the old full-disk behaviour) and one that holds nothing but the bag header are removed:
    no empty context file, no leftover reported at every start."""
    data, _, _ = context_bag
    for name, content in (('empty', b''), ('header', data[:4117])):
        directory = tmp_path / name
        path = leftover(directory, content)
        assert context_track.recover(directory) == ([], []), name
        assert not path.exists() and files(directory) == [], name


def test_the_live_odom_1hz_takes_the_first_message_of_each_second_of_header_stamps_not_of_receipts():
    """BWI's live ``odom_1hz`` (``node_extras.Thinned``) fed decoded messages: the first of each second of their
    header stamps, whatever their receipt (one receipt per batch of 5, 90 ms late, as the reader hands them over)."""
    rospy = pytest.importorskip('rospy')
    from nav_msgs.msg import Odometry
    from cc_log.nodes.node_extras import Thinned
    thinned = Thinned('/odom', '/odom_1hz', 1.0)
    published = []
    thinned.publisher = type('Published', (), {'publish': lambda self, msg: published.append(msg)})()
    for k in range(300):  # 3 s at 100 Hz
        msg = Odometry()
        msg.header.stamp = rospy.Time(100) + rospy.Duration.from_sec(k * 0.01)
        thinned.on_message('/odom', msg, 100.0 + (k // 5 + 1) * 0.05 + 0.04)
    assert [round(m.header.stamp.to_sec(), 6) for m in published] == [100.0, 101.0, 102.0]
