"""Window files: the formats, their names, atomic writing and reading.

``write_window(window, directory, fmt, metadata)`` writes one LogWindow in a format of ``formats``
(``json-xz``: pure, ``formats.json_xz``; ``bag-lz4``: a rosbag, ``formats.bag_lz4``, rosbag imported only
when that format is written or read); ``read_window(path)`` reads any of them by its magic bytes, and
``read_metadata(path)`` only its metadata, whose summary (``window_info.summary_of``: messages, serialized bytes and
first/last stamps per topic, row JSON bytes) tells ``cclog info`` and ``stats`` what they report.

Names (docs/FORMAT.md) are ``window_names``' (one grammar, a name reserved once per window), imported here for
the readers and writers that use them through this module.

A file is written as ``<final name>.tmp-<pid>``, flushed and fsynced, moved to a final name that does not
exist yet (hard link then unlink, so a file is never overwritten even by another process; rename on file
systems without hard links), and the directory is fsynced (``safe_files.AtomicFile``: created with
``O_EXCL|O_NOFOLLOW``, never through a link). Readers ignore ``*.tmp-*``; they are leftovers of a crash
(``temporary_files``).
"""
import collections
import heapq
import itertools
import os

from cc_log.storage import formats, payload_check
from cc_log.base import raw_message, safe_files, safe_input
from cc_log.storage.window_info import (  # noqa: F401 (trigger_name: also read through this module)
    SUMMARY_KEYS, Contents, check_metadata, merged_summary, summary_of, trigger_name, utc_text, window_metadata)
from cc_log.storage.window_names import (  # noqa: F401 (the names, read through this module too)
    ANY_PREFIX, KEPT_MARK, PREFIX, RESERVED_MARK, TMP_MARK, Piece, WindowName, base_name, file_order, file_prefix,
    final_names, parse_piece, piece_name, release_name, reservations, reserve_name, split_number, split_suffix,
    window_key)

CONTEXT_PREFIX = PREFIX + 'context_'  # a context-track file (``context_track``: a plain rosbag, not a window)
CONTEXT_MARK = 'context_'  # after the prefix: a context-track file
FILE_MODE = safe_files.FILE_MODE  # group-writable, never world-writable (the umask may take more away)
DIR_MODE = safe_files.DIR_MODE


class Format(object):
    """The window file formats, as named in the code (the table is ``formats.FORMATS``)."""

    JSON_XZ = formats.json_xz.CODEC
    BAG_LZ4 = formats.bag_lz4.CODEC
    ALL = formats.names()
    EXTENSIONS = {name: module.EXTENSION for name, module in formats.FORMATS.items()}
    check = staticmethod(formats.check)


# -- grouping -------------------------------------------------------------------------------------------

def _extension(path):
    module = formats.by_extension(path)
    return module.CODEC if module else None


def window_files(directory, prefix=PREFIX):
    """Final window files in ``directory`` whose names begin with ``prefix`` (paths, sorted by name, hence by
    time); ``*.tmp-*`` ignored."""
    try:
        names = os.listdir(directory)
    except OSError:
        return []
    return [os.path.join(directory, name) for name in sorted(names)
            if name.startswith(prefix) and TMP_MARK not in name and _extension(name)]


def window_sets(paths):
    """``[[path, ...]]``: ``paths`` grouped by window (``window_key``) in order of first appearance, each window's
    other files from its directory added, its own file (no route) first, the files of a split window in order."""
    sets, listed = collections.OrderedDict(), {}
    for path in paths:
        key = window_key(path)
        directory = os.path.dirname(path)
        if directory not in listed:  # each directory listed once: {window key: its files}
            listed[directory] = collections.defaultdict(list)
            for name in window_files(directory or '.', prefix=''):  # the key holds the path's prefix
                sibling = os.path.join(directory, os.path.basename(name))
                listed[directory][window_key(sibling)].append(sibling)
        files = sets.setdefault(key, [])
        for candidate in [path] + listed[directory].get(key, []):
            if candidate not in files:
                files.append(candidate)
    return [sorted(files, key=file_order) for files in sets.values()]


