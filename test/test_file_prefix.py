"""A file-name prefix other than cc_log_ (``~name_prefix``, rosbag record's ``-o PREFIX``): naming, listing,
recovery and the quota (in bytes and in files, ``~max_files``) follow it and leave other files alone; and the
LZ4 bags' chunk size (``~chunk_kb``, rosbag record's ``--chunksize``)."""
import json
import os
import sys

import pytest

from cc_log.logger import options
from cc_log.storage import context_track, disk_guard, log_format, recovery
from cc_log.storage.disk_guard import DiskGuard
from cc_log.storage.formats import bag_lz4
from cc_log.storage.log_format import Format, file_prefix, write_window
from cc_log.base.event_kinds import DELETED
from cc_log.storage.window_writer import Job, WindowWriter

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from test_reliability import DEAD_PID, as_leftover, window  # noqa: E402

RUN = 'run_'


def test_the_prefix_is_a_plain_part_of_a_file_name():
    assert file_prefix('run') == RUN and file_prefix('cc_log') == log_format.PREFIX
    declared = options.get('name_prefix')
    assert declared.default == 'cc_log' and declared.parse('lab-run.2') == 'lab-run.2'
    for bad in ('', 'a/b', 'run\x01', 'run\n', '.hidden', 'x' * 101, 3):
        with pytest.raises(ValueError, match='^name_prefix: .* must be a plain part of a file name'):
            file_prefix(bad)
    with pytest.raises(ValueError, match='^~name_prefix: '):
        options.get('name_prefix').parse('a/b', '~name_prefix')


def test_listing_finds_the_files_of_its_prefix_only(tmp_path):
    directory = str(tmp_path)
    ours, _ = write_window(window(start=0), directory, Format.JSON_XZ, prefix=RUN)
    base = os.path.basename(ours)[:-len('.json.xz')]
    route, _ = write_window(window(start=0), directory, Format.JSON_XZ, base=base + '+numeric')
    theirs, _ = write_window(window(start=1000), directory, Format.JSON_XZ)
    (tmp_path / 'run_notes.txt').write_text('not a window')
    assert os.path.basename(ours).startswith('run_2015') and os.path.basename(theirs).startswith('cc_log_2015')
    assert log_format.window_files(directory, RUN) == [route, ours]  # '+' sorts before '.'
    assert log_format.window_files(directory) == [theirs]
    assert log_format.window_sets([ours]) == [[ours, route]]  # a window's files found beside it, whatever prefix
    assert context_track.file_name(1432235498.0, RUN) == 'run_context_20150521T191138.000Z'


def test_recovery_follows_the_prefix_and_leaves_other_leftovers_alone(tmp_path):
    directory = str(tmp_path)
    ours = as_leftover(write_window(window(start=0), directory, Format.BAG_LZ4, prefix=RUN)[0])
    theirs = as_leftover(write_window(window(start=1000), directory, Format.BAG_LZ4)[0])
    assert recovery.scan(directory, RUN) == [ours] and recovery.scan(directory) == [theirs]
    outcome, = recovery.recover_directory(directory, RUN)
    assert outcome.status == recovery.COMPLETE and outcome.leftover == ours
    assert os.path.basename(outcome.path).startswith(RUN) and os.path.exists(theirs)
    kept = tmp_path / ('run_20000101T000000.000Z_x.bag' + log_format.KEPT_MARK + str(DEAD_PID))
    kept.write_bytes(b'z' * 10)
    assert log_format.kept_leftovers(directory, RUN) == [str(kept)] and log_format.kept_leftovers(directory) == []
    with pytest.raises(ValueError, match='not a cc_log leftover'):
        recovery.recover(theirs, RUN)


def test_the_quota_counts_and_deletes_files_of_its_prefix_only(tmp_path):
    directory = str(tmp_path)
    theirs = [write_window(window(start=1000 * k), directory, Format.JSON_XZ)[0] for k in range(2)]
    ours = [write_window(window(start=1000 * k), directory, Format.JSON_XZ, prefix=RUN)[0] for k in range(2, 6)]
    size = disk_guard.allocated_bytes(os.lstat(ours[0]))
    guard = DiskGuard(directory, max_disk_mb=2.5 * size / disk_guard.MB, prefix=RUN)
    assert [path for path, _ in guard.window_files()] == ours
    assert guard.enforce_quota(keep=ours[-1]) == ours[:2]
    assert log_format.window_files(directory, RUN) == ours[2:] and log_format.window_files(directory) == theirs


