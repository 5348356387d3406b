"""Leftovers of a crash in a logging directory: find them, recover them, never delete data silently.

A window file is written as ``<final name>.tmp-<pid>`` and only then given its final name (see
``log_format``). A process killed on the way leaves the temporary file behind. ``recover(path)`` turns one
leftover into a final window file with what it held:

- ``duplicate``: the process died between the hard link and the unlink, so a final file of the same
  name is the same file (same inode) or holds the same bytes: the leftover name is removed, nothing is lost.
- ``complete``: the file decodes completely (the crash came after the fsync, before the link): it is
  given its final name (the first free one; never overwriting).
- ``partial``: a bag-lz4 file cut off while rosbag was writing it (no index, perhaps a chunk half written):
  the rosbag 2.0 records are read directly, every complete message of every chunk (and of a chunk cut off
  mid-write, as far as its data decompresses) is decoded with its connection header, and they are written
  as a new window file named ``..._recovered.bag`` with the original metadata plus ``"recovered": true``.
  The leftover is then removed only when every byte of it was decoded; otherwise it is kept, renamed
  ``<final name>.unrecovered-<pid>`` (out of the leftovers, so it is not recovered twice), and the outcome
  says how many bytes could not be decoded.
- ``empty``: a zero-byte leftover, or a bag that holds nothing but (part of) its bag header: removed,
  and reported. A file larger than its bag header is never deleted unless all it held was recovered.
- ``unrecoverable``: anything else (a json-xz file cut off mid-write, a bag none of whose messages
  decodes, garbage, something that is not a regular file): left where it is, under its ``.tmp-`` name,
  and reported every time; it is never deleted.

``scan(directory)`` lists the leftovers; ``recover_directory(directory)`` recovers them all and returns one
``Outcome`` per leftover, which the nodes log and show on /diagnostics. A leftover whose writer is still
alive (its pid is running, is not this process, and the file changed in the last ``BUSY_SECONDS``: a
pid reused after a reboot does not keep a stale leftover forever) is ``busy`` and left alone.

Pure: roslz4 is imported only to decompress the chunks of a bag leftover; message classes come from
``msg_codec.message_class`` (the definitions in the connection headers are data, checked there).
"""
import collections
import errno
import itertools
import mmap
import os
import re
import stat
import struct
import time

from . import log_format, msg_codec, safe_files, safe_input
from .bag_lz4 import MAGIC, METADATA_TOPIC

__all__ = ['Outcome', 'scan', 'recover', 'recover_directory', 'incomplete', 'DUPLICATE', 'COMPLETE', 'PARTIAL',
           'EMPTY', 'UNRECOVERABLE', 'BUSY', 'RECOVERED_SUFFIX', 'KEPT_MARK']

DUPLICATE = 'duplicate'
COMPLETE = 'complete'
PARTIAL = 'partial'
EMPTY = 'empty'
UNRECOVERABLE = 'unrecoverable'
BUSY = 'busy'
RECOVERED_SUFFIX = '_recovered'
KEPT_MARK = '.unrecovered-'
BUSY_SECONDS = 300.0
MAX_CHUNK_BYTES = 1 << 28  # a decompressed chunk larger than this is not decoded (rosbag writes ~768 KiB)

Outcome = collections.namedtuple('Outcome', 'leftover status path messages detail lost_bytes kept',
                                 defaults=(0, ''))
Outcome.__doc__ = """What ``recover`` did with one leftover.

leftover: the ``*.tmp-<pid>`` path; status: DUPLICATE, COMPLETE, PARTIAL, EMPTY, UNRECOVERABLE or BUSY;
path: the final window file now holding its data ('' when none); messages: how many messages that file
holds (0 when none); detail: one line for the log; lost_bytes: bytes of the leftover that could not be
decoded (0 when none); kept: where the leftover is kept after a partial recovery ('' when it is not).
"""

_LEFTOVER = re.compile(r'^%s.*(%s)%s(\d+)(\.\d+)?$' % (
    re.escape(log_format.PREFIX), '|'.join(re.escape(extension) for extension in log_format.Format.EXTENSIONS.values()),
    re.escape(log_format.TMP_MARK)))


