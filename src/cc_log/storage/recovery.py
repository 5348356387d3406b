"""Leftovers of a crash in a logging directory: find them, recover them, never delete data silently.

A window file is written as ``<final name>.tmp-<pid>`` and only then given its final name (see
``log_format``). A process killed on the way leaves the temporary file behind. ``recover(path)`` turns one
leftover into a final window file with what it held:

- ``duplicate``: the process died between the hard link and the unlink, so a final file of the same
  name is the same file (same inode) or holds the same bytes: the leftover name is removed, nothing is lost.
- ``complete``: the file decodes completely (the crash came after the fsync, before the link): it is
  given its final name (the first free one; never overwriting).
- ``partial``: a file cut off mid-write whose format can salvage it (``salvage`` of its module in
  ``formats``; bag-lz4: ``formats.bag_salvage`` reads the rosbag 2.0 records directly, every complete message
  of every chunk and of a chunk cut off mid-write): what it held is written as a new window file named
  ``..._recovered<extension>`` with the original metadata plus ``"recovered": true`` (a context-track file,
  ``cc_log_context_*``, as the plain rosbag it was, each message with its connection header).
  The leftover is then removed only when every byte of it was decoded; otherwise it is kept, renamed
  ``<final name>.unrecovered-<pid>`` (out of the leftovers, so it is not recovered twice), and the outcome
  says how many bytes could not be decoded.
- ``empty``: a zero-byte leftover, or a bag that holds nothing but (part of) its bag header: removed,
  and reported. A file larger than its bag header is never deleted unless all it held was recovered.
- ``unrecoverable``: anything else (a json-xz file cut off mid-write, a bag none of whose messages
  decodes, garbage, something that is not a regular file): left where it is, under its ``.tmp-`` name,
  and reported every time; it is never deleted.

``scan(directory, prefix)`` lists the leftovers of files named ``<prefix>...`` (default ``cc_log_``;
``log_format.file_prefix``); ``recover_directory(directory, prefix)`` recovers them all and returns one
``Outcome`` per leftover, which the nodes log and show on /diagnostics. A leftover whose writer is still
alive (its pid, read by ``safe_files.pid_of``: 0 or one out of range names none, is running, is not this
process, and the file changed in the last ``BUSY_SECONDS``: a
pid reused after a reboot does not keep a stale leftover forever) is ``busy`` and left alone.

Pure: what a format needs to read a cut-off file is in its module.
"""
import collections
import itertools
import os
import re
import stat
import time

from cc_log.storage import formats, log_format
from cc_log.storage.formats import bag_lz4
from cc_log.base import msg_codec, safe_files, why
from cc_log.base.records import LogWindow, Trigger

__all__ = ['Outcome', 'scan', 'recover', 'recover_directory', 'release_stale_names', 'incomplete', 'DUPLICATE',
           'COMPLETE', 'PARTIAL', 'EMPTY', 'UNRECOVERABLE', 'BUSY', 'RECOVERED_SUFFIX', 'KEPT_MARK']

DUPLICATE = 'duplicate'
COMPLETE = 'complete'
PARTIAL = 'partial'
EMPTY = 'empty'
UNRECOVERABLE = 'unrecoverable'
BUSY = 'busy'
RECOVERED_SUFFIX = '_recovered'
KEPT_MARK = log_format.KEPT_MARK
BUSY_SECONDS = 300.0

Outcome = collections.namedtuple('Outcome', 'leftover status path messages detail lost_bytes kept',
                                 defaults=(0, ''))
Outcome.__doc__ = """What ``recover`` did with one leftover.

leftover: the ``*.tmp-<pid>`` path; status: DUPLICATE, COMPLETE, PARTIAL, EMPTY, UNRECOVERABLE or BUSY;
path: the final window file now holding its data ('' when none); messages: how many messages that file
holds (0 when none); detail: one line for the log; lost_bytes: bytes of the leftover that could not be
decoded (0 when none); kept: where the leftover is kept after a partial recovery ('' when it is not).
"""


def _leftover(prefix):
    """The pattern of a leftover's name whose final name begins with ``prefix``."""
    return re.compile(r'%s.*(%s)%s(\d+)(\.\d+)?' % (  # (re.fullmatch)
        re.escape(prefix), '|'.join(re.escape(extension) for extension in formats.extensions()),
        re.escape(log_format.TMP_MARK)))


_STAMPED = re.compile(r'^(.+?_)(%s)?\d{8}T\d{6}\.\d{3}Z' % re.escape(log_format.CONTEXT_MARK))


