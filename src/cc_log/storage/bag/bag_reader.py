"""A rosbag 2.0 reader for replay and collect that walks the chunks itself (edge module: imports rosbag).

``read_raw(path, topics)`` yields the same ``Record(bag time, topic, None, 0, bytes, connection)`` as rosbag's
``read_messages(raw=True)`` in the same order, without rosbag's per-message Python: ``bag_open.open_bag`` opens
the bag with ``skip_index`` (connections, chunk infos and chunk headers only, with ``bagio``'s checks: the
definitions are checked before any message is read); the index data records after each chunk are read with
numpy (time, offset per message), the order is rosbag's (a stable merge of the connections' indexes by time);
a chunk is decompressed once (none, lz4, bz2; its declared size is capped at ``MAX_CHUNK_BYTES`` and must be
what it decompresses to) and the offsets and lengths of all its message data records are found in bulk. Record
headers are parsed with ``formats.bag_salvage``'s parser (``read_record``, ``field_u32``). A damaged bag is a
ValueError naming the file.
"""
import bz2
import collections
import heapq
import itertools

import numpy as np

from cc_log.storage.bag import bag_open
from cc_log.base import raw_message
from cc_log.storage.bag.bag_format import OP_CONNECTION, OP_INDEX_DATA, OP_MSG_DATA
from cc_log.storage.bag.bag_salvage import (
    MAX_CHUNK_BYTES, close_map, field_u32, lz4_decompress, map_file, read_record)
from cc_log.base.records import records_of

__all__ = ['read_raw', 'read_runs', 'MAX_CHUNK_BYTES']

CACHED_CHUNKS = 4  # decompressed chunks kept (bags whose connections were written into interleaved chunks)
RECORDS_BLOCK = 65536  # index entries turned into Python objects at a time

_OP_FIELD = b'\x04\x00\x00\x00op=%c' % OP_MSG_DATA
_MSG_HEADER_LEN = 38      # op, conn and time fields with their lengths
_OP_AT = (0, 13, 17, 30)  # where the op field starts in a message data header, for each order of its fields
_INDEX_ENTRY = np.dtype([('secs', '<u4'), ('nsecs', '<u4'), ('offset', '<u4')])


class _Damaged(Exception):
    """A structural problem of the bag (said as ``<path>: bag is truncated or damaged (...)``)."""


def read_raw(path, topics):
    """``bag_open.read_raw`` (same records, same order, same errors) read by walking the chunks."""
    yield from itertools.chain.from_iterable(read_runs(path, topics))


def read_runs(path, topics):
    """``read_raw``'s records as lists of consecutive records (those of one chunk, at most RECORDS_BLOCK)."""
    if isinstance(topics, str):
        topics = [topics]
    bag = bag_open.open_bag(path, skip_index=True)
    try:
        if not _plain(bag):
            reader = None
        else:
            for topic in topics:
                bag_open.check_topic(bag, topic)
            reader = _Reader(bag, path, topics)
    finally:
        bag.close()
    if reader is None:  # an encrypted bag: rosbag decrypts it
        yield list(bag_open.read_raw(path, topics))
        return
    yield from reader.records()


def _plain(bag):
    """Whether the bag's chunks can be read as written (no encryption)."""
    return type(getattr(bag, '_encryptor', None)).__name__ == '_ROSBagNoEncryptor'


