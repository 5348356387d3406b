"""Writing a rosbag 2.0 file: how ``bag_lz4`` writes a window (LZ4 chunks) and ``cclog export`` a bag.

``write_bag(stream, messages, headers, compression)`` writes the bytes that rosbag's ``Bag(...,
compression=...)`` (LZ4, the default; BZ2 or NONE) writes for the same messages (``write(topic, raw, time,
raw=True, connection_header=...)`` in the same order, then ``close``), byte for byte (``test/test_bag_writer.py``
compares them), without rosbag's Python per message: one connection per topic with its first message's header,
chunks closed after the message that takes them past ``CHUNK_THRESHOLD`` uncompressed bytes, each chunk's index
data records (entries in stable time order), then the connection and chunk info records, and last the bag
header (padded to 4096 bytes) pointing at them. As rosbag, it writes that header first with no index (a file
cut off before the end is read by ``bag_salvage``), then one chunk at a time: it holds one chunk in memory, not
the bag. Pure: roslz4 (rosbag's LZ4) is imported only to compress LZ4 chunks.
"""
import bz2
import io
import struct

from .bag_lz4 import MAGIC
from .bag_salvage import OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION, OP_FILE_HEADER, OP_INDEX_DATA, OP_MSG_DATA

CHUNK_THRESHOLD = 768 * 1024  # rosbag's default: a chunk is closed once it holds more uncompressed bytes
FILE_HEADER_LENGTH = 4096     # rosbag pads the bag header record's header to this many bytes
INDEX_VERSION = 1             # of index data and chunk info records
COMPRESSIONS = ('lz4', 'bz2', 'none')  # of the chunks, as rosbag names them

_U32 = struct.Struct('<I')
_TIME_AND_LENGTH = struct.Struct('<III')  # a message data record's time field and the length of its data
_INDEX_ENTRY = struct.Struct('<III')      # secs, nsecs, offset in the uncompressed chunk


def field(name, value):
    """One ``name=value`` field of a record header, with its length; name and value bytes or str (UTF-8)."""
    name = name.encode() if isinstance(name, str) else name
    value = value.encode() if isinstance(value, str) else value
    return _U32.pack(len(name) + 1 + len(value)) + name + b'=' + value


def header(fields):
    """A record header: its length, then the ``fields`` ((name, value) pairs) in order."""
    body = b''.join(field(name, value) for name, value in fields)
    return _U32.pack(len(body)) + body


def _message_prefix(conn):
    """A message data record of connection ``conn`` up to its time: the header's length, its op and conn fields
    and the time field's length and name (then secs, nsecs, the data's length, the data)."""
    op, connection = field('op', bytes((OP_MSG_DATA,))), field('conn', _U32.pack(conn))
    time_length = len('time=') + 8
    return _U32.pack(len(op) + len(connection) + 4 + time_length) + op + connection + _U32.pack(time_length) + b'time='


def _time(secs, nsecs):
    return _U32.pack(secs) + _U32.pack(nsecs)


def _connection_record(conn, topic, connection_header):
    return (header([('op', bytes((OP_CONNECTION,))), ('topic', topic), ('conn', _U32.pack(conn))])
            + header(connection_header.items()))


class _Chunk(object):
    """The chunk being filled: its uncompressed parts, size, time span and index entries per connection."""

    def __init__(self, pos, when):
        self.pos = pos
        self.start = self.end = when
        self.parts = []
        self.size = 0
        self.entries = {}  # conn -> [(secs, nsecs, offset)], connections in order of first message

    def add(self, data):
        self.parts.append(data)
        self.size += len(data)

    def record(self, compression):
        """The chunk record (its data compressed as ``compression`` says) and the index data records after it."""
        data = b''.join(self.parts)
        if compression == 'lz4':
            import roslz4
            compressed = roslz4.compress(data)
        else:
            compressed = bz2.compress(data) if compression == 'bz2' else data
        out = [header([('op', bytes((OP_CHUNK,))), ('compression', compression), ('size', _U32.pack(len(data)))]),
               _U32.pack(len(compressed)), compressed]
        for conn, entries in self.entries.items():
            entries = sorted(entries)  # by time, ties in write order (offsets grow): rosbag's insort_right
            out.append(header([('op', bytes((OP_INDEX_DATA,))), ('conn', _U32.pack(conn)),
                               ('ver', _U32.pack(INDEX_VERSION)), ('count', _U32.pack(len(entries)))]))
            out.append(_U32.pack(_INDEX_ENTRY.size * len(entries)))
            out.extend(_INDEX_ENTRY.pack(*entry) for entry in entries)
        return b''.join(out)

    def info(self):
        """The chunk info record of this chunk (written in the index at the end of the bag)."""
        counts = [(conn, len(entries)) for conn, entries in self.entries.items()]
        return (header([('op', bytes((OP_CHUNK_INFO,))), ('ver', _U32.pack(INDEX_VERSION)),
                        ('chunk_pos', struct.pack('<Q', self.pos)), ('start_time', _time(*self.start)),
                        ('end_time', _time(*self.end)), ('count', _U32.pack(len(counts)))])
                + _U32.pack(8 * len(counts)) + b''.join(_U32.pack(conn) + _U32.pack(n) for conn, n in counts))


