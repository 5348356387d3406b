"""Leftovers of a crash in a logging directory: find them, recover them, never delete data silently.

A window file is written as ``<final name>.tmp-<pid>`` and only then given its final name (see
``log_format``). A process killed on the way leaves the temporary file behind. ``recover(path)`` turns one
leftover into a final window file with what it held:

- ``duplicate``: the process died between the hard link and the unlink, so a final file of the same
  name is the same file (same inode) or holds the same bytes: the leftover name is removed, nothing is lost.
- ``complete``: the file decodes completely (the crash came after the fsync, before the link): it is
  given its final name (the first free one; never overwriting).
- ``partial``: a bag-lz4 file cut off while rosbag was writing chunks (no index): a copy is reindexed
  (rosbag's own reindex) and every message it still holds is written as a new window file named
  ``..._recovered`` with the original metadata plus ``"recovered": true``; the leftover is then removed.
- ``empty``: a zero-byte leftover, or a bag that holds no message once reindexed (the writer was killed
  before rosbag wrote its first chunk: the messages were only in its memory): removed, and reported.
- ``unrecoverable``: anything else (a json-xz file cut off mid-write, garbage): left where it is, under
  its ``.tmp-`` name, and reported every time; it is never deleted.

``scan(directory)`` lists the leftovers; ``recover_directory(directory)`` recovers them all and returns one
``Outcome`` per leftover, which the nodes log and show on /diagnostics. A leftover whose writer is still
alive (its pid is running, is not this process, and the file changed in the last ``BUSY_SECONDS``: a
pid reused after a reboot does not keep a stale leftover forever) is ``busy`` and left alone.

Pure: rosbag is imported only to reindex a bag leftover.
"""
import collections
import errno
import json
import os
import shutil
import time

from . import log_format, safe_input

__all__ = ['Outcome', 'scan', 'recover', 'recover_directory', 'DUPLICATE', 'COMPLETE', 'PARTIAL', 'EMPTY',
           'UNRECOVERABLE', 'BUSY', 'RECOVERED_SUFFIX']

DUPLICATE = 'duplicate'
COMPLETE = 'complete'
PARTIAL = 'partial'
EMPTY = 'empty'
UNRECOVERABLE = 'unrecoverable'
BUSY = 'busy'
RECOVERED_SUFFIX = '_recovered'
BUSY_SECONDS = 300.0

Outcome = collections.namedtuple('Outcome', 'leftover status path messages detail')
Outcome.__doc__ = """What ``recover`` did with one leftover.

leftover: the ``*.tmp-<pid>`` path; status: DUPLICATE, COMPLETE, PARTIAL, EMPTY, UNRECOVERABLE or BUSY;
path: the final window file now holding its data ('' when none); messages: how many messages that file
holds (0 when none); detail: one line for the log.
"""


def scan(directory):
    """Leftovers (``cc_log_*.tmp-<pid>``) in ``directory``, sorted."""
    return log_format.temporary_files(directory)


def _split(path):
    """(directory, final base name without extension, extension, pid) of a leftover path."""
    directory, name = os.path.split(path)
    final, _, pid = name.rpartition(log_format.TMP_MARK)
    if not final:
        raise ValueError('%s: not a cc_log leftover (no %s in the name)' % (path, log_format.TMP_MARK))
    fmt = log_format._extension(final)
    if fmt is None:
        raise ValueError('%s: not a cc_log leftover (unknown extension)' % path)
    extension = log_format.Format.EXTENSIONS[fmt]
    try:
        pid = int(pid)
    except ValueError:
        pid = None
    return directory, final[:-len(extension)], extension, pid


def _alive(pid):
    if pid is None or pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except OSError as error:
        return error.errno == errno.EPERM
    return True


def _same_bytes(a, b):
    if os.path.getsize(a) != os.path.getsize(b):
        return False
    with open(a, 'rb') as fa, open(b, 'rb') as fb:
        while True:
            block_a, block_b = fa.read(1 << 20), fb.read(1 << 20)
            if block_a != block_b:
                return False
            if not block_a:
                return True


def _publish(tmp, directory, base, extension):
    final = log_format._publish(tmp, directory, base, extension)
    log_format._fsync_path(directory, directory=True)
    return final


class _NoMessage(ValueError):
    pass