def prefix_of(path):
    """The file prefix of a leftover's name: what comes before its UTC stamp (and a context file's ``context_``):
    ``run_`` of ``run_20150521T191138.027Z_x.bag.tmp-1``; ``log_format.PREFIX`` when it has no stamp."""
    match = _STAMPED.match(os.path.basename(path))
    return match.group(1) if match else log_format.PREFIX


def scan(directory, prefix=log_format.PREFIX):
    """Leftovers (``cc_log_*.tmp-<pid>``; ``prefix``: ``log_format.file_prefix``'s) in ``directory``, sorted."""
    pattern = _leftover(prefix)
    return [path for path in log_format.temporary_files(directory, prefix)
            if pattern.fullmatch(os.path.basename(path))]


def incomplete(outcomes):
    """The outcomes that left something unrecovered (unrecoverable leftovers, bytes a partial one lost)."""
    return [outcome for outcome in outcomes if outcome.status == UNRECOVERABLE or outcome.lost_bytes]


def _split(path, prefix):
    """(directory, final base name without extension, extension, pid) of a leftover path."""
    directory, name = os.path.split(path)
    match = _leftover(prefix).fullmatch(name)
    if not match:
        raise ValueError('%s: not a cc_log leftover (%s*.json.xz%s<pid> or %s*.bag%s<pid>)'
                         % (path, prefix, log_format.TMP_MARK, prefix, log_format.TMP_MARK))
    extension = match.group(1)
    final = name[:name.rindex(log_format.TMP_MARK)]
    return directory, final[:-len(extension)], extension, safe_files.pid_of(match.group(2))


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


def _triggers(metadata, first_stamp):
    triggers = []
    for trigger in metadata.get('triggers') or []:
        if not isinstance(trigger, dict):
            continue
        try:
            stamp = msg_codec.decode_float(trigger.get('stamp', first_stamp))
            score = msg_codec.decode_float(trigger['score']) if trigger.get('score') is not None else None
        except ValueError:
            stamp, score = first_stamp, None
        name = trigger.get('name')
        triggers.append(Trigger(stamp, str(trigger.get('reason', 'recovered')), score,
                                name if isinstance(name, str) else None, why.bounded(trigger.get('why'))))
    return triggers


def _is_context(path, prefix):
    """Whether ``path`` is a context-track file (a plain rosbag, not a window)."""
    return os.path.basename(path).startswith(prefix + log_format.CONTEXT_MARK)


def _write_recovered(path, directory, base, fmt, metadata, records, prefix):
    """Write ``records`` as ``<base>_recovered<extension>`` in format ``fmt`` with ``metadata`` (of the
    leftover), or as the plain rosbag it was for a context file; return its path."""
    if _is_context(path, prefix):
        names = log_format.final_names(directory, base + RECOVERED_SUFFIX, fmt.EXTENSION)
        first = next(names)
        return bag_lz4.to_bag(records, first, names=itertools.chain([first], names))[0]
    for key in ('topics', 'types', 'counts', 'count', 'start', 'end', 'start_utc', 'end_utc', 'codec', 'layout',
                'cc_log_version'):
        metadata.pop(key, None)
    triggers = _triggers(metadata, records[0].stamp)
    metadata.pop('triggers', None)
    part = metadata.get('part', 0)
    window = LogWindow(records, triggers, part if isinstance(part, int) and not isinstance(part, bool) else 0)
    metadata['recovered'] = True
    metadata['recovered_from'] = os.path.basename(path)
    return log_format.write_window(window, directory, fmt.CODEC, metadata, base=base + RECOVERED_SUFFIX)[0]