def read_window_set(paths):
    """``(metadata, records)`` of a window written as several files (``window_sets``: routes, split files): the
    metadata of them all (``merged_metadata``) with ``counts``/``topics``/``count`` of the records read, and the
    records: those of the files of the window's own file or of one route in file order (split files follow each
    other), those of different routes merged in stamp order; a ``copy`` route's records are read from the
    window's own file. ValueError as ``read_window``."""
    metadata, records = read_window(paths[0])
    if len(paths) == 1:
        return metadata, records
    metadatas, groups = [metadata], collections.OrderedDict([(file_order(paths[0])[:2], records)])
    for path in paths[1:]:
        found, more = read_window(path)
        metadatas.append(found)
        if not _is_copy(found, paths):
            groups.setdefault(file_order(path)[:2], []).extend(more)
    merged = list(heapq.merge(*groups.values(), key=lambda record: record.stamp)) if len(groups) > 1 else records
    counts = collections.Counter(record.topic for record in merged)
    metadata = dict(merged_metadata(metadatas, paths), counts=dict(counts), topics=list(counts), count=len(merged))
    return metadata, merged


def merged_metadata(metadatas, paths):
    """The metadata of a window written as several files (``paths``, as ``window_sets`` orders them, and their
    ``metadatas``): that of the last file of its first group (its own file, or its last split: it names every
    trigger; a window written a file per part: the triggers of them all), with ``files``, the messages
    (``counts``, ``count``, ``topics``, ``types``), ``start``/``end`` and the summed
    ``dropped``/``undecodable``/``lost`` of them all, ``splits`` (files of its own written) for a split
    window, and a summary (``SUMMARY_KEYS``) when every file has one."""
    first = file_order(paths[0])[:2]
    own = [meta for meta, path in zip(metadatas, paths) if file_order(path)[:2] == first]
    result = dict(own[-1], files=list(paths))
    if len(own) > 1 and not any('split' in meta for meta in own):  # a file per part: each says its new triggers
        result['triggers'] = [trigger for meta in own for trigger in meta.get('triggers') or []]
    result.pop('split', None)
    if any(split_number(path) for path in paths):  # the files written (older ones may be gone: max_disk_mb)
        result['splits'] = own[-1].get('splits', len(own))
    metadatas = [meta for meta in metadatas if not _is_copy(meta, paths)]  # a copy's messages are counted once
    counts, types = collections.Counter(), {}
    for meta in metadatas:
        counts.update(meta.get('counts') or {})
        types.update(meta.get('types') or {})
    result.update(counts=dict(counts), count=sum(counts.values()), topics=list(counts), types=types)
    for key, pick in (('start', min), ('end', max)):
        stamps = [meta[key] for meta in metadatas if key in meta]
        if stamps:
            result[key] = pick(stamps)
            result[key + '_utc'] = utc_text(result[key])
    for key in ('dropped', 'undecodable_topics'):  # per topic
        summed = collections.Counter()
        for meta in metadatas:
            summed.update(meta[key] if isinstance(meta.get(key), dict) else {})
        result.pop(key, None)
        if summed:
            result[key] = dict(summed)
    for key in ('undecodable', 'lost'):  # in all
        total = sum(meta[key] for meta in metadatas if isinstance(meta.get(key), int))
        result.pop(key, None)
        if total:
            result[key] = total
    summaries = [summary_of(meta) for meta in metadatas]
    for key in SUMMARY_KEYS:
        result.pop(key, None)
    if None not in summaries:
        summary = merged_summary(summaries)
        result.update(topic_bytes=dict(summary.topic_bytes), raw_json_bytes=summary.raw_json_bytes,
                      topic_spans=dict((topic, list(span)) for topic, span in summary.topic_spans.items()))
    return result


def _is_copy(metadata, paths):
    """True for the metadata of a ``copy`` route's file (``base.routes``) of a window whose own file is among
    ``paths`` (as ``window_sets`` orders them): its messages are in the window's own file too."""
    return bool(metadata.get('copy')) and metadata.get('route') is not None and not file_order(paths[0])[0]


def kept_leftovers(directory, prefix=PREFIX):
    """Leftovers kept after a partial recovery (``cc_log_*.unrecovered-<pid>``; ``prefix``: for ``cc_log_``),
    sorted: bytes no reader could decode, left for a person to look at."""
    try:
        names = os.listdir(directory)
    except OSError:
        return []
    return [os.path.join(directory, name) for name in sorted(names)
            if name.startswith(prefix) and KEPT_MARK in name and TMP_MARK not in name]


def temporary_files(directory, prefix=PREFIX):
    """Leftovers of an interrupted write (``cc_log_*.tmp-<pid>``; ``prefix``: for ``cc_log_``), sorted."""
    try:
        names = os.listdir(directory)
    except OSError:
        return []
    return [os.path.join(directory, name) for name in sorted(names)
            if name.startswith(prefix) and TMP_MARK in name]


