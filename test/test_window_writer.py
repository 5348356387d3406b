"""The window writer shared by smart and collect mode, on a real full disk (a small tmpfs, mounted as root;
skipped with the reason otherwise) and with injected failures: the quota makes room when space runs out,
windows are ordered by the time they were written, collect mode holds and retries like smart mode and leaves
no empty leftovers, offline writers give up after a few seconds, and the memory budget holds."""
import errno
import os
import time

import pytest

from conftest import fill_disk
from cc_log.storage import log_format, window_writer
from cc_log.logger.collector import Collector
from cc_log.storage.disk_guard import DiskGuard, allocated_bytes
from cc_log.storage.log_format import Format, read_window, write_window
from cc_log.base.event_kinds import DELETED, FAILED, WRITTEN
from cc_log.logger.smart import SmartLogger
from cc_log.storage.window_writer import Job, WindowWriter

pytest.importorskip('rosbag')
from test_reliability import EveryNthModel, FlakyDisk, feed, odom, window  # noqa: E402


def leftovers(directory):
    """Every ``*.tmp-*`` file below ``directory``."""
    return [os.path.join(folder, name) for folder, _, names in os.walk(directory) for name in names
            if log_format.TMP_MARK in name]


def allocated(path):
    """The bytes the quota counts of ``path``: those allocated to it."""
    return allocated_bytes(os.lstat(path))


def wait_until(predicate, timeout=20.0):
    deadline = time.time() + timeout
    while not predicate():
        assert time.time() < deadline, 'timed out'
        time.sleep(0.02)


# -- disk limits that hold when the disk is full ----------------------------------------------------------

def test_full_disk_with_old_windows_over_the_quota_makes_room_oldest_first(small_tmpfs):
    disk = small_tmpfs('2m')
    directory = os.path.join(disk, 'logs')
    old = [write_window(window(2000, start=5000 * k), directory, Format.JSON_XZ)[0] for k in range(4)]
    sizes = [os.path.getsize(path) for path in old]
    quota = 2.5 * max(sizes) / 1e6  # MB: the old windows alone are over it
    other = os.path.join(disk, 'filler')
    fill_disk(other)
    logger = SmartLogger(EveryNthModel({10, 200}), directory, 'json-xz', 50, 50, driving_topic='/odom',
                         classify_every='1', background=False, max_disk_mb=quota)
    events = []
    logger.on_event(events.append)
    feed(logger, 400, start=30000)
    logger.close()
    stats = logger.stats()
    assert stats['messages_lost'] == 0 and stats['windows_saved'] == 2, stats['last_error']
    deleted = [e.path for e in events if e.kind == DELETED]
    assert deleted and deleted == old[:len(deleted)]  # the oldest went first, and only as many as needed
    written = [e.path for e in events if e.kind == WRITTEN]
    assert log_format.window_files(directory) == sorted(old[len(deleted):] + written)
    assert sum(os.path.getsize(p) for p in log_format.window_files(directory)) <= quota * 1e6 + os.path.getsize(
        written[-1])
    assert os.path.exists(other) and leftovers(disk) == []
    assert [len(read_window(path)[1]) for path in written] == [e.messages for e in events if e.kind == WRITTEN]


def test_quota_orders_windows_by_time_written_not_by_their_stamps(tmp_path):
    """After a clock jump (bag replayed, simulation reset) the newest window has the oldest stamps."""
    directory = str(tmp_path)
    late = [write_window(window(300, start=100000 + 1000 * k), directory, Format.JSON_XZ)[0] for k in range(3)]
    early = [write_window(window(300, start=1000 * k), directory, Format.JSON_XZ)[0] for k in range(2)]
    for age, path in enumerate(reversed(late + early)):  # written one second apart, in that order
        os.utime(path, ns=(time.time_ns() - age * 10 ** 9,) * 2)
    assert sorted(late + early) == early + late  # by name the jumped-back windows look oldest
    guard = DiskGuard(directory, max_disk_mb=2.5 * allocated(late[0]) / 1e6)
    deleted = guard.enforce_quota(keep=early[-1])
    assert deleted == late[:3] and log_format.window_files(directory) == early
    assert [path for path, _ in guard.window_files()] == early


def test_quota_counts_the_bytes_a_partial_recovery_kept_oldest_first(tmp_path):
    """``*.unrecovered-<pid>`` files hold bytes of a crashed write: counted in the quota and deleted by age like a
    window, never a ``*.tmp-<pid>`` leftover that is still to be recovered."""
    directory = str(tmp_path)
    windows = [write_window(window(300, start=1000 * k), directory, Format.JSON_XZ)[0] for k in range(2)]
    size = os.path.getsize(windows[0])
    kept = os.path.join(directory, os.path.basename(windows[0]) + log_format.KEPT_MARK + '4242')
    pending = os.path.join(directory, os.path.basename(windows[0]) + '.1' + log_format.TMP_MARK + '4243')
    for path in (kept, pending):
        with open(path, 'wb') as stream:
            stream.write(b'\0' * size)
    for age, path in enumerate([windows[1], windows[0], kept]):  # the kept leftover is the oldest
        os.utime(path, ns=(time.time_ns() - age * 10 ** 9,) * 2)
    guard = DiskGuard(directory, max_disk_mb=(sum(map(allocated, windows)) + 1) / 1e6)
    assert guard.usage() == sum(map(allocated, windows + [kept]))
    assert log_format.kept_leftovers(directory) == [kept]
    assert guard.enforce_quota(keep=windows[1]) == [kept]
    assert os.path.exists(pending) and log_format.window_files(directory) == windows