def _reindexed_records(path):
    """(metadata, records) from a bag cut off while being written: a copy is reindexed, the leftover is not
    touched. Raises ValueError when nothing can be read."""
    import rosbag
    from . import bag_lz4, features
    from .window_buffer import Record
    copy = path + '.reindex'
    try:
        shutil.copyfile(path, copy)
        metadata, records = None, []
        try:
            with rosbag.Bag(copy, 'a', allow_unindexed=True) as bag:
                for _ in bag.reindex():
                    pass
            with rosbag.Bag(copy) as bag:
                safe_input.check_bag(bag, path)  # before rosbag generates a class from any definition
                for topic, msg, time in bag.read_messages():
                    if topic == bag_lz4.METADATA_TOPIC:
                        if metadata is None:
                            metadata = safe_input.json_loads(msg.data)
                        continue
                    records.append(Record(features.stamp_of(msg, time.to_sec()), topic, msg))
        except safe_input.UnsafeDefinition:
            raise
        except Exception as error:  # rosbag raises many kinds: ROSBag*Exception, struct.error, lz4 ...
            if not records:
                raise ValueError('%s: cannot be reindexed (%s: %s)' % (path, type(error).__name__, error))
        if not records:
            raise _NoMessage('%s: holds no message (killed before rosbag wrote its first chunk)' % path)
        return metadata if isinstance(metadata, dict) else {}, records
    finally:
        if os.path.lexists(copy):
            os.unlink(copy)


def recover(path):
    """Recover one leftover; return an Outcome. Raises ValueError for a path that is not a cc_log leftover
    and OSError when the directory cannot be written (nothing is deleted then)."""
    directory, base, extension, pid = _split(path)
    if _alive(pid) and time.time() - os.path.getmtime(path) < BUSY_SECONDS:
        return Outcome(path, BUSY, '', 0, 'process %d that writes it is still running' % pid)
    size = os.path.getsize(path)
    if size == 0:
        os.unlink(path)
        return Outcome(path, EMPTY, '', 0, 'empty (nothing had been written into it): removed')
    final = os.path.join(directory, base + extension)
    if os.path.lexists(final) and (os.path.samefile(path, final) or _same_bytes(path, final)):
        os.unlink(path)
        return Outcome(path, DUPLICATE, final, 0, 'same file as %s (crash between link and unlink): removed'
                       % os.path.basename(final))
    try:
        metadata, records = log_format.read_window(path)
    except ValueError as error:
        reason = str(error)
    else:
        final = _publish(path, directory, base, extension)
        return Outcome(path, COMPLETE, final, len(records), 'complete: renamed to %s' % os.path.basename(final))
    if extension != log_format.Format.EXTENSIONS[log_format.Format.BAG_LZ4]:
        return Outcome(path, UNRECOVERABLE, '', 0, '%s; kept as it is' % reason)
    try:
        metadata, records = _reindexed_records(path)
    except _NoMessage as error:
        os.unlink(path)
        return Outcome(path, EMPTY, '', 0, '%s: removed' % error)
    except ValueError as error:
        return Outcome(path, UNRECOVERABLE, '', 0, '%s; kept as it is' % error)
    from .window_buffer import LogWindow, Trigger
    metadata.pop('bag', None)
    for key in ('topics', 'types', 'counts', 'count', 'start', 'end', 'start_utc', 'end_utc', 'codec', 'layout',
                'cc_log_version'):
        metadata.pop(key, None)
    triggers = [Trigger(t.get('stamp', records[0].stamp), t.get('reason', 'recovered'), None)
                for t in metadata.get('triggers', []) if isinstance(t, dict)]
    window = LogWindow(sorted(records, key=lambda record: record.stamp), triggers,
                       int(metadata.get('part', 0) or 0))
    metadata['recovered'] = True
    metadata['recovered_from'] = os.path.basename(path)
    written, _ = log_format.write_window(window, directory, log_format.Format.BAG_LZ4, metadata,
                                         base=base + RECOVERED_SUFFIX)
    os.unlink(path)
    log_format._fsync_path(directory, directory=True)
    return Outcome(path, PARTIAL, written, len(records), 'cut off while written; %d messages recovered into %s'
                   % (len(records), os.path.basename(written)))


def recover_directory(directory):
    """Recover every leftover in ``directory``; a list of Outcomes (an OSError for one leftover becomes an
    UNRECOVERABLE outcome naming it; nothing is deleted then)."""
    outcomes = []
    for path in scan(directory):
        try:
            outcomes.append(recover(path))
        except (OSError, ValueError) as error:
            outcomes.append(Outcome(path, UNRECOVERABLE, '', 0, '%s; kept as it is' % error))
    return outcomes