# -- writing --------------------------------------------------------------------------------------------

def ensure_directory(directory):
    """Create ``directory`` (and parents) group-writable, not world-writable, if it does not exist."""
    return safe_files.make_dirs(directory)


def write_window(window, directory, fmt, metadata=None, base=None, left_out=None, triggers=None, prefix=PREFIX):
    """Write a LogWindow to ``directory`` in format ``fmt``; return ``(path, bytes written)``.

    ``base``: the file name without extension (default: a name reserved for the window, ``reserve_name``, of
    ``prefix`` (``file_prefix``'s), numbered by the window's part as ``piece_name`` does; the writer gives its
    reserved name's piece, ``recovery`` a leftover's).
    ``triggers``: those its metadata says (default: the window's; a part of a window written as a file per part
    says those that came since the part before it, while its name is the window's first trigger's).

    ``metadata`` (JSON-able dict) is added to ``window_metadata``. Records held as serialized bytes are
    decoded here (the writer thread) unless the format writes bytes (``RAW_RECORDS``), by the format's own
    ``decoded_records`` when it has one (json-xz reads fixed layouts from the bytes); one that cannot be
    decoded (or whose bytes are not of its connection's type) is left out and counted in the metadata's
    ``undecodable`` and, per topic, ``undecodable_topics`` and ``dropped`` (and added to ``left_out``, a
    ``collections.Counter``, when given); a format writing bytes refuses those whose bytes are not of their
    connection's type, counted in ``dropped``. Raises ValueError for a bad format or an empty window, OSError
    when the file cannot be written (the temporary file is removed).
    """
    module = formats.get(fmt)
    if not window.records:
        raise ValueError('window: has no records')
    ensure_directory(directory)
    records, undecodable = window.records, 0
    if not getattr(module, 'RAW_RECORDS', False):
        records, undecodable = getattr(module, 'decoded_records', raw_message.decoded_records)(records)
        if not records:
            raise ValueError('window: none of its %d records can be decoded' % undecodable)
    meta = window_metadata(window, fmt, metadata, triggers)
    if undecodable:
        topics = collections.Counter(record.topic for record in window.records)
        topics.subtract(record.topic for record in records)
        meta['undecodable'] = undecodable
        meta['undecodable_topics'] = {topic: count for topic, count in topics.items() if count}
        meta = payload_check.with_dropped(meta, meta['undecodable_topics'])
        for key in SUMMARY_KEYS:  # of the window's records, not of those in the file
            meta.pop(key, None)
        if left_out is not None:
            left_out.update(meta['undecodable_topics'])
    extension = module.EXTENSION
    write = module.encoder(records, meta)  # a format may encode now, before the temporary file exists
    name = WindowName(prefix=prefix)
    if base is None:
        base = piece_name(name.take(directory, window), None, getattr(window, 'part', 0))
    try:
        names = final_names(directory, base, extension)
        first = next(names)
        target = safe_files.AtomicFile(first, names=itertools.chain([first], names))
        with target as stream:
            write(stream)
    finally:
        name.release()
    return target.path, target.size


def streams(fmt):
    """Whether windows of format ``fmt`` are written a part at a time into one file (``WindowFile``)."""
    return hasattr(formats.get(fmt), 'WindowStream')


