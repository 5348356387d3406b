"""Reliability without ROS nodes: crash leftovers and their recovery, disk quota and free-space floor,
write errors kept in memory and retried, bad input into SmartLogger, permissions with umask 0."""
import errno
import io
import json
import math
import os
import signal
import stat
import subprocess
import sys
import textwrap
import time

import pytest

from cc_log.base import safe_files
from cc_log.storage import disk_guard, log_format, recovery
from cc_log.storage.disk_guard import DiskGuard
from cc_log.storage.log_format import Format, read_window, write_window
from cc_log.base.records import LogWindow, Record, Trigger

rosbag = pytest.importorskip('rosbag')
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def odom(i, t0=1432235498.0, dt=0.01):
    msg = Odometry()
    msg.header.seq = i
    msg.header.stamp.secs = int(t0 + i * dt)
    msg.header.stamp.nsecs = int(round(((t0 + i * dt) % 1) * 1e9)) % 1000000000
    msg.header.frame_id = 'odom'
    msg.pose.pose.position.x = 0.1 * i + 1e-3 * math.sin(i)
    msg.twist.twist.linear.x = math.cos(i * 0.1)
    msg.pose.pose.orientation.w = 1.0
    return msg


def window(n=300, start=0, reason='classifier'):
    records = [Record(odom(i).header.stamp.to_sec(), '/odom', odom(i)) for i in range(start, start + n)]
    return LogWindow(records, [Trigger(records[n // 2].stamp, reason, -1.5)])


def same(records_a, records_b):
    from cc_log.base import msg_codec
    return ([(r.stamp, r.topic, msg_codec.to_dict(r.msg)) for r in records_a]
            == [(r.stamp, r.topic, msg_codec.to_dict(r.msg)) for r in records_b])


# no such process (a pid in range: safe_files.pid_of takes one above PID_MAX as naming none)
DEAD_PID = next(pid for pid in range(safe_files.PID_MAX, 1, -1) if not safe_files.writer_running(pid))


def as_leftover(path):
    """Move a final file back to a leftover name of a dead writer."""
    tmp = path + log_format.TMP_MARK + str(DEAD_PID)
    os.rename(path, tmp)
    return tmp


# -- crash leftovers -------------------------------------------------------------------------------------

@pytest.mark.parametrize('fmt', Format.ALL)
def test_complete_leftover_gets_its_final_name(fmt, tmp_path):
    win = window()
    path, _ = write_window(win, str(tmp_path), fmt)
    tmp = as_leftover(path)
    assert log_format.window_files(str(tmp_path)) == [] and recovery.scan(str(tmp_path)) == [tmp]
    outcome, = recovery.recover_directory(str(tmp_path))
    assert outcome.status == recovery.COMPLETE and outcome.path == path and outcome.messages == 300
    assert same(read_window(path)[1], win.records)
    assert recovery.scan(str(tmp_path)) == []


def test_duplicate_leftover_from_a_crash_between_link_and_unlink(tmp_path):
    path, _ = write_window(window(), str(tmp_path), Format.JSON_XZ)
    tmp = path + log_format.TMP_MARK + str(DEAD_PID)
    os.link(path, tmp)
    outcome = recovery.recover(tmp)
    assert outcome.status == recovery.DUPLICATE and outcome.path == path
    assert not os.path.exists(tmp) and log_format.window_files(str(tmp_path)) == [path]
    read_window(path)


def test_leftover_of_a_running_writer_is_left_alone(tmp_path):
    path, _ = write_window(window(), str(tmp_path), Format.JSON_XZ)
    tmp = path + log_format.TMP_MARK + str(os.getppid())
    os.rename(path, tmp)
    outcome = recovery.recover(tmp)
    assert outcome.status == recovery.BUSY and os.path.exists(tmp)


@pytest.mark.parametrize('pid', ['99999999999999999999', '0', '00'])
def test_a_leftover_or_reservation_naming_no_process_is_recovered_at_once(pid, tmp_path):
    """Issue 42 item 5: a pid out of range (os.kill raised OverflowError: the nodes and cclog recover stopped with a
    traceback) or 0 (os.kill(0) signals this process group: "busy" for BUSY_SECONDS) names no running writer: the
    leftover is recovered now and a reservation holding it (stale by its time) released."""
    path, _ = write_window(window(), str(tmp_path), Format.JSON_XZ)
    tmp = path + log_format.TMP_MARK + pid
    os.rename(path, tmp)
    reservation = os.path.join(str(tmp_path), 'cc_log_20150521T191138.027Z_other' + log_format.RESERVED_MARK)
    with open(reservation, 'w') as stream:
        stream.write(pid + '\n')
    old = time.time() - recovery.BUSY_SECONDS - 1
    os.utime(reservation, (old, old))
    outcome, = recovery.recover_directory(str(tmp_path))
    assert outcome.status == recovery.COMPLETE and outcome.path == path and outcome.messages == 300
    assert not os.path.exists(reservation) and not os.path.exists(tmp)


def test_a_vector_leftover_naming_no_process_is_removed(tmp_path):
    """Issue 42 item 5 in collect mode: a vector leftover whose pid is out of range or 0 has no running writer."""
    from cc_log.logger import collector
    names = ['1.0.json' + log_format.TMP_MARK + pid for pid in ('99999999999999999999', '0')]
    for name in names:
        (tmp_path / name).write_text('{}')
    assert collector.remove_vector_leftovers(str(tmp_path)) == sorted(str(tmp_path / name) for name in names)


def test_empty_and_garbled_leftovers_are_reported_and_garbled_kept(tmp_path):
    good, _ = write_window(window(), str(tmp_path), Format.JSON_XZ)
    data = open(good, 'rb').read()
    os.unlink(good)
    cut = good + log_format.TMP_MARK + str(DEAD_PID)
    with open(cut, 'wb') as stream:
        stream.write(data[:len(data) // 2])  # a json-xz cut off mid-write
    empty = os.path.join(str(tmp_path),
                         'cc_log_20150521T191138.027Z_manual.json.xz' + log_format.TMP_MARK + str(DEAD_PID))
    open(empty, 'wb').close()
    outcomes = {o.leftover: o for o in recovery.recover_directory(str(tmp_path))}
    assert outcomes[cut].status == recovery.UNRECOVERABLE and str(cut) in outcomes[cut].detail
    assert os.path.exists(cut) and open(cut, 'rb').read() == data[:len(data) // 2]  # never deleted
    assert outcomes[empty].status == recovery.EMPTY and 'removed' in outcomes[empty].detail
    assert log_format.window_files(str(tmp_path)) == []
    # reported again on the next start, still not deleted
    again, = recovery.recover_directory(str(tmp_path))
    assert again.status == recovery.UNRECOVERABLE and os.path.exists(cut)


CRASHING_WRITER = textwrap.dedent('''
    import os, signal, sys, tempfile
    sys.path.insert(0, {test!r})
    import rosbag
    from test_reliability import window
    from cc_log.storage import log_format
    from cc_log.storage.formats import bag_lz4
    from cc_log.storage.bag import bag_writer
    bag_writer.CHUNK_THRESHOLD = {chunk_threshold!r}  # several chunks in one window
    kill_at = {kill_at!r}
    write_bag = bag_writer.write_bag

    def where_to_die(messages, headers):
        # (bytes on disk when the process dies, messages of the chunks whose data they hold), from the whole bag
        with tempfile.NamedTemporaryFile(suffix='.bag') as whole:
            write_bag(whole, messages, headers)
            whole.flush()
            with rosbag.Bag(whole.name) as bag:
                chunks = [(bag._chunk_headers[info.pos], sum(info.connection_counts.values()))
                          for info in bag._chunks]
                index_pos = bag._index_data_pos
        if kill_at == 'close':  # everything but the index
            return index_pos, sum(count for _, count in chunks)
        header = chunks[max(kill_at - 1, 0)][0]  # right after chunk N's data (0: its header only)
        return header.data_pos + (header.compressed_size if kill_at else 0), sum(c for _, c in chunks[:kill_at])

    class Dying(object):
        # the file as the writer fills it, until the process is killed
        def __init__(self, stream, cut, done):
            self.stream, self.cut, self.done = stream, cut, done

        def write(self, data):
            if kill_at is None:  # killed from outside once {kill_after!r} bytes are on disk, wherever that falls
                for start in range(0, len(data), 4099):
                    self.stream.write(data[start:start + 4099])
                    self.stream.flush()
                    if self.stream.tell() >= {kill_after!r}:
                        sys.stdin.read()  # until killed
                return
            room = self.cut - self.stream.tell()
            self.stream.write(data[:room])
            if len(data) >= room:
                self.stream.flush()
                print(self.done, flush=True)  # messages (the metadata's too) of the chunks whose data is on disk
                os.kill(os.getpid(), signal.SIGKILL)

        def __getattr__(self, name):
            return getattr(self.stream, name)

    def dying_write_bag(stream, messages, headers, chunk_threshold=None):
        messages = list(messages)
        cut, done = where_to_die(messages, headers) if kill_at is not None else (None, None)
        write_bag(Dying(stream, cut, done), messages, headers, chunk_threshold)

    bag_writer.write_bag = dying_write_bag
    log_format.write_window(window({messages!r}), {directory!r}, 'bag-lz4')
''')


def crashing_writer(directory, messages=6000, kill_at='close', chunk_threshold=768 * 1024, kill_after=None):
    """Run a process that writes a bag-lz4 window of ``messages`` and is SIGKILLed mid-bag; return how many
    window messages (the metadata message left out) the chunks whose data reached the disk held.

    ``kill_at``: 'close' (the bag's bytes up to its index on disk), N (up to the end of chunk N's data, before
    its index records; 0: chunk 1's header only) or None: SIGKILLed from here once its leftover holds
    ``kill_after`` bytes (returns None).
    """
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [os.path.join(ROOT, 'src'),
                                                                    os.environ.get('PYTHONPATH')])))
    script = CRASHING_WRITER.format(test=os.path.join(ROOT, 'test'), directory=directory, messages=messages,
                                    kill_at=kill_at, chunk_threshold=chunk_threshold, kill_after=kill_after)
    child = subprocess.Popen([sys.executable, '-c', script], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    if kill_at is None:
        deadline = time.time() + 60
        while time.time() < deadline and child.poll() is None and not any(
                os.path.getsize(path) >= kill_after for path in recovery.scan(directory)):
            time.sleep(0.001)
        child.kill()
    out, _ = child.communicate(timeout=120)
    assert child.returncode == -signal.SIGKILL, (child.returncode, out)
    return int(out) - 1 if kill_at is not None else None


@pytest.mark.parametrize('kill_at, threshold', [('close', 768 * 1024), ('close', 16 * 1024), (1, 768 * 1024),
                                                (3, 16 * 1024)])
def test_bag_cut_off_by_sigkill_keeps_every_message_of_every_complete_chunk(kill_at, threshold, tmp_path):
    """A writer SIGKILLed before the bag's index reached the disk, or right after a chunk's data (its index
    records missing; rosbag reindex dropped such a chunk when its header lacked its sizes, and a bag of one
    chunk was "empty" and deleted): every message of every chunk whose data is on disk is recovered, exactly."""
    directory = str(tmp_path)
    written = crashing_writer(directory, messages=6000 if kill_at == 'close' or threshold < 1e5 else 1000,
                              kill_at=kill_at, chunk_threshold=threshold)
    leftover, = recovery.scan(directory)
    size = os.path.getsize(leftover)
    with pytest.raises(ValueError) as error:
        read_window(leftover)
    assert leftover in str(error.value)
    outcome, = recovery.recover_directory(directory)
    assert outcome.status == recovery.PARTIAL, outcome
    assert outcome.path.endswith('_classifier_recovered.bag') and not os.path.exists(leftover)
    assert outcome.lost_bytes == 0 and 'every byte decoded' in outcome.detail, outcome  # nothing else was on disk
    metadata, records = read_window(outcome.path)
    assert metadata['recovered'] is True and metadata['recovered_from'] == os.path.basename(leftover)
    assert metadata['triggers'][0]['reason'] == 'classifier' and metadata['triggers'][0]['score'] == -1.5
    full = window(6000).records
    assert outcome.messages == len(records) == written > 0
    assert same(records, full[:written])  # exactly the first messages, nothing invented
    assert size > 4117 and recovery.scan(directory) == [] and os.listdir(directory) == [os.path.basename(outcome.path)]


def test_bag_writer_sigkilled_from_outside_at_any_moment_loses_only_what_was_not_on_disk(tmp_path):
    directory = str(tmp_path)
    assert crashing_writer(directory, messages=30000, kill_at=None, chunk_threshold=16 * 1024,
                           kill_after=300000) is None
    leftover, = recovery.scan(directory)
    data = open(leftover, 'rb').read()
    outcome, = recovery.recover_directory(directory)
    assert outcome.status == recovery.PARTIAL, outcome
    _, records = read_window(outcome.path)
    assert len(records) > 300 and same(records, window(len(records)).records)
    if outcome.lost_bytes:  # the tail rosbag was writing: kept, byte for byte
        assert open(outcome.kept, 'rb').read() == data and str(outcome.lost_bytes) in outcome.detail
    else:
        assert outcome.kept == '' and not os.path.exists(leftover)


def test_damaged_bags_larger_than_their_header_are_never_deleted(tmp_path):
    """Garbage after the bag header, a file that is no bag, messages whose definition does not match the
    md5sum of their connection: nothing decodes, so each is kept as it is and reported at every start."""
    import genpy
    from std_msgs.msg import Float64
    directory = str(tmp_path)
    other = str(tmp_path / 'other.bag')
    with rosbag.Bag(other, 'w', compression=rosbag.Compression.LZ4) as bag:
        for i in range(50):
            value = Float64(data=i)
            buffer = io.BytesIO()
            value.serialize(buffer)
            bag.write('/x', (Float64._type, buffer.getvalue(), 'f' * 32, Float64), genpy.Time(1000 + i), raw=True)
    with open(other, 'rb') as stream:
        wrong_md5 = stream.read()
    os.unlink(other)
    contents = {
        'garbage': wrong_md5[:4117] + os.urandom(100000),
        'not-a-bag': os.urandom(100000),
        'md5': wrong_md5[:-200],  # its index cut off: read directly, the connection refused
    }
    paths = {}
    for name, data in contents.items():
        paths[name] = os.path.join(directory, 'cc_log_20150521T191138.000Z_%s.bag.tmp-%d' % (name, DEAD_PID))
        with open(paths[name], 'wb') as stream:
            stream.write(data)
    for _ in range(2):
        outcomes = {o.leftover: o for o in recovery.recover_directory(directory)}
        for name, path in paths.items():
            assert outcomes[path].status == recovery.UNRECOVERABLE, (name, outcomes[path])
            assert outcomes[path].lost_bytes == len(contents[name]) and path in outcomes[path].detail
            with open(path, 'rb') as stream:
                assert stream.read() == contents[name]
    assert 'md5sum' in outcomes[paths['md5']].detail
    assert log_format.window_files(directory) == []


def test_cclog_recover_reports_what_it_could_not_recover_and_exits_1_once(tmp_path):
    from test_cli import run
    directory = str(tmp_path)
    written = crashing_writer(directory, messages=3000, kill_at=3, chunk_threshold=16 * 1024)
    leftover, = recovery.scan(directory)
    with open(leftover, 'rb') as stream:
        data = stream.read()
    with open(leftover, 'wb') as stream:
        stream.write(data[:-30])  # the third chunk's block cut off: bytes that cannot be decoded
    first = run('recover', directory, '--json')
    assert first.returncode == 1 and first.stderr == '', first
    outcome, = json.loads(first.stdout)['leftovers']
    assert outcome['status'] == 'partial' and outcome['lost_bytes'] > 0, outcome
    with open(outcome['kept'], 'rb') as stream:
        assert stream.read() == data[:-30]
    _, records = read_window(outcome['path'])
    assert 0 < outcome['messages'] == len(records) < written and same(records, window(len(records)).records)
    again = run('recover', directory)
    assert again.returncode == 0 and again.stdout == 'no leftovers\n'


def test_bag_killed_before_any_message_data_reached_the_disk_is_removed_with_a_report(tmp_path):
    directory = str(tmp_path)
    assert crashing_writer(directory, messages=10, kill_at=0) == -1  # the first chunk's header only
    leftover, = recovery.scan(directory)
    outcome, = recovery.recover_directory(directory)
    assert outcome.status == recovery.EMPTY and 'holds no message' in outcome.detail, outcome
    assert os.listdir(directory) == []


def _chunks(path):
    """(data start, data end, window messages) of each chunk of a complete bag, from rosbag's own index."""
    with rosbag.Bag(path) as bag:
        chunks = []
        for info in bag._chunks:
            header = bag._chunk_headers[info.pos]
            chunks.append((header.data_pos, header.data_pos + header.compressed_size,
                           sum(info.connection_counts.values())))
    data_start, data_end, count = chunks[0]
    chunks[0] = (data_start, data_end, count - 1)  # the metadata message
    return chunks


@pytest.fixture(scope='module')
def chunked_bag(tmp_path_factory):
    """A bag-lz4 window of 600 odometry messages in about 30 chunks: its bytes and its chunks."""
    from cc_log.storage.bag import bag_writer
    directory = str(tmp_path_factory.mktemp('chunked'))
    default = bag_writer.CHUNK_THRESHOLD
    bag_writer.CHUNK_THRESHOLD = 16 * 1024
    try:
        path, _ = write_window(window(600), directory, Format.BAG_LZ4)
    finally:
        bag_writer.CHUNK_THRESHOLD = default
    with open(path, 'rb') as stream:
        data = stream.read()
    chunks = _chunks(path)
    assert len(chunks) > 20
    return data, chunks


def test_bag_truncated_anywhere_keeps_every_complete_chunk_and_never_deletes_data(chunked_bag, tmp_path):
    from cc_log.base import msg_codec
    data, chunks = chunked_bag
    full = [(r.stamp, r.topic, msg_codec.to_dict(r.msg)) for r in window(600).records]
    header_end = 4117
    offsets = {13, 100, header_end, header_end + 1, len(data) - 1}
    for number, (start, end, _) in enumerate(chunks):
        offsets.update({end - 9, end - 8, end})  # the last byte of its block; its end mark; all of it
        if number % 3 == 0:
            offsets.update({start - 1, start + 20, (start + end) // 2, end + 30})
    for offset in sorted(offsets):
        directory = tmp_path / str(offset)
        directory.mkdir()
        leftover = directory / ('cc_log_20150521T191138.000Z_classifier.bag.tmp-%d' % DEAD_PID)
        leftover.write_bytes(data[:offset])
        outcome, = recovery.recover_directory(str(directory))
        complete = sum(count for _, end, count in chunks if end <= offset)
        following = [count for start, end, count in chunks if end > offset]
        if offset <= chunks[0][0]:  # nothing but the bag header and (part of) the first chunk's header
            assert outcome.status == recovery.EMPTY and os.listdir(str(directory)) == [], (offset, outcome)
            continue
        if outcome.status == recovery.UNRECOVERABLE:  # nothing decodes: kept as it is, at every start
            assert complete == 0 and outcome.lost_bytes == offset, (offset, outcome)
            assert leftover.read_bytes() == data[:offset]
            again, = recovery.recover_directory(str(directory))
            assert again.status == recovery.UNRECOVERABLE and leftover.read_bytes() == data[:offset]
            continue
        assert outcome.status == recovery.PARTIAL, (offset, outcome)
        _, records = read_window(outcome.path)
        # every complete chunk; the next one too when its compressed block is whole (only its end mark missing)
        assert len(records) in (complete, complete + (following[0] if following else 0)), (offset, len(records))
        assert [(r.stamp, r.topic, msg_codec.to_dict(r.msg)) for r in records] == full[:len(records)], offset
        assert outcome.messages == len(records)
        assert not leftover.exists() and recovery.scan(str(directory)) == []
        if outcome.lost_bytes:  # bytes that could not be decoded: the leftover is kept, out of the leftovers
            assert outcome.kept.endswith('.bag' + recovery.KEPT_MARK + str(DEAD_PID))
            with open(outcome.kept, 'rb') as stream:
                assert stream.read() == data[:offset]
            assert 0 < outcome.lost_bytes < offset - header_end
            assert str(outcome.lost_bytes) in outcome.detail
        else:
            assert outcome.kept == '' and sorted(os.listdir(str(directory))) == [os.path.basename(outcome.path)]
    assert len(offsets) > 100


def test_no_empty_leftover_while_encoding(tmp_path, monkeypatch):
    """json-xz is encoded before the temporary file exists: dying while encoding leaves nothing."""
    from cc_log.storage.formats import json_xz

    def boom(*args, **kwargs):
        assert recovery.scan(str(tmp_path)) == []
        raise KeyboardInterrupt
    monkeypatch.setattr(json_xz, 'encode', boom)
    with pytest.raises(KeyboardInterrupt):
        write_window(window(), str(tmp_path), Format.JSON_XZ)
    assert os.listdir(str(tmp_path)) == []


# -- disk guard --------------------------------------------------------------------------------------------

def test_quota_deletes_only_the_oldest_window_files(tmp_path):
    directory = str(tmp_path)
    other = tmp_path / 'notes.txt'
    other.write_bytes(b'x' * 200000)
    leftover = tmp_path / ('cc_log_20000101T000000.000Z_x.json.xz' + log_format.TMP_MARK + '1')
    leftover.write_bytes(b'y' * 200000)
    paths = [write_window(window(300, start=1000 * k), directory, Format.JSON_XZ)[0] for k in range(6)]
    size = disk_guard.allocated_bytes(os.lstat(paths[0]))
    guard = DiskGuard(directory, max_disk_mb=3.5 * size / disk_guard.MB)
    deleted = guard.enforce_quota(keep=paths[-1])
    assert deleted == paths[:3]
    assert log_format.window_files(directory) == paths[3:]
    assert other.exists() and leftover.exists()
    assert guard.deleted == 3 and guard.last_deleted == paths[2] and guard.usage() <= guard.max_bytes


def test_quota_never_deletes_the_newest_file(tmp_path):
    path, _ = write_window(window(), str(tmp_path), Format.JSON_XZ)
    guard = DiskGuard(str(tmp_path), max_disk_mb=0.000001)
    assert guard.enforce_quota(keep=path) == [] and os.path.exists(path)


class FakeStatvfs(object):
    def __init__(self, free):
        self.free = free

    def __call__(self, path):
        return os.statvfs_result((4096, 1, 1000, self.free, self.free, 0, 0, 0, 0, 255))


def test_min_free_pauses_and_resumes(tmp_path):
    statvfs = FakeStatvfs(free=100)
    guard = DiskGuard(str(tmp_path), min_free_mb=5, statvfs=statvfs)
    ok, why = guard.check()
    assert not ok and guard.paused and 'min_free_mb 5' in why
    statvfs.free = 10 * disk_guard.MB
    assert guard.check() == (True, '') and not guard.paused
    assert DiskGuard(str(tmp_path)).check() == (True, '')


@pytest.mark.parametrize('value', ['-1', 'lots', float('nan'), float('inf')])
def test_bad_limits_name_the_parameter(tmp_path, value):
    for name in ('max_disk_mb', 'min_free_mb'):
        with pytest.raises(ValueError) as error:
            DiskGuard(str(tmp_path), **{name: value})
        assert str(error.value).startswith(name + ':')


def test_retryable_errors():
    assert disk_guard.is_retryable(OSError(errno.ENOSPC, 'No space left on device'))
    assert disk_guard.is_retryable(PermissionError(errno.EACCES, 'Permission denied'))
    assert not disk_guard.is_retryable(ValueError('x'))


# -- permissions -------------------------------------------------------------------------------------------

def _group_writable_not_world(path, directory):
    mode = stat.S_IMODE(os.stat(path).st_mode)
    if directory:
        assert mode & 0o070 == 0o070 and not mode & 0o002, (path, oct(mode))
    else:
        assert mode & 0o060 == 0o060 and not mode & 0o002 and not mode & 0o111, (path, oct(mode))


@pytest.mark.parametrize('fmt', Format.ALL)
def test_window_files_and_directories_group_writable_never_world_writable_even_with_umask_0(fmt, tmp_path):
    from cc_log.storage.directory import LoggingDirectory
    old = os.umask(0)
    try:
        chosen = LoggingDirectory(str(tmp_path / 'a' / 'logs'))
        path, _ = write_window(window(), os.path.join(chosen.path, 'sub'), fmt)
        recovered = write_window(window(), chosen.path, fmt, base='cc_log_x_recovered')[0]
    finally:
        os.umask(old)
    for directory in (chosen.path, os.path.dirname(path)):
        _group_writable_not_world(directory, True)
    for file_path in (path, recovered):
        _group_writable_not_world(file_path, False)


def test_feature_vector_files_never_world_writable_even_with_umask_0(tmp_path):
    from cc_log.learning import learning
    from cc_log.features import FeatureConfig
    old = os.umask(0)
    try:
        vector = learning.write_vector(str(tmp_path / 'features'), 'nominal', 12.5, [1.0, 2.0],
                                       FeatureConfig('motion', '20'))
    finally:
        os.umask(old)
    _group_writable_not_world(os.path.dirname(vector), True)
    _group_writable_not_world(vector, False)


def test_no_shell_anywhere():
    """No module runs a shell or builds a command line from strings (user input could become commands)."""
    import re
    pattern = re.compile(r'shell\s*=\s*True|os\.system\(|os\.popen\(|commands\.getoutput|subprocess\.getoutput')
    found = []
    for folder in ('src/cc_log', 'scripts', 'bench'):
        for name in sorted(os.listdir(os.path.join(ROOT, folder))):
            path = os.path.join(ROOT, folder, name)
            if os.path.isfile(path) and (name.endswith('.py') or folder == 'scripts'):
                for number, line in enumerate(open(path, encoding='utf-8', errors='replace'), 1):
                    if pattern.search(line):
                        found.append('%s:%d: %s' % (path, number, line.strip()))
    assert not found, found


# -- SmartLogger: write failures, disk limits, bad input -------------------------------------------------

from cc_log.features import FeatureConfig, vector_length  # noqa: E402
from cc_log.base.event_kinds import DELETED, FAILED, OPENED, WRITTEN  # noqa: E402
from cc_log.logger.smart import SmartLogger  # noqa: E402

CONFIG = FeatureConfig('motion', '20')


class EveryNthModel(object):
    """Calls every driving message whose number is in ``flags`` anomalous (counted by the model itself)."""

    def __init__(self, flags=(), config=CONFIG):
        self.config = config
        self.threshold = 0.0
        self.flags = set(flags)
        self.count = 0

    def is_anomalous(self, vector):
        assert len(vector) == vector_length(self.config)
        self.count += 1
        return self.count in self.flags, (-1.0 if self.count in self.flags else 1.0)


def feed(logger, n, start=0, mutate=None):
    for i in range(start, start + n):
        msg = odom(i)
        if mutate is not None:
            mutate(i, msg)
        logger.on_message('/odom', msg, msg.header.stamp.to_sec())


class FlakyDisk(object):
    """log_format.write_window that fails with ``errno`` while ``failing`` is set."""

    def __init__(self, monkeypatch, code=errno.ENOSPC):
        self.failing = True
        self.calls = 0
        self.code = code
        self.real = log_format.write_window
        monkeypatch.setattr(log_format, 'write_window', self)

    def __call__(self, *args, **kwargs):
        self.calls += 1
        if self.failing:
            raise OSError(self.code, os.strerror(self.code))
        return self.real(*args, **kwargs)


@pytest.mark.parametrize('code', [errno.ENOSPC, errno.EACCES])
def test_disk_full_keeps_the_window_in_memory_and_writes_it_when_space_returns(code, tmp_path, monkeypatch):
    disk = FlakyDisk(monkeypatch, code)
    model = EveryNthModel({10, 60})
    logger = SmartLogger(model, str(tmp_path), 'json-xz', 5, 5, driving_topic='/odom', classify_every='1',
                         retry_period=0.05)
    events = []
    logger.on_event(events.append)
    feed(logger, 200)
    deadline = time.time() + 10
    while logger.stats()['windows_held'] < 2 and time.time() < deadline:
        time.sleep(0.02)
    stats = logger.stats()
    assert stats['windows_held'] == 2 and stats['messages_held'] == 22 and stats['messages_lost'] == 0
    assert stats['write_errors'] == 1 and os.strerror(code) in stats['last_error']
    assert stats['messages_not_kept'] + stats['messages_queued'] + stats['messages_buffered'] == 200
    failed = [e for e in events if e.kind == FAILED]
    assert len(failed) == 1 and 'retrying' in failed[0].error
    deadline = time.time() + 10
    while logger.stats()['write_retries'] < 2 and time.time() < deadline:
        time.sleep(0.02)
    assert logger.stats()['write_retries'] >= 2  # it keeps trying, the writer thread is alive
    disk.failing = False
    assert logger.close(30)
    stats = logger.stats()
    assert stats['windows_saved'] == 2 and stats['messages_kept'] == 22 and stats['messages_lost'] == 0
    assert stats['windows_held'] == 0 and stats['messages_queued'] == 0
    files = log_format.window_files(str(tmp_path))
    assert [len(read_window(f)[1]) for f in files] == [11, 11]  # order kept, nothing lost
    assert [e.kind for e in events].count(WRITTEN) == 2


def test_still_failing_at_close_counts_the_loss_once(tmp_path, monkeypatch):
    FlakyDisk(monkeypatch)
    logger = SmartLogger(EveryNthModel({10}), str(tmp_path), 'json-xz', 5, 5,
                         driving_topic='/odom', classify_every='1', background=False)
    events = []
    logger.on_event(events.append)
    feed(logger, 100)
    assert logger.stats()['windows_held'] == 1
    logger.close()
    stats = logger.stats()
    assert stats['messages_lost'] == 11 and stats['windows_held'] == 0 and stats['write_errors'] == 1
    assert [e.kind for e in events] == [OPENED, FAILED, FAILED]  # kept in memory, then lost: both said
    assert 'retrying' in events[1].error and 'still failing at close' in events[2].error


def test_memory_held_is_bounded_oldest_dropped_and_counted(tmp_path, monkeypatch):
    FlakyDisk(monkeypatch)
    logger = SmartLogger(EveryNthModel({10, 40, 70, 100}), str(tmp_path), 'json-xz', 5, 5,
                         driving_topic='/odom', classify_every='1', background=False, max_held_messages=25)
    feed(logger, 200)
    stats = logger.stats()
    assert stats['windows_held'] == 2 and stats['messages_held'] == 22 and stats['messages_lost'] == 22
    assert 'dropped' in stats['last_error']


def test_min_free_pauses_writing_with_windows_in_memory_and_resumes(tmp_path):
    statvfs = FakeStatvfs(free=1)
    logger = SmartLogger(EveryNthModel({10}), str(tmp_path), 'json-xz', 5, 5,
                         driving_topic='/odom', classify_every='1', background=False, min_free_mb=1)
    logger.guard._statvfs = statvfs
    events = []
    logger.on_event(events.append)
    feed(logger, 100)
    stats = logger.stats()
    assert stats['disk_paused'] and stats['windows_held'] == 1 and stats['write_errors'] == 0
    assert log_format.window_files(str(tmp_path)) == [] and FAILED not in [e.kind for e in events]
    statvfs.free = 1000000
    feed(logger, 50, start=100)  # the next completed window (none here) or close retries
    logger.close()
    stats = logger.stats()
    assert not stats['disk_paused'] and stats['windows_saved'] == 1 and stats['messages_lost'] == 0


def test_quota_in_the_logger_deletes_oldest_and_says_so(tmp_path):
    other = tmp_path / 'keep.me'
    other.write_bytes(b'z' * 1000)
    flags = {10 + 40 * k for k in range(6)}
    logger = SmartLogger(EveryNthModel(flags), str(tmp_path), 'json-xz', 5, 5,
                         driving_topic='/odom', classify_every='1', background=False, max_disk_mb=0.0035)
    events = []
    logger.on_event(events.append)
    feed(logger, 300)
    logger.close()
    stats = logger.stats()
    files = log_format.window_files(str(tmp_path))
    assert stats['windows_saved'] == 6 and stats['windows_deleted'] == 6 - len(files) > 0
    written = [e.path for e in events if e.kind == WRITTEN]
    assert files == written[-len(files):]  # the newest are kept
    assert [e.path for e in events if e.kind == DELETED] == written[:-len(files)]
    assert sum(os.path.getsize(f) for f in files) <= 3500 and other.exists()


def test_unwritable_directory_does_not_kill_the_writer(tmp_path):
    if os.geteuid() == 0:
        # root writes anywhere: make the path a file instead (ENOTDIR / EEXIST), then fix it
        blocked = tmp_path / 'logs'
        blocked.write_text('x')
    else:
        blocked = tmp_path / 'logs'
        blocked.mkdir()
        blocked.chmod(0o500)
    logger = SmartLogger(EveryNthModel({10}), str(blocked), 'json-xz', 5, 5, driving_topic='/odom', classify_every='1',
                         retry_period=0.05)
    feed(logger, 100)
    deadline = time.time() + 10
    while logger.stats()['windows_held'] < 1 and time.time() < deadline:
        time.sleep(0.02)
    assert logger.stats()['windows_held'] == 1
    if blocked.is_file():
        blocked.unlink()
    else:
        blocked.chmod(0o775)
    assert logger.close(30)
    assert logger.stats()['windows_saved'] == 1 and len(log_format.window_files(str(blocked))) == 1


def _nan(i, msg):
    if i % 7 == 0:
        msg.twist.twist.linear.x = float('nan')
    if i % 11 == 0:
        msg.pose.pose.position.x = float('inf')
    if i % 13 == 0:
        msg.twist.twist.angular.z = float('-inf')


def _zero_stamps(i, msg):
    if i % 5 == 0:
        msg.header.stamp.secs = msg.header.stamp.nsecs = 0


def _repeated_stamps(i, msg):
    t = odom(i - i % 3).header.stamp
    msg.header.stamp.secs, msg.header.stamp.nsecs = t.secs, t.nsecs


@pytest.mark.parametrize('mutate', [_nan, _zero_stamps, _repeated_stamps], ids=['nan-inf', 'zero', 'repeated'])
def test_bad_values_and_stamps_are_logged_not_fatal(mutate, tmp_path):
    logger = SmartLogger(EveryNthModel({30, 90}), str(tmp_path), 'json-xz', 5, 5,
                         driving_topic='/odom', classify_every='1', background=False)
    feed(logger, 300, mutate=mutate)
    logger.close()
    stats = logger.stats()
    assert stats['write_errors'] == 0 and stats['messages_lost'] == 0 and stats['messages_seen'] == 300
    for path in log_format.window_files(str(tmp_path)):
        _, records = read_window(path)  # NaN/inf read back as written
        for record in records:
            if record.msg.header.seq % 7 == 0 and mutate is _nan:
                assert math.isnan(record.msg.twist.twist.linear.x)


def test_time_jumping_back_and_a_10x_burst(tmp_path):
    logger = SmartLogger(EveryNthModel({30, 150, 260}), str(tmp_path), 'json-xz', 5, 5,
                         driving_topic='/odom', classify_every='1', background=False)
    feed(logger, 120)          # 100 Hz
    feed(logger, 120)          # the same stamps again: a bag loop
    for i in range(240, 400):  # a burst at 1 kHz
        msg = odom(0, t0=1432235498.0 + 2.4 + (i - 240) * 0.001)
        msg.header.seq = i
        logger.on_message('/odom', msg, msg.header.stamp.to_sec())
    logger.close()
    stats = logger.stats()
    assert stats['time_resets'] == 1 and stats['write_errors'] == stats['messages_lost'] == 0
    assert stats['windows_saved'] == 3


def test_a_side_topic_changing_type_does_not_lose_the_window(tmp_path):
    logger = SmartLogger(EveryNthModel({30}), str(tmp_path), 'json-xz', 5, 5,
                         driving_topic='/odom', classify_every='1', side_topics=None, background=False)
    for i in range(100):
        msg = odom(i)
        logger.on_message('/odom', msg, msg.header.stamp.to_sec())
        side = Imu() if i % 2 else odom(i)
        side.header.stamp = msg.header.stamp
        logger.on_message('/side', side, msg.header.stamp.to_sec())
    logger.close()
    stats = logger.stats()
    assert stats['windows_saved'] == 1 and stats['messages_lost'] == 0, stats['last_error']
    assert stats['messages_refused'] == 50 and 'sensor_msgs/Imu message refused' in stats['last_refused']
    _, records = read_window(log_format.window_files(str(tmp_path))[0])
    assert {r.msg._type for r in records if r.topic == '/side'} == {'nav_msgs/Odometry'}


def test_wrong_message_type_on_the_driving_topic_is_refused(tmp_path):
    logger = SmartLogger(EveryNthModel({30}), str(tmp_path), 'json-xz', 5, 5,
                         driving_topic='/odom', classify_every='1', background=False)
    feed(logger, 50)
    imu = Imu()
    imu.header.stamp = odom(50).header.stamp
    logger.on_message('/odom', imu, 0.0)
    feed(logger, 50, start=51)
    logger.close()
    stats = logger.stats()
    assert stats['messages_refused'] == 1 and 'nav_msgs/Odometry' in stats['last_refused']
    assert stats['windows_saved'] == 1 and stats['messages_lost'] == 0