def _recover_partial(path, directory, base, extension, size, fmt, prefix):
    """Outcome of a leftover that does not decode as a whole, by its format's ``salvage`` (see the module
    docstring)."""
    try:
        salvage = fmt.salvage(path)
    except ValueError as error:
        return Outcome(path, UNRECOVERABLE, '', 0, '%s: %s; kept as it is' % (path, error), size)
    lost = size - salvage.decoded
    why = ' (%s)' % '; '.join(salvage.problems) if salvage.problems else ''
    metadata, records = dict(salvage.metadata), salvage.records
    if not records:
        if salvage.headers_only:
            os.unlink(path)
            safe_files.fsync_directory(directory)
            return Outcome(path, EMPTY, '', 0, 'holds no message, nothing but %s headers (killed before any '
                                               'message data reached the disk): removed' % fmt.CODEC)
        return Outcome(path, UNRECOVERABLE, '', 0, '%s: no message decodes%s; %d bytes kept as they are'
                       % (path, why, size), size)
    written, count = _write_recovered(path, directory, base, fmt, metadata, records, prefix), len(records)
    cut = ', %d of them from a chunk cut off mid-write' % salvage.cut if salvage.cut else ''
    detail = 'cut off while written; %d messages recovered into %s%s' % (count, os.path.basename(written), cut)
    if salvage.undecoded:
        detail += '; %d message records could not be decoded' % salvage.undecoded
    if not lost:
        os.unlink(path)
        safe_files.fsync_directory(directory)
        return Outcome(path, PARTIAL, written, count, detail + '; every byte decoded: leftover removed')
    pid = os.path.basename(path).rpartition(log_format.TMP_MARK)[2]
    kept = safe_files.publish(path, (safe_files.inside(directory, base + extension + KEPT_MARK + pid + (
        '.%d' % number if number else ''), 'leftover') for number in itertools.count()))
    safe_files.fsync_directory(directory)
    return Outcome(path, PARTIAL, written, count, '%s; %d bytes could not be decoded%s: the leftover is kept as %s'
                   % (detail, lost, why, os.path.basename(kept)), lost, kept)


def recover(path, prefix=log_format.PREFIX):
    """Recover one leftover (its name beginning with ``prefix``); return an Outcome. Raises ValueError for a path
    that is not a cc_log leftover and OSError when the directory cannot be written (nothing is deleted then)."""
    directory, base, extension, pid = _split(path, prefix)
    info = os.lstat(path)
    if not stat.S_ISREG(info.st_mode):
        return Outcome(path, UNRECOVERABLE, '', 0, '%s: not a regular file (a link?); left alone' % path)
    if safe_files.writer_running(pid) and time.time() - info.st_mtime < BUSY_SECONDS:
        return Outcome(path, BUSY, '', 0, 'process %d that writes it is still running' % pid)
    if info.st_size == 0:
        os.unlink(path)
        return Outcome(path, EMPTY, '', 0, 'empty (nothing had been written into it): removed')
    final = safe_files.inside(directory, base + extension, 'leftover')
    if os.path.isfile(final) and not os.path.islink(final) and (os.path.samefile(path, final)
                                                                or _same_bytes(path, final)):
        os.unlink(path)
        return Outcome(path, DUPLICATE, final, 0, 'same file as %s (crash between link and unlink): removed'
                       % os.path.basename(final))
    try:
        metadata, records = log_format.read_window(path)
    except ValueError as error:
        reason = str(error)
    else:
        final = safe_files.publish(path, log_format.final_names(directory, base, extension))
        safe_files.fsync_directory(directory)
        return Outcome(path, COMPLETE, final, len(records), 'complete: renamed to %s' % os.path.basename(final))
    fmt = formats.by_extension(extension)
    if not hasattr(fmt, 'salvage'):
        return Outcome(path, UNRECOVERABLE, '', 0, '%s; kept as it is' % reason, info.st_size)
    return _recover_partial(path, directory, base, extension, info.st_size, fmt, prefix)


def release_stale_names(directory, prefix=log_format.PREFIX):
    """Remove the name reservations (``log_format.reserve_name``; ``prefix``: of the names) of processes no longer
    running (this one's and a running one's are kept, and one that names no process but changed in the last
    ``BUSY_SECONDS``); they hold no data. Returns the paths removed."""
    removed = []
    for path, pid in log_format.reservations(directory, prefix):
        if pid == os.getpid() or safe_files.writer_running(pid):
            continue
        if pid is None and time.time() - os.lstat(path).st_mtime < BUSY_SECONDS:
            continue  # whose it is is not said (a full disk): a recent one may be a running writer's
        log_format.release_name(path)
        removed.append(path)
    return removed


def recover_directory(directory, prefix=log_format.PREFIX):
    """Recover every leftover in ``directory`` (of files named ``<prefix>...``); a list of Outcomes (an OSError
    for one leftover becomes an UNRECOVERABLE outcome naming it; nothing is deleted then; one gone meanwhile is
    left out). Stale name reservations are removed first (``release_stale_names``)."""
    try:
        release_stale_names(directory, prefix)
    except OSError:
        pass  # a directory that cannot be written: its leftovers are reported below
    outcomes = []
    for path in scan(directory, prefix):
        try:
            outcomes.append(recover(path, prefix))
        except (OSError, ValueError) as error:
            if isinstance(error, FileNotFoundError) and not os.path.lexists(path):
                continue  # recovered meanwhile by another process
            outcomes.append(Outcome(path, UNRECOVERABLE, '', 0, '%s; kept as it is' % error))
    return outcomes