class _Reader(object):
    """What ``read_raw`` needs of an open bag (taken while it is open), then the records from a map of the file."""

    def __init__(self, bag, path, topics):
        self.path = path
        wanted = set(topics)
        # rosbag's order of connections (the merge's tie-break) and their text headers, one object each
        self.connections = [c for c in bag._connections.values() if c.topic in wanted]
        self.headers = [raw_message.text_header(c.header) for c in self.connections]
        self.chunks = [(info, bag._chunk_headers[info.pos]) for info in bag._chunks]

    def _damaged(self, what):
        return ValueError('%s: bag is truncated or damaged (%s)' % (self.path, what))

    def records(self):
        """Yield lists of the records (see ``read_raw``), a run of one chunk's at a time."""
        data, _ = map_file(self.path)
        try:
            try:
                index = self._index(data)
            except _Damaged as error:
                raise self._damaged(error)
            yield from self._records(data, index)
        finally:
            close_map(data)

    def _index(self, data):
        """``(connection number, chunk number, bag time, offset)`` arrays of every message, in rosbag's order."""
        numbers = {c.id: k for k, c in enumerate(self.connections)}
        per_conn = [[] for _ in self.connections]  # connection -> [(chunk number, entries)] in chunk order
        for k, (info, header) in enumerate(self.chunks):
            pos = header.data_pos + header.compressed_size
            for _ in range(len(info.connection_counts)):
                found = read_record(data, pos, len(data))
                if found is None or found[1] != OP_INDEX_DATA or found[2] + found[3] > len(data):
                    raise _Damaged('index of the chunk at byte %d' % info.pos)
                fields, _, start, length = found
                try:
                    conn, count, version = (field_u32(fields, name) for name in ('conn', 'count', 'ver'))
                except ValueError as error:
                    raise _Damaged('index of the chunk at byte %d: %s' % (info.pos, error))
                if version != 1 or count * _INDEX_ENTRY.itemsize > length:
                    raise _Damaged('index of the chunk at byte %d' % info.pos)
                if conn in numbers:
                    entries = np.frombuffer(data, _INDEX_ENTRY, count, start)
                    per_conn[numbers[conn]].append((k, entries))
                pos = start + length
        conns, chunks, secs, nsecs, offsets = [], [], [], [], []
        for number, parts in enumerate(per_conn):
            for k, entries in parts:
                conns.append(np.full(len(entries), number, np.int64))
                chunks.append(np.full(len(entries), k, np.int64))
                secs.append(entries['secs'].astype(np.int64))
                nsecs.append(entries['nsecs'].astype(np.int64))
                offsets.append(entries['offset'].astype(np.int64))
        if not conns:
            return tuple(np.zeros(0, np.int64) for _ in range(4))
        conns, chunks, secs, nsecs, offsets = (np.concatenate(a) for a in (conns, chunks, secs, nsecs, offsets))
        nsec = secs * 1000000000 + nsecs
        order = _merge_order(nsec, conns)
        # genpy's Time.to_sec: float(secs) + float(nsecs) / 1e9 (rospy.Time canonicalises nsecs >= 1e9 first)
        secs, nsecs = np.divmod(nsec, 1000000000)
        stamps = secs.astype(float) + nsecs.astype(float) / 1e9
        return conns[order], chunks[order], stamps[order], offsets[order]

    def _records(self, data, index):
        """Lists of records: the consecutive ones of one chunk, at most RECORDS_BLOCK at a time, built without
        a Python call per record."""
        conns, chunks, stamps, offsets = index
        topics = [c.topic for c in self.connections]
        headers = self.headers
        by_chunk = np.argsort(chunks, kind='stable')  # the messages of chunk k: by_chunk[bounds[k]:bounds[k + 1]]
        bounds = np.searchsorted(chunks[by_chunk], np.arange(len(self.chunks) + 1))
        cache = collections.OrderedDict()  # chunk number -> (data, starts, ends), the CACHED_CHUNKS last used
        for block in range(0, len(conns), RECORDS_BLOCK):  # Python lists of a block at a time, not of the bag
            part = slice(block, block + RECORDS_BLOCK)
            in_chunks = chunks[part]
            edges = [0] + (np.flatnonzero(in_chunks[1:] != in_chunks[:-1]) + 1).tolist() + [len(in_chunks)]
            numbers, times, places = conns[part].tolist(), stamps[part].tolist(), offsets[part].tolist()
            for first, stop, k in zip(edges[:-1], edges[1:], in_chunks[edges[:-1]].tolist()):
                if k not in cache:
                    data_k = self._chunk(data, k)
                    mine = np.unique(offsets[by_chunk[bounds[k]:bounds[k + 1]]])
                    cache[k] = (data_k,) + self._extents(data_k, k, mine)
                    if len(cache) > CACHED_CHUNKS:
                        cache.popitem(last=False)
                cache.move_to_end(k)
                chunk, starts, ends = cache[k]
                run, kinds = places[first:stop], numbers[first:stop]
                raws = map(chunk.__getitem__, map(slice, map(starts.__getitem__, run), map(ends.__getitem__, run)))
                yield records_of(times[first:stop], map(topics.__getitem__, kinds), itertools.repeat(None),
                                 itertools.repeat(0), raws, map(headers.__getitem__, kinds))

    def _chunk(self, data, k):
        """The decompressed data of chunk ``k``."""
        info, header = self.chunks[k]
        start, stop = header.data_pos, header.data_pos + header.compressed_size
        declared = header.uncompressed_size
        if stop > len(data):
            raise self._damaged('chunk at byte %d runs past the end of the file' % info.pos)
        if declared > MAX_CHUNK_BYTES:
            raise self._damaged('chunk at byte %d declares %d bytes, more than %d'
                                % (info.pos, declared, MAX_CHUNK_BYTES))
        payload = data[start:stop]
        if header.compression == 'none':
            chunk, whole = payload, True
        elif header.compression == 'lz4':
            chunk, whole = lz4_decompress(payload, declared)
        elif header.compression == 'bz2':
            decompressor = bz2.BZ2Decompressor()
            try:
                chunk = decompressor.decompress(payload, declared + 1)
            except (OSError, ValueError, EOFError):
                chunk = b''
            whole = decompressor.eof
        else:
            raise self._damaged('unsupported compression type: %s' % header.compression)
        if not whole or len(chunk) != declared:
            raise self._damaged('chunk at byte %d does not decompress to its %d bytes' % (info.pos, declared))
        return chunk

    def _extents(self, chunk, k, offsets):
        """``({offset: data start}, {offset: data end})`` of the message data records at ``offsets`` of chunk
        ``k`` (rosbag skips connection records found there first)."""
        size = len(chunk)
        buf = np.frombuffer(chunk, np.uint8)
        if len(offsets) and offsets[-1] + 12 > size:
            raise self._damaged('index of the chunk at byte %d points past its end' % self.chunks[k][0].pos)
        header_len = _u32_at(buf, offsets)
        length_at = offsets + 4 + header_len
        bad = length_at + 4 > size
        length_at[bad] = 0
        data_len = _u32_at(buf, length_at)
        ends = length_at + 4 + data_len
        bad |= ends > size
        # a message data header is op (4 bytes with its name), conn (9) and time (13) in some order, 38 bytes
        # with their lengths: find op=2 where one of the orders puts it, else parse the header
        simple = np.zeros(len(offsets), bool)
        if size >= 46:
            near = np.minimum(offsets, size - 46)
            for at in _OP_AT:
                simple |= _bytes_at(buf, near + 4 + at, _OP_FIELD)
            simple &= (header_len == _MSG_HEADER_LEN) & (near == offsets)
        starts, stops = {}, {}
        for offset, start, end, ok, quick in zip(offsets.tolist(), (length_at + 4).tolist(), ends.tolist(),
                                                 (~bad).tolist(), simple.tolist()):
            if not (ok and quick):
                start, end = self._slow(chunk, offset, k)
            starts[offset], stops[offset] = start, end
        return starts, stops

    def _slow(self, chunk, offset, k):
        """(data start, end) of the message data record at ``offset`` parsed field by field, after any
        connection records (as rosbag reads it)."""
        pos = offset
        while True:
            found = read_record(chunk, pos, len(chunk))
            if found is None or found[2] + found[3] > len(chunk):
                raise self._damaged('message record at %d of the chunk at byte %d' % (pos, self.chunks[k][0].pos))
            _, op, start, length = found
            if op == OP_MSG_DATA:
                return start, start + length
            if op != OP_CONNECTION:
                raise self._damaged('expected a message data record at %d of the chunk at byte %d, got op %r'
                                    % (pos, self.chunks[k][0].pos, op))
            pos = start + length