def scan(directory):
    """Leftovers (``cc_log_*.tmp-<pid>``) in ``directory``, sorted."""
    return [path for path in log_format.temporary_files(directory) if _LEFTOVER.match(os.path.basename(path))]


def incomplete(outcomes):
    """The outcomes that left something unrecovered (unrecoverable leftovers, bytes a partial one lost)."""
    return [outcome for outcome in outcomes if outcome.status == UNRECOVERABLE or outcome.lost_bytes]


def _split(path):
    """(directory, final base name without extension, extension, pid) of a leftover path."""
    directory, name = os.path.split(path)
    match = _LEFTOVER.match(name)
    if not match:
        raise ValueError('%s: not a cc_log leftover (cc_log_*.json.xz%s<pid> or cc_log_*.bag%s<pid>)'
                         % (path, log_format.TMP_MARK, log_format.TMP_MARK))
    extension = match.group(1)
    final = name[:name.rindex(log_format.TMP_MARK)]
    return directory, final[:-len(extension)], extension, int(match.group(2))


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


# -- reading a rosbag 2.0 file cut off mid-write ------------------------------------------------------------

_OP_MSG_DATA, _OP_FILE_HEADER, _OP_INDEX_DATA, _OP_CHUNK, _OP_CHUNK_INFO, _OP_CONNECTION = 2, 3, 4, 5, 6, 7
_U32 = struct.Struct('<I')
_LZ4_MAGIC = b'\x04\x22\x4d\x18'
_LZ4_STEP = 1 << 16  # compressed bytes decompressed at a time (bounds what one step can expand to)
_MAX_HEADER = 1024  # record headers rosbag writes outside chunks (bag header, chunk, index) are < 100 bytes
_BAG_HEADER_END = len(MAGIC) + 4104  # rosbag pads its bag header record to 4096 bytes (+ two sizes)


def _fields(header):
    """{name: value bytes} of a record header; ValueError when malformed."""
    fields, pos = {}, 0
    while pos < len(header):
        if pos + 4 > len(header):
            raise ValueError('header field cut off')
        size, = _U32.unpack_from(header, pos)
        name, sep, value = header[pos + 4:pos + 4 + size].partition(b'=')
        if not sep or pos + 4 + size > len(header):
            raise ValueError('bad header field')
        fields[name.decode('ascii', 'replace')] = value
        pos += 4 + size
    return fields


def _record(data, pos, end):
    """(header fields, op, data start, data length) of the record at ``pos``, or None when its header is cut
    off at ``end`` or malformed."""
    if pos + 4 > end:
        return None
    header_end = pos + 4 + _U32.unpack_from(data, pos)[0]
    if header_end + 4 > end:
        return None
    try:
        fields = _fields(data[pos + 4:header_end])
    except ValueError:
        return None
    op = fields.get('op', b'')
    return fields, op[0] if len(op) == 1 else None, header_end + 4, _U32.unpack_from(data, header_end)[0]


def _u32(fields, name):
    value = fields.get(name, b'')
    if len(value) != 4:
        raise ValueError('header field %s missing' % name)
    return _U32.unpack(value)[0]


def _lz4_extent(data):
    """How many leading bytes of roslz4 stream ``data`` (cut off anywhere) hold nothing that was lost: all of
    it but a block cut off (the stream header, whole blocks, a part of a block size or of the end mark)."""
    if not data.startswith(_LZ4_MAGIC[:len(data)]):
        return 0
    flags = data[4] if len(data) > 4 else 0
    pos = 7 + (8 if flags & 0x08 else 0)
    while pos + 4 <= len(data):
        size = _U32.unpack_from(data, pos)[0] & 0x7fffffff
        end = pos + 4 + size + (4 if flags & 0x10 else 0)
        if not size:
            break  # the end mark: every block is there
        if end > len(data):
            return pos
        pos = end
    return len(data)


def _lz4(data, limit):
    """(what roslz4 stream ``data`` decompresses to, as far as it goes; True when no error or limit stopped it)."""
    import roslz4
    decompressor = roslz4.LZ4Decompressor()
    pieces, total = [], 0
    for offset in range(0, len(data), _LZ4_STEP):
        try:
            piece = decompressor.decompress(data[offset:offset + _LZ4_STEP])
        except OSError:  # roslz4: "malformed data to decompress"
            return b''.join(pieces), False
        total += len(piece)
        if total > limit:
            return b''.join(pieces), False
        pieces.append(piece)
    return b''.join(pieces), True


