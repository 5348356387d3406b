"""Writing a rosbag 2.0 file: how ``bag_lz4`` writes a window (LZ4 chunks) and ``cclog export`` a bag.

``write_bag(stream, messages, headers, compression)`` writes the bytes that rosbag's ``Bag(...,
compression=...)`` (LZ4, the default; BZ2 or NONE) writes for the same messages (``write(topic, raw, time,
raw=True, connection_header=...)`` in the same order, then ``close``), byte for byte (``test/test_bag_writer.py``
compares them), without rosbag's Python per message: one connection per topic with its first message's header,
chunks closed after the message that takes them past ``CHUNK_THRESHOLD`` uncompressed bytes, each chunk's index
data records (entries in stable time order), then the connection and chunk info records, and last the bag
header (padded to 4096 bytes) pointing at them. As rosbag, it writes that header first with no index (a file
cut off before the end is read by ``bag_salvage``), then one chunk at a time: it holds one chunk in memory, not
the bag, and writes a chunk's record in pieces (its compressed bytes are not copied into one record).

An LZ4 chunk is one LZ4 frame as roslz4 (rosbag's LZ4) writes it: independent blocks of at most 1 MB, a content
checksum (XXH32, checked by roslz4 when the chunk is read), no content size (``lz4_frame``). A chunk of more than
``LZ4_FRAME_MIN`` bytes (the heavy messages' chunks) is compressed by python3-lz4's ``lz4.frame`` when it is
installed: the same liblz4 and the same frame, byte for byte, at a half to a third of roslz4's CPU (roslz4's
Python compressor streams through buffers it allocates per call) and without holding the GIL; a smaller one, or
any without python3-lz4, by roslz4. Pure: roslz4 is imported only to compress an LZ4 chunk, ``lz4.frame`` (when
installed) with this module.
"""
import bz2
import io
import struct

try:
    import lz4.frame as _lz4_frame
except ImportError:  # python3-lz4 is optional: roslz4 writes the same frames
    _lz4_frame = None

from cc_log.storage.bag.bag_format import (
    MAGIC, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION, OP_FILE_HEADER, OP_INDEX_DATA, OP_MSG_DATA)

CHUNK_THRESHOLD = 768 * 1024  # rosbag's default: a chunk is closed once it holds more uncompressed bytes
FILE_HEADER_LENGTH = 4096     # rosbag pads the bag header record's header to this many bytes
INDEX_VERSION = 1             # of index data and chunk info records
COMPRESSIONS = ('lz4', 'bz2', 'none')  # of the chunks, as rosbag names them

_U32 = struct.Struct('<I')
_TIME_AND_LENGTH = struct.Struct('<III')  # a message data record's time field and the length of its data
_INDEX_ENTRY = struct.Struct('<III')      # secs, nsecs, offset in the uncompressed chunk
#: Bytes above which ``lz4.frame.compress`` writes roslz4's frame: liblz4 shrinks the block size of a frame of at
#: most 256 KiB to fit it (roslz4 keeps 1 MB blocks whatever the size).
LZ4_FRAME_MIN = 256 * 1024


def lz4_frame(data):
    """One LZ4 frame of ``data`` (bytes or a buffer), byte for byte as ``roslz4.compress`` writes it (see the
    module docstring): through ``lz4.frame`` for more than ``LZ4_FRAME_MIN`` bytes when python3-lz4 is installed,
    else through roslz4."""
    if _lz4_frame is not None and len(data) > LZ4_FRAME_MIN:
        return _lz4_frame.compress(data, compression_level=0, block_size=_lz4_frame.BLOCKSIZE_MAX1MB,
                                   block_linked=False, content_checksum=True, store_size=False)
    import roslz4
    return roslz4.compress(data)


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
        """The chunk record (its data compressed as ``compression`` says) and the index data records after it, as
        a list of pieces to write in order: the compressed data is one piece, not copied into a record."""
        data = b''.join(self.parts)
        if compression == 'lz4':
            compressed = lz4_frame(data)
        else:
            compressed = bz2.compress(data) if compression == 'bz2' else data
        index = []
        for conn, entries in self.entries.items():
            entries = sorted(entries)  # by time, ties in write order (offsets grow): rosbag's insort_right
            index.append(header([('op', bytes((OP_INDEX_DATA,))), ('conn', _U32.pack(conn)),
                                 ('ver', _U32.pack(INDEX_VERSION)), ('count', _U32.pack(len(entries)))]))
            index.append(_U32.pack(_INDEX_ENTRY.size * len(entries)))
            index.extend(_INDEX_ENTRY.pack(*entry) for entry in entries)
        return [header([('op', bytes((OP_CHUNK,))), ('compression', compression), ('size', _U32.pack(len(data)))])
                + _U32.pack(len(compressed)), compressed, b''.join(index)]

    def info(self):
        """The chunk info record of this chunk (written in the index at the end of the bag)."""
        counts = [(conn, len(entries)) for conn, entries in self.entries.items()]
        return (header([('op', bytes((OP_CHUNK_INFO,))), ('ver', _U32.pack(INDEX_VERSION)),
                        ('chunk_pos', struct.pack('<Q', self.pos)), ('start_time', _time(*self.start)),
                        ('end_time', _time(*self.end)), ('count', _U32.pack(len(counts)))])
                + _U32.pack(8 * len(counts)) + b''.join(_U32.pack(conn) + _U32.pack(n) for conn, n in counts))


