"""Reading a rosbag 2.0 file cut off mid-write, record by record: what ``recovery`` needs of a bag-lz4 leftover.

``salvage(path)`` reads every complete message of every chunk (and of a chunk cut off mid-write, as far as its
data decompresses), each decoded with its connection header's class (``raw_message.message_class``: definitions
are data, checked there), and returns a ``Salvaged``. Pure: roslz4 is imported only to decompress chunks.
"""
import collections
import mmap
import os
import struct

from cc_log.base import msg_codec, raw_message, safe_input
from cc_log.base.records import Record
from cc_log.storage.bag.bag_format import (
    MAGIC, METADATA_TOPIC, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION, OP_FILE_HEADER, OP_INDEX_DATA, OP_MSG_DATA,
    bag_stamp)

MAX_CHUNK_BYTES = safe_input.MAX_CHUNK_BYTES

Salvaged = collections.namedtuple('Salvaged', 'metadata records decoded undecoded cut problems headers_only')
Salvaged.__doc__ = """What a file cut off mid-write still holds.

metadata: the window metadata it held ({} when none); records: its Records in window order (each with its message,
its serialized bytes and its connection header: callerid and latching kept); decoded: bytes of
the file that were decoded completely (the rest is lost if the file is removed); undecoded: message records
read but not decoded; cut: records taken from a chunk cut off mid-write; problems: why something was not
decoded (the first few reasons); headers_only: it holds no message, nothing but (part of) the format's headers.
"""


def salvage(path):
    """A ``Salvaged`` of the bag at ``path`` (never through a link); ValueError when it is no rosbag."""
    data, size = map_file(path, follow=False)
    try:
        found = _Salvage(data).run()
    finally:
        close_map(data)
    metadata, records = _window_of(found)
    headers_only = not records and not found.undecoded and (
        found.decoded == size or found.header_end is None and size <= _BAG_HEADER_END)
    return Salvaged(metadata, records, found.decoded, found.undecoded, found.cut, found.problems, headers_only)


def map_file(path, follow=True):
    """``(a read-only map of the file at path, its size)`` (``b''`` for an empty file; ``close_map`` it when done);
    ``follow``: through a symbolic link too."""
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC | (0 if follow else os.O_NOFOLLOW))
    try:
        size = os.fstat(fd).st_size
        return (mmap.mmap(fd, size, access=mmap.ACCESS_READ) if size else b''), size
    finally:
        os.close(fd)


def close_map(data):
    """Close a map of ``map_file`` (``b''``: none). One that views still use (numpy arrays of it, held by the
    traceback of an error raised while reading) is closed when the last of them goes: closing it now would
    raise BufferError in place of that error."""
    if isinstance(data, mmap.mmap):
        try:
            data.close()
        except BufferError:
            pass


# -- reading a rosbag 2.0 file cut off mid-write ------------------------------------------------------------

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


def read_record(data, pos, end):
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


def field_u32(fields, name):
    """The little-endian uint32 of header field ``name`` (of ``read_record``'s fields); ValueError when missing."""
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