class _Salvage(object):
    """Every complete message record of a rosbag 2.0 file, in file order, however the file ends.

    ``messages``: (topic, secs, nsecs, message) of every message decoded; ``undecoded``: message records
    that were read but could not be decoded; ``decoded``: bytes of the file in records decoded completely
    (every message in them too); ``header_end``: where the bag header record ends (None when the file ends
    inside it); ``cut``: messages taken from a chunk cut off mid-write; ``problems``: why something was not
    decoded (the first few reasons).
    """

    def __init__(self, data):
        self.data = data
        self.connections = {}
        self.messages = []
        self.undecoded = 0
        self.decoded = 0
        self.header_end = None
        self.cut = 0
        self.problems = []

    def _problem(self, text):
        if len(self.problems) < 3 and text not in self.problems:
            self.problems.append(text)

    def run(self):
        """Read the file; return self. ValueError when it is not a rosbag 2.0 file at all."""
        data, size = self.data, len(self.data)
        if data[:len(MAGIC)] != MAGIC[:size]:
            raise ValueError('not a rosbag 2.0 file')
        pos = len(MAGIC)
        while pos < size:
            found = _record(data, pos, size)
            if found is None:
                claimed = _U32.unpack_from(data, pos)[0] if pos + 4 <= size else 0
                if claimed <= _MAX_HEADER and size < pos + 8 + claimed:
                    self.decoded += size - pos  # a record header cut off: no message data in it yet
                break
            fields, op, start, length = found
            if pos == len(MAGIC) and op != _OP_FILE_HEADER:
                raise ValueError('not a rosbag 2.0 file (no bag header record)')
            end = start + length
            undecoded = self.undecoded
            if op == _OP_CHUNK and (not length or end > size):  # being written (its sizes not yet set), cut off
                self._cut_chunk(fields, pos, start, end if length else size)
                break
            if end > size:
                if op in (_OP_INDEX_DATA, _OP_CHUNK_INFO):
                    self.decoded += size - pos  # a cut-off index holds nothing the chunks do not
                break
            if op == _OP_CHUNK:
                done = self._chunk(fields, data[start:end])
            elif op in (_OP_CONNECTION, _OP_MSG_DATA):  # records outside chunks
                done = self._records(data[pos:end]) == end - pos
            else:
                done = op in (_OP_FILE_HEADER, _OP_INDEX_DATA, _OP_CHUNK_INFO)
                if op == _OP_FILE_HEADER:
                    self.header_end = end
                    self.decoded += len(MAGIC)
            if done and self.undecoded == undecoded:
                self.decoded += end - pos
            pos = end
        return self

    def _decompress(self, fields, payload, limit):
        """(decompressed data, whether all of it decompressed) of a chunk's data."""
        compression = fields.get('compression', b'')
        if compression == b'none':
            return payload, True
        if compression == b'lz4':
            return _lz4(payload, limit)
        self._problem('chunk compressed with %r' % compression.decode('ascii', 'replace'))
        return b'', False

    def _chunk(self, fields, payload):
        try:
            size = _u32(fields, 'size')
        except ValueError as error:
            self._problem('chunk: %s' % error)
            return False
        raw, whole = self._decompress(fields, payload, min(size, MAX_CHUNK_BYTES))
        if len(raw) != size:
            self._problem('a chunk does not decompress to its size')
            whole = False
        return self._records(raw) == len(raw) and whole

    def _cut_chunk(self, fields, pos, start, stop):
        before, undecoded = len(self.messages), self.undecoded
        payload = self.data[start:stop]
        raw, whole = self._decompress(fields, payload, MAX_CHUNK_BYTES)
        used = self._records(raw)
        self.cut = sum(1 for message in self.messages[before:] if message[0] != METADATA_TOPIC)
        if self.undecoded != undecoded:
            self.decoded += start - pos
        elif fields.get('compression') == b'none':
            self.decoded += start - pos + used
        elif whole and used == len(raw):
            self.decoded += start - pos + _lz4_extent(payload)
        else:
            self.decoded += start - pos

    def _records(self, raw):
        """Read the connection and message records in ``raw``; return the bytes they take (whole records)."""
        pos = 0
        while pos < len(raw):
            found = _record(raw, pos, len(raw))
            if found is None or found[2] + found[3] > len(raw):
                break
            fields, op, start, length = found
            if op == _OP_CONNECTION:
                self._connection(fields, raw[start:start + length])
            elif op == _OP_MSG_DATA:
                self._message(fields, raw[start:start + length])
            pos = start + length
        return pos

    def _connection(self, fields, payload):
        try:
            conn = _u32(fields, 'conn')
        except ValueError as error:
            self._problem('connection: %s' % error)
            return
        if conn in self.connections:  # each connection is written into the first chunk using it and the index
            return
        self.connections[conn] = (None, None)
        try:
            topic = fields.get('topic', b'').decode('utf-8')
            header = _fields(payload)
            msg_type = header['type'].decode('utf-8')
            cls = msg_codec.message_class(msg_type, header['message_definition'].decode('utf-8'))
            if cls._md5sum != header.get('md5sum', b'').decode('ascii', 'replace'):
                raise ValueError('%s: md5sum %s does not match its definition' % (msg_type, header.get('md5sum')))
        except (ValueError, KeyError) as error:
            self._problem('connection: %s' % error)
            return
        self.connections[conn] = (topic, cls)

    def _message(self, fields, payload):
        try:
            topic, cls = self.connections.get(_u32(fields, 'conn'), (None, None))
            secs, nsecs = struct.unpack('<II', fields.get('time', b''))
            if cls is None:
                raise ValueError('messages of a connection that could not be read')
            msg = cls().deserialize(payload)
        except Exception as error:  # genpy raises DeserializationError, struct.error, UnicodeDecodeError...
            self._problem('message: %s' % error)
            self.undecoded += 1
            return
        self.messages.append((topic, secs, nsecs, msg))