def _u32_at(buf, positions):
    """Little-endian uint32 at each of ``positions`` (int64 array) of a uint8 array."""
    return (buf[positions].astype(np.int64) | buf[positions + 1].astype(np.int64) << 8
            | buf[positions + 2].astype(np.int64) << 16 | buf[positions + 3].astype(np.int64) << 24)


def _bytes_at(buf, positions, text):
    """Whether ``text`` is at each of ``positions`` (int64 array, each within ``buf`` with ``text``)."""
    pattern = np.frombuffer(text, np.uint8)
    return (buf[positions[:, None] + np.arange(len(pattern))] == pattern).all(axis=1)


def _merge_order(nsec, conns):
    """The order in which ``heapq.merge`` of the connections' indexes (``conns`` ascending in connection order,
    each connection's entries in chunk order) by time yields the entries: a stable sort by time when every
    connection's entries are in time order, else the merge itself."""
    same = conns[1:] == conns[:-1]
    if not np.any(same & (nsec[1:] < nsec[:-1])):
        return np.argsort(nsec, kind='stable')
    lists = []
    for number in np.unique(conns):
        positions = np.flatnonzero(conns == number)
        lists.append(list(zip(nsec[positions].tolist(), positions.tolist())))
    return np.array([position for _, position in heapq.merge(*lists, key=lambda entry: entry[0])], np.int64)