class WindowFile(object):
    """One window file written a part at a time, for a window handed on in parts (``LogWindow.part`` 1, 2, ...,
    the last ``final``), by a format with a ``WindowStream``: ``append(part, metadata)`` for each part, then
    ``finish(metadata)`` -> ``(path, bytes)``. The file is ``<piece name>.<ext>.tmp-<pid>`` until it is finished (a
    crash leaves a leftover that ``recovery`` salvages), then gets its final name, ``piece_name(name, route)``
    (``name``: the window's reserved name; None: one reserved for its first part's ``base_name`` of ``prefix``,
    ``file_prefix``'s). ``summary``: the
    window as a whole (triggers, start, end, its length) once a part was appended. Metadata counters that every
    part carries (``SUMMED``) are summed over the parts; ``lost``: messages of parts that could not be written (said
    in the metadata).

    ``split_bytes`` (0: never): before a part, a file holding at least that many bytes is finished and the part
    begins a new one; the files are then ``<piece>.001<ext>``, ``<piece>.002<ext>``, ... (``split_suffix``), each
    a complete file whose metadata says its own messages, ``split`` (its number) and ``window_start``, the last
    also ``splits`` and ``window_end``; each holds at least ``split_bytes`` (but the last) and at most one part
    more. ``take_closed()`` gives the ``(path, bytes)`` of the files finished so by ``append``."""

    SUMMED = ('dropped', 'undecodable')

    def __init__(self, directory, fmt, route=None, name=None, split_bytes=0, prefix=PREFIX):
        self.directory = directory
        self.route = route    # a route's file of the window (``base.routes``), None for its own
        self.name = WindowName(name=name, prefix=prefix)  # the window's (None until its first part: reserved then)
        self.format = formats.check(fmt)
        self.split_bytes = int(split_bytes or 0)
        self._module = formats.get(fmt)
        self._target = self._stream = self._file = None
        self._split = False   # a file was finished at split_bytes: every file is named as a split
        self.number = 1       # of the file being written
        self._closed = []     # (path, bytes) of the files finished before the window's end (``take_closed``)
        self._contents = Contents()  # the whole window
        self._in_file = Contents()   # the records of the file being written
        self._summed = {}     # of the parts in the file being written
        self.triggers = []
        self.metadata = None  # of the last part
        self.lost = 0         # messages of parts of the file being written that could not be written

    def append(self, window, metadata=None):
        """Write the records of the next part (OSError, ValueError: nothing of it was written; try again)."""
        if self._stream is not None and self.split_bytes and window.records and self._in_file.count \
                and os.fstat(self._file.fileno()).st_size >= self.split_bytes:
            self._close_split()
        if self._stream is None:
            self._open(window)
        if window.records:
            first = self._in_file.count == 0
            self._stream.append(window.records, self._metadata(window, metadata) if first else None)
            self._contents.add(window.records)
            self._in_file.add(window.records)
        self._sum(metadata)
        self.triggers, self.metadata = list(window.triggers), metadata

    def _open(self, window):
        ensure_directory(self.directory)
        name = self.name.take(self.directory, window)
        extension = self._module.EXTENSION
        path = piece_name(name, self.route, self.number if self.number > 1 else 0) + extension
        target = safe_files.AtomicFile(safe_files.inside(self.directory, path, 'window'),
                                       names=self._final_name(extension), keep=True)
        self._file = target.__enter__()
        self._target, self._stream = target, self._module.WindowStream(self._file)
        self._in_file, self._summed, self.lost = Contents(), {}, 0

    def _final_name(self, extension):
        """The name the file being written takes when it is finished (read then: a window's first file is named
        as a split once a second one began)."""
        number = self.number if self._split else 0
        yield safe_files.inside(self.directory, piece_name(self.name.name, self.route, number) + extension, 'window')

    def _close_split(self):
        """Finish the file being written (its number said) before the next part begins a new one."""
        self._split = True
        try:
            self._closed.append(self._close(self.triggers, self.metadata, {'split': self.number}))
        finally:
            if self._target is None:  # finished, or left for recovery: the next part begins the next file
                self.number += 1

    def take_closed(self):
        """``[(path, bytes)]`` of the files finished at ``split_bytes`` since the last call."""
        closed, self._closed = self._closed, []
        return closed

    def lose(self, window, metadata=None):
        """A part that could not be written: counted in the file's metadata."""
        self.lost += len(window.records)
        self._sum(metadata)
        self.triggers, self.metadata = list(window.triggers), metadata

    def finish(self, window, metadata=None):
        """Append the last part, write the metadata, close the file and give it its final name: (path, bytes)."""
        self.append(window, metadata)
        if not self._in_file.count or getattr(self._stream, 'count', None) == 0:  # bag-lz4: every record refused
            self.discard()
            raise ValueError('window: has no records')
        split = {}
        if self.number > 1:
            split = {'split': self.number, 'splits': self.number, 'window_end': float(self._contents.end)}
        try:
            return self._close(window.triggers, metadata, split)
        finally:
            self.name.release()

    def _close(self, triggers, metadata, split):
        """Write the final metadata of the file being written (``split``: its keys of a split window), close it
        and give it its final name: (path, bytes)."""
        if split:
            split['window_start'] = float(self._contents.start)
        self._stream.finish(dict(self._file_metadata(triggers, metadata), **split))
        target, self._target, self._stream = self._target, None, None
        try:
            target.__exit__(None, None, None)
        except OSError as error:
            raise OSError(error.errno, '%s (the window is kept in %s for recovery at the next start)'
                          % (error.strerror or error, target.tmp)) from None
        return target.path, target.size

    def abandon(self):
        """Stop writing; the unfinished file stays under its temporary name, a leftover for ``recovery``."""
        if self._target is not None:
            target, self._target, self._stream = self._target, None, None
            target.abandon()
        self.name.release()

    def discard(self):
        """Remove the unfinished file (nothing of it is kept)."""
        if self._target is not None:
            target, self._target, self._stream = self._target, None, None
            target.__exit__(ValueError, ValueError('discarded'), None)
        self.name.release()

    @property
    def summary(self):
        """The window as a whole: ``triggers``, ``start``, ``end``, ``part`` 0 and its length."""
        return _Summary(self.triggers, self._contents.start, self._contents.end, self._contents.count)

    def _sum(self, metadata):
        for key in self.SUMMED:
            for topic, count in ((metadata or {}).get(key) or {}).items():
                self._summed.setdefault(key, {})[topic] = self._summed.get(key, {}).get(topic, 0) + count

    def _metadata(self, window, metadata):
        """The provisional metadata of a file, written with its first part (no summary: the final says it)."""
        contents = Contents()
        contents.no_summary()
        contents.add(window.records)
        meta = contents.metadata(window.triggers, 0, self.format, metadata)
        if self.number > 1:
            meta.update(split=self.number, window_start=float(self._contents.start))
        return meta

    def _file_metadata(self, triggers, metadata):
        """The final metadata of the file being written: its records, the window's triggers so far."""
        meta = self._in_file.metadata(triggers, 0, self.format, metadata)
        meta.update(self._summed)
        if self.lost:
            meta['lost'] = self.lost
        return meta