def _read_bag(path):
    """A ``_Salvage`` of the bag at ``path`` (never through a link); ValueError when it is no rosbag."""
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    try:
        size = os.fstat(fd).st_size
        data = mmap.mmap(fd, size, access=mmap.ACCESS_READ) if size else b''
    finally:
        os.close(fd)
    try:
        return _Salvage(data).run()
    finally:
        if size:
            data.close()


def _window_of(salvage):
    """(metadata, records in the order they were written) of what a salvage decoded."""
    import genpy
    from .bag_lz4 import bag_time
    from .window_buffer import Record
    metadata, records = None, []
    for topic, secs, nsecs, msg in salvage.messages:
        if topic == METADATA_TOPIC:
            if metadata is None:
                try:
                    metadata = safe_input.json_loads(msg.data)
                except ValueError:
                    metadata = {}
            continue
        records.append((Record(genpy.Time(secs, nsecs).to_sec(), topic, msg), secs, nsecs))
    metadata = metadata if isinstance(metadata, dict) else {}
    layout = metadata.pop('bag', None)
    stamps = layout.get('stamps') if isinstance(layout, dict) else None
    if isinstance(stamps, list) and len(stamps) >= len(records):
        # the exact stamps of the records, in window order (= the order they were written in)
        try:
            exact = [msg_codec.decode_float(stamp) for stamp in stamps[:len(records)]]
            if all(bag_time(stamp) == genpy.Time(secs, nsecs) for stamp, (_, secs, nsecs) in zip(exact, records)):
                return metadata, [record._replace(stamp=stamp) for stamp, (record, _, _) in zip(exact, records)]
        except ValueError:
            pass
    return metadata, [record for record, _, _ in records]


def _triggers(metadata, first_stamp):
    from .window_buffer import Trigger
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
                                name if isinstance(name, str) else None))
    return triggers


def _write_recovered(path, directory, base, metadata, records):
    """Write ``records`` as ``<base>_recovered.bag`` with ``metadata`` (of the leftover); return its path."""
    from .window_buffer import LogWindow
    for key in ('topics', 'types', 'counts', 'count', 'start', 'end', 'start_utc', 'end_utc', 'codec', 'layout',
                'cc_log_version'):
        metadata.pop(key, None)
    triggers = _triggers(metadata, records[0].stamp)
    metadata.pop('triggers', None)
    part = metadata.get('part', 0)
    window = LogWindow(records, triggers, part if isinstance(part, int) and not isinstance(part, bool) else 0)
    metadata['recovered'] = True
    metadata['recovered_from'] = os.path.basename(path)
    return log_format.write_window(window, directory, log_format.Format.BAG_LZ4, metadata,
                                   base=base + RECOVERED_SUFFIX)[0]


