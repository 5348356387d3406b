"""Reliability without ROS nodes: crash leftovers and their recovery, disk quota and free-space floor,
write errors kept in memory and retried, bad input into SmartLogger, permissions with umask 0."""
import errno
import math
import os
import signal
import stat
import subprocess
import sys
import textwrap
import time

import pytest

from cc_log import disk_guard, log_format, recovery
from cc_log.disk_guard import DiskGuard
from cc_log.log_format import Format, read_window, write_window
from cc_log.window_buffer import LogWindow, Record, Trigger

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
    from cc_log import msg_codec
    return ([(r.stamp, r.topic, msg_codec.to_dict(r.msg)) for r in records_a]
            == [(r.stamp, r.topic, msg_codec.to_dict(r.msg)) for r in records_b])


DEAD_PID = 999999999  # no such process


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


def test_empty_and_garbled_leftovers_are_reported_and_garbled_kept(tmp_path):
    good, _ = write_window(window(), str(tmp_path), Format.JSON_XZ)
    data = open(good, 'rb').read()
    os.unlink(good)
    cut = good + log_format.TMP_MARK + str(DEAD_PID)
    with open(cut, 'wb') as stream:
        stream.write(data[:len(data) // 2])  # a json-xz cut off mid-write
    empty = os.path.join(str(tmp_path), 'cc_log_20150521T191138.027Z_manual.json.xz' + log_format.TMP_MARK + str(DEAD_PID))
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
    import os, signal, sys
    sys.path.insert(0, {test!r})
    import rosbag
    from test_reliability import window
    from cc_log import log_format
    # the process dies while the bag is still open: rosbag wrote some chunks, no index
    rosbag.Bag.close = lambda self: os.kill(os.getpid(), signal.SIGKILL)
    rosbag.Bag.__del__ = lambda self: None
    log_format.write_window(window(6000), {directory!r}, 'bag-lz4')
''')


def test_bag_cut_off_by_sigkill_is_reindexed_with_what_it_held(tmp_path):
    directory = str(tmp_path)
    code = subprocess.call([sys.executable, '-c', CRASHING_WRITER.format(test=os.path.join(ROOT, 'test'),
                                                                         directory=directory)])
    assert code == -signal.SIGKILL
    leftover, = recovery.scan(directory)
    with pytest.raises(ValueError) as error:
        read_window(leftover)
    assert leftover in str(error.value)
    outcome, = recovery.recover_directory(directory)
    assert outcome.status == recovery.PARTIAL, outcome
    assert outcome.path.endswith('_classifier_recovered.bag') and not os.path.exists(leftover)
    metadata, records = read_window(outcome.path)
    assert metadata['recovered'] is True and metadata['recovered_from'] == os.path.basename(leftover)
    assert metadata['reason'] if 'reason' in metadata else True
    assert metadata['triggers'][0]['reason'] == 'classifier'
    full = window(6000).records
    assert 0 < len(records) < len(full) and outcome.messages == len(records)
    assert same(records, full[:len(records)])  # exactly the first messages, nothing invented


def test_no_empty_leftover_while_encoding(tmp_path, monkeypatch):
    """json-xz is encoded before the temporary file exists: dying while encoding leaves nothing."""
    from cc_log import json_xz

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
    size = os.path.getsize(paths[0])
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
    from cc_log.directory import LoggingDirectory
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


@pytest.mark.xfail(strict=True, reason='learning.write_vector (not owned here) creates vector files with '
                   'open(): 0666 under umask 0; needs os.open(..., 0o664) + the world-bit strip of log_format')
def test_feature_vector_files_never_world_writable_even_with_umask_0(tmp_path):
    from cc_log import learning
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