class _Summary(object):
    __slots__ = ('triggers', 'start', 'end', 'count', 'part', 'records')

    def __init__(self, triggers, start, end, count):
        self.triggers, self.start, self.end, self.count, self.part, self.records = triggers, start, end, count, 0, ()

    def __len__(self):
        return self.count


# -- reading --------------------------------------------------------------------------------------------

def read_window(path):
    """``(metadata, records)`` of a window file, by its magic bytes (then extension).

    Raises ValueError('<path>: <what is wrong>') for a missing, truncated, corrupt or foreign file, one that
    is not a regular file (a FIFO), metadata of the wrong types (``check_metadata``) or an unsafe message
    definition (``safe_input.check_definition``).
    """
    return _read(path, 'read')


def read_metadata(path):
    """The metadata of a window file without its messages, as ``read_window`` gives it, by the format's
    ``read_metadata`` (bag-lz4: the metadata message and the index; json-xz: the start of the document).

    Its summary (``SUMMARY_KEYS``; ``summary_of``) is kept only when it describes the records in the file: the
    file's messages per topic (bag-lz4: from its index) are the metadata's ``counts``, and no record was left out
    at writing (``undecodable``). The messages are not read: what ``read_window`` finds wrong in them (a damaged
    chunk, records that do not match their checksum, a file cut off after its metadata) is not seen. Raises
    ValueError as ``read_window`` for what it reads.
    """
    metadata, counts = _read(path, 'read_metadata')
    if counts is None:
        counts = metadata.get('counts') if not metadata.get('undecodable') else None
    if counts != metadata.get('counts'):
        for key in SUMMARY_KEYS:
            metadata.pop(key, None)
    return metadata


def _read(path, reader):
    """What the ``reader`` function ('read' or 'read_metadata') of the file's format gives, by its magic bytes,
    its metadata checked; ValueError as ``read_window``."""
    try:
        stream = safe_input.open_input(path)
    except OSError as error:
        raise ValueError('%s: cannot read (%s)' % (path, error.strerror or error))
    with stream:
        try:
            head = stream.read(16)
            stream.seek(0)
        except OSError as error:
            raise ValueError('%s: cannot read (%s)' % (path, error.strerror or error))
        module = formats.by_magic(head)
        found = getattr(module, reader)(path, stream) if module else None
    if found is not None:
        try:
            check_metadata(found[0])
        except ValueError as error:
            raise ValueError('%s: %s' % (path, error))
        return found
    fmt = _extension(path)
    if not head:
        raise ValueError('%s: empty file' % path)
    if fmt is not None:
        raise ValueError('%s: not a %s file (wrong magic bytes; truncated or corrupt?)' % (path, fmt))
    raise ValueError('%s: not a cc_log window file (not %s)' % (path, ' nor '.join(formats.names())))