def write_bag(stream, messages, headers, chunk_threshold=None, compression='lz4'):
    """Write the bag of ``messages`` into ``stream`` (binary, seekable, positioned at the start of the bag):
    ``messages``, any iterable of (topic, secs, nsecs, serialized bytes) in the order written; ``headers``:
    topic -> its connection header (a dict of str: topic, type, md5sum, message_definition, ... in the order
    they are written; read when the topic's first message comes); ``chunk_threshold``: None for
    CHUNK_THRESHOLD; ``compression`` of the chunks, one of COMPRESSIONS. ValueError for no message or a time
    outside rosbag's (unsigned 32-bit secs, nsecs); the stream then holds an unfinished bag."""
    if compression not in COMPRESSIONS:
        raise ValueError('compression: %r is not one of: %s' % (compression, ', '.join(COMPRESSIONS)))
    chunk_threshold = CHUNK_THRESHOLD if chunk_threshold is None else chunk_threshold
    start = stream.tell()
    stream.write(MAGIC + _file_header(0, 0, 0))
    pos = len(MAGIC) + 8 + FILE_HEADER_LENGTH
    connections = {}  # topic -> (conn, prefix of its message data records)
    infos = []  # the chunk info record of each chunk written
    chunk = None
    for topic, secs, nsecs, data in messages:
        if not (0 <= secs < 1 << 32 and 0 <= nsecs < 1 << 32):
            raise ValueError('time %d.%09d of a message on %s cannot be a bag time' % (secs, nsecs, topic))
        when = (secs, nsecs)
        if chunk is None:
            chunk = _Chunk(pos, when)
        if topic not in connections:
            conn = len(connections)
            chunk.add(_connection_record(conn, topic, headers[topic]))
            connections[topic] = (conn, _message_prefix(conn))
        conn, prefix = connections[topic]
        chunk.entries.setdefault(conn, []).append((secs, nsecs, chunk.size))
        if when > chunk.end:
            chunk.end = when
        elif when < chunk.start:
            chunk.start = when
        chunk.add(prefix + _TIME_AND_LENGTH.pack(secs, nsecs, len(data)))
        chunk.add(data)
        if chunk.size > chunk_threshold:
            pos = _close(chunk, infos, stream, pos, compression)
            chunk = None
    if chunk is not None:
        pos = _close(chunk, infos, stream, pos, compression)
    if not infos:
        raise ValueError('a bag needs at least one message')
    index_pos = pos
    for topic, (conn, _) in connections.items():
        stream.write(_connection_record(conn, topic, headers[topic]))
    stream.write(b''.join(infos))
    end = stream.tell()
    stream.seek(start + len(MAGIC))
    stream.write(_file_header(index_pos, len(connections), len(infos)))
    stream.seek(end)


def bag_bytes(messages, headers, chunk_threshold=None, compression='lz4'):
    """The bytes ``write_bag`` writes (same arguments)."""
    stream = io.BytesIO()
    write_bag(stream, messages, headers, chunk_threshold, compression)
    return stream.getvalue()


def _file_header(index_pos, conn_count, chunk_count):
    """The bag header record, padded as rosbag pads it."""
    fields = header([('op', bytes((OP_FILE_HEADER,))), ('index_pos', struct.pack('<Q', index_pos)),
                     ('conn_count', _U32.pack(conn_count)), ('chunk_count', _U32.pack(chunk_count))])
    padding = FILE_HEADER_LENGTH - (len(fields) - 4)
    return fields + _U32.pack(padding) + b' ' * padding


def _close(chunk, infos, stream, pos, compression):
    record = chunk.record(compression)
    stream.write(record)
    infos.append(chunk.info())
    return pos + len(record)