class BagStream(object):
    """A rosbag 2.0 file written a message at a time into ``stream`` (binary, seekable, positioned at the start
    of the bag): ``write(topic, secs, nsecs, data, header)`` appends a message (``header``: its topic's
    connection header, read when the topic's first message comes), ``flush()`` closes the chunk being filled
    so that everything written so far is on the stream in whole chunks, ``close()`` writes the index and the
    bag header (an unclosed stream holds a bag that ``bag_salvage`` reads). ``mark()`` / ``rollback()``: after
    a failed write, put the stream and the state back where they were at the last mark (the bytes after it
    are truncated), so that the same messages can be written again. ``chunk_threshold``: None for
    CHUNK_THRESHOLD; ``compression`` of the chunks, one of COMPRESSIONS."""

    def __init__(self, stream, chunk_threshold=None, compression='lz4'):
        if compression not in COMPRESSIONS:
            raise ValueError('compression: %r is not one of: %s' % (compression, ', '.join(COMPRESSIONS)))
        self.stream = stream
        self.compression = compression
        self.chunk_threshold = CHUNK_THRESHOLD if chunk_threshold is None else chunk_threshold
        self._start = stream.tell()
        stream.write(MAGIC + _file_header(0, 0, 0))
        self.pos = len(MAGIC) + 8 + FILE_HEADER_LENGTH  # bytes of the bag written
        self.connections = {}  # topic -> (conn, prefix of its message data records, its connection header)
        self._infos = []       # the chunk info record of each chunk written
        self._chunk = None
        self._mark = None

    def write(self, topic, secs, nsecs, data, header):
        """Append one message (``header``: the topic's connection header, a dict of str); ValueError for a time
        outside rosbag's (unsigned 32-bit secs, nsecs)."""
        if not (0 <= secs < 1 << 32 and 0 <= nsecs < 1 << 32):
            raise ValueError('time %d.%09d of a message on %s cannot be a bag time' % (secs, nsecs, topic))
        when = (secs, nsecs)
        chunk = self._chunk
        if chunk is None:
            chunk = self._chunk = _Chunk(self.pos, when)
        known = self.connections.get(topic)
        if known is None:
            conn = len(self.connections)
            chunk.add(_connection_record(conn, topic, header))
            known = self.connections[topic] = (conn, _message_prefix(conn), header)
        conn, prefix, _ = known
        chunk.entries.setdefault(conn, []).append((secs, nsecs, chunk.size))
        if when > chunk.end:
            chunk.end = when
        elif when < chunk.start:
            chunk.start = when
        chunk.add(prefix + _TIME_AND_LENGTH.pack(secs, nsecs, len(data)))
        chunk.add(data)
        if chunk.size > self.chunk_threshold:
            self.flush()

    def flush(self):
        """Write the chunk being filled, if any."""
        if self._chunk is not None:
            pieces = self._chunk.record(self.compression)
            for piece in pieces:
                self.stream.write(piece)
            self._infos.append(self._chunk.info())
            self.pos += sum(map(len, pieces))
            self._chunk = None

    def mark(self):
        """Remember the state after the last flush (``rollback`` returns to it)."""
        self.flush()
        self._mark = (self.pos, dict(self.connections), len(self._infos))

    def rollback(self):
        """Return to the last ``mark`` (or the empty bag): drop what was written since, truncating the stream."""
        self._chunk = None
        if self._mark is None:
            self.connections, pos, infos = {}, len(MAGIC) + 8 + FILE_HEADER_LENGTH, 0
        else:
            pos, connections, infos = self._mark
            self.connections = dict(connections)
        del self._infos[infos:]
        self.pos = pos
        self.stream.seek(self._start + len(MAGIC))
        self.stream.write(_file_header(0, 0, 0))  # close may have pointed it at an index
        self.stream.seek(self._start + pos)
        self.stream.truncate()

    @property
    def chunks(self):
        """Chunks written so far."""
        return len(self._infos)

    def close(self):
        """Flush, then write the index (connection and chunk info records) and the bag header pointing at it;
        ValueError when no message was written."""
        self.flush()
        if not self._infos:
            raise ValueError('a bag needs at least one message')
        stream = self.stream
        for topic, (conn, _, header) in self.connections.items():
            stream.write(_connection_record(conn, topic, header))
        stream.write(b''.join(self._infos))
        end = stream.tell()
        stream.seek(self._start + len(MAGIC))
        stream.write(_file_header(self.pos, len(self.connections), len(self._infos)))
        stream.seek(end)


def write_bag(stream, messages, headers, chunk_threshold=None, compression='lz4'):
    """Write the bag of ``messages`` into ``stream`` (binary, seekable, positioned at the start of the bag):
    ``messages``, any iterable of (topic, secs, nsecs, serialized bytes) in the order written; ``headers``:
    topic -> its connection header (a dict of str: topic, type, md5sum, message_definition, ... in the order
    they are written; read when the topic's first message comes); ``chunk_threshold``: None for
    CHUNK_THRESHOLD; ``compression`` of the chunks, one of COMPRESSIONS. ValueError for no message or a time
    outside rosbag's (unsigned 32-bit secs, nsecs); the stream then holds an unfinished bag."""
    bag = BagStream(stream, chunk_threshold, compression)
    write = bag.write
    for topic, secs, nsecs, data in messages:
        write(topic, secs, nsecs, data, headers[topic])
    bag.close()


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