def test_max_files_keeps_the_newest_n_through_the_same_quota(tmp_path):
    directory = str(tmp_path)
    theirs = write_window(window(start=0), directory, Format.JSON_XZ)[0]
    ours = [write_window(window(start=1000 * k), directory, Format.JSON_XZ, prefix=RUN)[0] for k in range(1, 5)]
    guard = DiskGuard(directory, max_files=2, prefix=RUN)
    assert guard.active and guard.has_quota and guard.quota_text() == 'max_files 2'
    assert guard.enforce_quota(keep=ours[-1]) == ours[:2]
    assert log_format.window_files(directory, RUN) == ours[2:] and os.path.exists(theirs)
    assert guard.enforce_quota(keep=ours[-1]) == []
    with pytest.raises(ValueError, match='^max_files: '):
        DiskGuard(directory, max_files=-1)
    assert options.get('max_files').parse('3') == 3 and options.get('max_files').key == 'limits.max_files'


def test_the_writer_names_its_files_with_the_prefix_and_keeps_max_files(tmp_path):
    directory = str(tmp_path / 'out')
    writer = WindowWriter(directory, Format.BAG_LZ4, background=False, max_files=2, prefix=RUN)
    deleted = []
    writer.on_event(lambda event: deleted.append(event.path) if event.kind == DELETED else None)
    for k in range(4):
        writer.submit(Job(window(start=1000 * k), {}))
    writer.close()
    files = log_format.window_files(directory, RUN)
    assert len(files) == 2 and all(os.path.basename(path).startswith('run_2015') for path in files)
    assert len(deleted) == 2 and not set(deleted) & set(files) and log_format.window_files(directory) == []
    assert writer.stats()['windows_deleted'] == 2


def _chunks(path):
    import rosbag
    with rosbag.Bag(path) as bag:
        return len(bag._chunks)


def test_chunk_kb_sets_the_lz4_chunk_size(tmp_path):
    whole, _ = write_window(window(n=3000), str(tmp_path), Format.BAG_LZ4)
    small, _ = write_window(window(n=3000), str(tmp_path / 'small'), Format.BAG_LZ4, {'chunk_kb': 16})
    assert _chunks(small) >= 10 * _chunks(whole)  # 16 KB chunks instead of rosbag's 768 KB: 48 times as many
    assert bag_lz4.chunk_bytes({'chunk_kb': 16}) == 16384 and bag_lz4.chunk_bytes({}) is None
    assert options.get('chunk_kb').parse('768') == 768


def test_cclog_reads_and_recovers_the_files_of_a_prefix(tmp_path):
    """cclog takes DIR/PREFIX as record -o does: the files DIR/PREFIX_* (info), their leftovers (recover); an
    explicit leftover of another prefix is recovered too."""
    from test_cli import run
    directory = str(tmp_path)
    ours = write_window(window(start=0), directory, Format.BAG_LZ4, prefix=RUN)[0]
    leftover = as_leftover(write_window(window(start=1000), directory, Format.BAG_LZ4, prefix=RUN)[0])
    theirs = as_leftover(write_window(window(start=2000), directory, Format.BAG_LZ4)[0])
    info = run('info', os.path.join(directory, 'run'), '--json')
    assert info.returncode == 0, info.stderr
    assert os.path.basename(ours) in info.stdout and 'cc_log_' not in info.stdout
    recovered = run('recover', os.path.join(directory, 'run'), '--json')
    assert recovered.returncode == 0, recovered.stderr
    outcome, = json.loads(recovered.stdout)['leftovers']
    assert outcome['leftover'] == leftover and outcome['status'] == 'complete' and os.path.exists(theirs)
    assert recovery.prefix_of(leftover) == RUN and recovery.prefix_of('run_context_20150521T191138.027Z.bag') == RUN
    context = tmp_path / 'context'
    context.mkdir()
    stray = context / ('x_20000101T000000.000Z_a.bag' + log_format.TMP_MARK + str(DEAD_PID))
    stray.write_bytes(b'')
    again = run('recover', str(stray))
    assert again.returncode == 0 and 'empty' in again.stdout and not stray.exists()
    assert run('info', os.path.join(directory, 'nothing')).returncode != 0


def test_the_context_track_names_its_files_with_the_prefix_and_takes_the_chunk_size(tmp_path):
    import rosbag
    from cc_log.base.records import Record
    from test_reliability import odom
    written = []
    track = context_track.ContextTrack(str(tmp_path), {'/odom': None}, rotate=1000, prefix=RUN, chunk_bytes=4096,
                                       submit=lambda job: written.append(job.write()))
    for i in range(2000):
        message = odom(i)
        track.add(Record(message.header.stamp.to_sec(), '/odom', message))
    track.close()
    path, = written
    assert os.path.basename(path).startswith('run_context_2015')
    with rosbag.Bag(path) as bag:
        assert len(bag._chunks) >= 50 and bag.get_message_count() == 2000  # 4 KB chunks of ~700 kB