def _recover_bag(path, directory, base, extension, size):
    """Outcome of a bag-lz4 leftover that does not decode as a whole (see the module docstring)."""
    try:
        salvage = _read_bag(path)
    except ValueError as error:
        return Outcome(path, UNRECOVERABLE, '', 0, '%s: %s; kept as it is' % (path, error), size)
    lost = size - salvage.decoded
    why = ' (%s)' % '; '.join(salvage.problems) if salvage.problems else ''
    metadata, records = _window_of(salvage)
    if not records:
        if not salvage.undecoded and (not lost or salvage.header_end is None and size <= _BAG_HEADER_END):
            os.unlink(path)
            safe_files.fsync_directory(directory)
            return Outcome(path, EMPTY, '', 0, 'holds no message, nothing but rosbag headers (killed before any '
                                               'message data reached the disk): removed')
        return Outcome(path, UNRECOVERABLE, '', 0, '%s: no message decodes%s; %d bytes kept as they are'
                       % (path, why, size), size)
    written, count = _write_recovered(path, directory, base, metadata, records), len(records)
    cut = ', %d of them from a chunk cut off mid-write' % salvage.cut if salvage.cut else ''
    detail = 'cut off while written; %d messages recovered into %s%s' % (count, os.path.basename(written), cut)
    if salvage.undecoded:
        detail += '; %d message records could not be decoded' % salvage.undecoded
    if not lost:
        os.unlink(path)
        safe_files.fsync_directory(directory)
        return Outcome(path, PARTIAL, written, count, detail + '; every byte decoded: leftover removed')
    pid = os.path.basename(path).rpartition(log_format.TMP_MARK)[2]
    kept = safe_files.publish(path, (os.path.join(directory, base + extension + KEPT_MARK + pid + (
        '.%d' % number if number else '')) for number in itertools.count()))
    safe_files.fsync_directory(directory)
    return Outcome(path, PARTIAL, written, count, '%s; %d bytes could not be decoded%s: the leftover is kept as %s'
                   % (detail, lost, why, os.path.basename(kept)), lost, kept)


def recover(path):
    """Recover one leftover; return an Outcome. Raises ValueError for a path that is not a cc_log leftover
    and OSError when the directory cannot be written (nothing is deleted then)."""
    directory, base, extension, pid = _split(path)
    info = os.lstat(path)
    if not stat.S_ISREG(info.st_mode):
        return Outcome(path, UNRECOVERABLE, '', 0, '%s: not a regular file (a link?); left alone' % path)
    if _alive(pid) and time.time() - info.st_mtime < BUSY_SECONDS:
        return Outcome(path, BUSY, '', 0, 'process %d that writes it is still running' % pid)
    if info.st_size == 0:
        os.unlink(path)
        return Outcome(path, EMPTY, '', 0, 'empty (nothing had been written into it): removed')
    final = os.path.join(directory, base + extension)
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
    if extension != log_format.Format.EXTENSIONS[log_format.Format.BAG_LZ4]:
        return Outcome(path, UNRECOVERABLE, '', 0, '%s; kept as it is' % reason, info.st_size)
    return _recover_bag(path, directory, base, extension, info.st_size)


def recover_directory(directory):
    """Recover every leftover in ``directory``; a list of Outcomes (an OSError for one leftover becomes an
    UNRECOVERABLE outcome naming it; nothing is deleted then; one gone meanwhile is left out)."""
    outcomes = []
    for path in scan(directory):
        try:
            outcomes.append(recover(path))
        except (OSError, ValueError) as error:
            if isinstance(error, FileNotFoundError) and not os.path.lexists(path):
                continue  # recovered meanwhile by another process
            outcomes.append(Outcome(path, UNRECOVERABLE, '', 0, '%s; kept as it is' % error))
    return outcomes