def lz4_decompress(data, limit):
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

    ``messages``: (topic, secs, nsecs, message, serialized bytes, connection header) of every message decoded;
    ``undecoded``: message records that were read but could not be decoded; ``decoded``: bytes of the file in
    records decoded completely (every message in them too); ``header_end``: where the bag header record ends
    (None when the file ends inside it); ``cut``: messages taken from a chunk cut off mid-write; ``problems``:
    why something was not decoded (the first few reasons).
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
            found = read_record(data, pos, size)
            if found is None:
                claimed = _U32.unpack_from(data, pos)[0] if pos + 4 <= size else 0
                if claimed <= _MAX_HEADER and size < pos + 8 + claimed:
                    self.decoded += size - pos  # a record header cut off: no message data in it yet
                break
            fields, op, start, length = found
            if pos == len(MAGIC) and op != OP_FILE_HEADER:
                raise ValueError('not a rosbag 2.0 file (no bag header record)')
            end = start + length
            undecoded = self.undecoded
            if op == OP_CHUNK and (not length or end > size):  # being written (its sizes not yet set), cut off
                self._cut_chunk(fields, pos, start, end if length else size)
                break
            if end > size:
                if op in (OP_INDEX_DATA, OP_CHUNK_INFO):
                    self.decoded += size - pos  # a cut-off index holds nothing the chunks do not
                break
            if op == OP_CHUNK:
                done = self._chunk(fields, data[start:end])
            elif op in (OP_CONNECTION, OP_MSG_DATA):  # records outside chunks
                done = self._records(data[pos:end]) == end - pos
            else:
                done = op in (OP_FILE_HEADER, OP_INDEX_DATA, OP_CHUNK_INFO)
                if op == OP_FILE_HEADER:
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
            return lz4_decompress(payload, limit)
        self._problem('chunk compressed with %r' % compression.decode('ascii', 'replace'))
        return b'', False

    def _chunk(self, fields, payload):
        try:
            size = field_u32(fields, 'size')
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
            found = read_record(raw, pos, len(raw))
            if found is None or found[2] + found[3] > len(raw):
                break
            fields, op, start, length = found
            if op == OP_CONNECTION:
                self._connection(fields, raw[start:start + length])
            elif op == OP_MSG_DATA:
                self._message(fields, raw[start:start + length])
            pos = start + length
        return pos

    def _connection(self, fields, payload):
        try:
            conn = field_u32(fields, 'conn')
        except ValueError as error:
            self._problem('connection: %s' % error)
            return
        if conn in self.connections:  # each connection is written into the first chunk using it and the index
            return
        self.connections[conn] = (None, None, None)
        try:
            topic = fields.get('topic', b'').decode('utf-8')
            header = _fields(payload)
            msg_type = header['type'].decode('utf-8')
            md5sum = header.get('md5sum', b'').decode('ascii', 'replace')
            cls = raw_message.message_class({'type': msg_type, 'md5sum': md5sum,
                                             'message_definition': header['message_definition'].decode('utf-8')})
            if cls._md5sum != md5sum:
                raise ValueError('%s: md5sum %s does not match its definition' % (msg_type, header.get('md5sum')))
        except (ValueError, KeyError) as error:
            self._problem('connection: %s' % error)
            return
        self.connections[conn] = (topic, cls, raw_message.text_header(header))

    def _message(self, fields, payload):
        try:
            topic, cls, header = self.connections.get(field_u32(fields, 'conn'), (None, None, None))
            secs, nsecs = struct.unpack('<II', fields.get('time', b''))
            if cls is None:
                raise ValueError('messages of a connection that could not be read')
            msg = cls().deserialize(payload)
        except Exception as error:  # genpy raises DeserializationError, struct.error, UnicodeDecodeError...
            self._problem('message: %s' % error)
            self.undecoded += 1
            return
        self.messages.append((topic, secs, nsecs, msg, bytes(payload), header))


def _window_of(salvage):
    """(metadata, records in the order they were written) of what a salvage decoded."""
    import genpy
    metadata, records = None, []
    for topic, secs, nsecs, msg, raw, header in salvage.messages:
        if topic == METADATA_TOPIC:
            if metadata is None:
                try:
                    metadata = safe_input.json_loads(msg.data)
                except ValueError:
                    metadata = {}
            continue
        records.append((Record(genpy.Time(secs, nsecs).to_sec(), topic, msg, 0, raw, header), secs, nsecs))
    metadata = metadata if isinstance(metadata, dict) else {}
    layout = metadata.pop('bag', None)
    stamps = layout.get('stamps') if isinstance(layout, dict) else None
    if isinstance(stamps, list) and len(stamps) >= len(records):
        # the exact stamps of the records, in window order (= the order they were written in)
        try:
            exact = [msg_codec.decode_float(stamp) for stamp in stamps[:len(records)]]
            if all(bag_stamp(stamp) == (secs, nsecs) for stamp, (_, secs, nsecs) in zip(exact, records)):
                return metadata, [record._replace(stamp=stamp) for stamp, (record, _, _) in zip(exact, records)]
        except ValueError:
            pass
    return metadata, [record for record, _, _ in records]