# -- collect mode: the same writer ------------------------------------------------------------------------

def test_collect_mode_on_a_full_disk_holds_everything_leaves_no_leftover_and_writes_it_later(small_tmpfs):
    disk = small_tmpfs('4m')
    directory = os.path.join(disk, 'collect')
    filler = os.path.join(disk, 'filler')
    fill_disk(filler)
    collector = Collector(directory, 'json-xz', '200', driving_topic='/odom', window='20', stride=10,
                          retry_period=0.05)
    failures = []
    collector.on_event(lambda kind, detail: failures.append(detail) if kind == FAILED else None)
    for i in range(1000):
        msg = odom(i)
        collector.on_message('/odom', msg, msg.header.stamp.to_sec())
    wait_until(lambda: collector.stats()['queue_depth'] == 0 and collector.stats()['files_held'] >= 5)
    stats = collector.stats()
    assert stats['messages_lost'] == 0 and stats['files_written'] == 0 and stats['write_errors'] >= 1
    assert 'No space left on device' in stats['last_error']
    assert failures and all(detail['kept'] for detail in failures)
    assert leftovers(disk) == []  # no empty *.tmp-<pid> window or vector file
    retries = collector.stats()['write_retries']
    wait_until(lambda: collector.stats()['write_retries'] > retries)  # retries go on while the disk stays full
    assert leftovers(disk) == []  # still nothing left behind
    os.unlink(filler)  # space returns
    assert collector.close(60)
    stats = collector.stats()
    assert stats['messages_lost'] == 0 and stats['files_held'] == 0 and stats['messages_kept'] == 1000
    kept = [r.msg.header.seq for path in log_format.window_files(directory) for r in read_window(path)[1]]
    assert kept == list(range(1000))
    vectors = os.listdir(os.path.join(directory, 'features', 'nominal'))
    assert len(vectors) == stats['vectors_written'] == (1000 - 19 + 9) // 10
    assert leftovers(disk) == []


# -- the writer itself: retries, offline give-up ----------------------------------------------------------

def test_offline_writer_retries_briefly_then_gives_up_and_says_so(tmp_path, monkeypatch):
    disk = FlakyDisk(monkeypatch)
    writer = WindowWriter(str(tmp_path), background=False, retry_period=0.05, give_up_after=0.3)
    events = []
    writer.on_event(events.append)
    started = time.monotonic()
    writer.submit(Job(window(), {'reason': 'x'}))
    assert 0.3 <= time.monotonic() - started < 5 and disk.calls >= 4
    assert writer.lost == 1
    kinds = [(e.kind, e.kept) for e in events]
    assert kinds == [(FAILED, True), (FAILED, False)] and 'given up after' in events[-1].error
    stats = writer.stats()
    assert stats['messages_lost'] == 300 and stats['jobs_queued'] == 0 and stats['jobs_held'] == 0


class FailingTwice(FlakyDisk):
    def __call__(self, *args, **kwargs):
        self.failing = self.calls < 2
        return FlakyDisk.__call__(self, *args, **kwargs)


def test_a_write_that_succeeds_on_a_retry_loses_nothing(tmp_path, monkeypatch):
    disk = FailingTwice(monkeypatch, errno.EDQUOT)
    writer = WindowWriter(str(tmp_path), background=False, retry_period=0.05, give_up_after=10)
    writer.submit(Job(window(), {'reason': 'x'}))
    writer.close()
    stats = writer.stats()
    assert disk.calls == 3 and stats['windows_saved'] == 1 and stats['messages_lost'] == 0
    assert stats['write_errors'] == 1 and stats['write_retries'] == 1


def test_jobs_other_than_windows_are_held_and_retried_in_order(tmp_path):
    calls = []

    def vector(name):
        def write():
            calls.append(name)
            if len(calls) < 3:
                raise OSError(errno.ENOSPC, 'No space left on device')
            return name
        return write
    writer = WindowWriter(str(tmp_path), background=False, retry_period=0.01, close_retry=5)
    for name in ('a', 'b', 'c'):
        writer.submit(Job(write=vector(name), what='vector'))
    assert writer.stats()['jobs_held'] == 3
    writer.close()  # retries for up to close_retry seconds: the third attempt succeeds
    assert calls[-3:] == ['a', 'b', 'c'] and writer.stats()['written'] == {'vector': 3}
    assert writer.lost == 0


def test_bad_writer_values_name_the_parameter(tmp_path):
    for kwargs, name in (({'retry_period': 0}, 'retry_period'), ({'give_up_after': -1}, 'give_up_after'),
                         ({'close_retry': 'x'}, 'close_retry'), ({'fmt': 'zip'}, 'format'),
                         ({'max_disk_mb': -1}, 'max_disk_mb')):
        with pytest.raises(ValueError) as error:
            WindowWriter(str(tmp_path), background=False, **kwargs)
        assert str(error.value).startswith(name), str(error.value)
    with pytest.raises(ValueError):
        Job()
    assert window_writer.OFFLINE_RETRY_SECONDS > 0
