"""The ``bag-lz4`` window file: one LZ4-compressed rosbag (format 2.0) per window.

``rosbag info``, ``rosbag play`` and rqt_bag open it. Records are written on their own topics with their
stamp as the bag time; a record held as serialized bytes is written as they are, with its original
connection header (``callerid``, ``latching``, the publisher's definition), without decoding it. The
window metadata is a JSON object in one ``std_msgs/String`` message on
``/cc_log/metadata``, written first at the time of the first record (``rostopic echo -b FILE
/cc_log/metadata`` shows it; ``rosbag play FILE --topics ...`` can leave it out); a file written a part at a
time (``WindowStream``) ends with its final metadata, in a chunk of its own at the time of its last record, so
that rosbag's start and end (``rosbag info``: of its first and last chunk) are its first and last record's.
The JSON also holds a ``"bag"`` object that ``read`` uses and removes:

- ``topics``: the record topics in order of first appearance (ties in bag time are read in this order);
- ``order``: only when the records were not in (bag time, topic) order: the index in bag read order of
  each record, in window order;
- ``stamps``: only when some record stamp (float seconds) does not survive the trip through bag time
  (secs, nsecs): every record's stamp, in window order;
- ``crc32`` (layout 2): the CRC-32 of the records as ``read`` returns them (``records_crc``: each topic's type,
  md5sum and definition, each record's topic, stamp and length, in window order; up to layout 3 its serialized
  bytes too). rosbag's records have no checksum of their own; the bytes of each message are covered by the
  LZ4 frame of the chunk holding them, whose content checksum (XXH32) roslz4 checks as it reads the chunk, so
  since layout 4 the CRC leaves them out (the writer reads each payload once, to compress it). ``read``
  refuses a file whose records do not match it (layout 1 files, written before it, are read without it).

A record held as bytes that are not exactly one message of its connection's type (a buggy publisher; two
types on one topic in a replayed bag: ``payload_check``) is refused, so that rosbag reads every message of the
file; the refused are counted per topic in the metadata's ``dropped`` (with messages shed before the writer).

The file is the bag rosbag would write for the same messages, byte for byte, written without rosbag
(``bag.bag_writer``). Edge module: rosbag is imported inside the functions that read or append with it
(``read``, ``read_metadata``, ``write_record``), so importing cc_log.bag_lz4 costs nothing.
"""
import collections
import itertools
import json
import os
import struct
import zlib

from cc_log.base import msg_codec, raw_message, safe_files, safe_input
from cc_log.base.records import Record
from cc_log.storage import payload_check
from cc_log.storage.bag import bag_salvage, bag_writer
from cc_log.storage.bag.bag_format import MAGIC, METADATA_TOPIC, bag_stamp  # noqa: F401  (bag_lz4.MAGIC, ...)

CODEC = 'bag-lz4'
RAW_RECORDS = True  # write_window hands records over as they are: serialized bytes are written as bytes
EXTENSION = '.bag'
#: Memory a part takes per estimated byte of it (``WindowBuffer``'s part_factor): the writer streams the bytes,
#: but at 1 kHz the live node's RSS grew 1.7-2.4 KB per buffered message estimated at 0.7 KB (allocator
#: fragmentation across the receiving threads; bench/memory_live.py --format bag-lz4).
PART_FACTOR = 4.0
LAYOUT_VERSION = 4  # 2: the layout holds the records' crc32; 3: computed records first (written a part at a time);
#                      4: of the records' lengths, not their bytes (LZ4's checksum covers them)
_STRING_DEFINITION = 'string data\n'


def write(target, records, metadata):
    """Write ``records`` (window order) and ``metadata`` (a JSON-able dict) as an LZ4 bag into ``target``: a
    binary, seekable file object open for writing, or the path of a new file (created with
    ``safe_files.create``: never over a file, never through a link)."""
    if isinstance(target, (str, bytes, os.PathLike)):
        with os.fdopen(safe_files.create(target), 'w+b') as stream:
            return write(stream, records, metadata)
    bag_writer.write_bag(target, *bag_messages(records, metadata), chunk_threshold=chunk_bytes(metadata))


def chunk_bytes(metadata):
    """The uncompressed bytes at which a chunk is closed: the metadata's ``chunk_kb`` (``~chunk_kb``, rosbag
    record's ``--chunksize``) KB of 1024 bytes, else None (``bag_writer.CHUNK_THRESHOLD``)."""
    kb = (metadata or {}).get('chunk_kb')
    return int(kb) * 1024 if isinstance(kb, int) and not isinstance(kb, bool) and kb > 0 else None


def bag_messages(records, metadata):
    """``(messages, headers)`` of the window's bag: an iterator of (topic, secs, nsecs, serialized bytes) in the
    order written, the metadata first, and each topic's connection header. A record held as serialized bytes
    with its connection header is written as it is; a decoded one is serialized, with its class's header.
    The records are read twice (the metadata holds their order, stamps and checksum); each message is made
    when it is written, so only the sort keys are held, while the metadata is made (a decoded record is
    serialized in both passes; the nodes and replay hand over bytes). ValueError for no records, the reserved
    topic, a bad stamp."""
    if not records:
        raise ValueError('window: has no records')
    layout = _Layout()
    records = layout.add(records)
    if not records:
        raise ValueError('window: none of its records is of its connection\'s type (%d refused)'
                         % sum(layout.refused.values()))
    headers = dict(layout.headers)
    metadata_message = (METADATA_TOPIC,) + layout.first + (layout.metadata_data(metadata),)
    return itertools.chain([metadata_message], map(bag_message, records)), headers


class _Layout(object):
    """What a window's metadata says of its records (``"bag"``: topics, order, stamps, crc32), gathered as the
    records are written, a batch at a time, with each topic's connection header (``headers``, the metadata topic
    first)."""

    def __init__(self):
        self.headers = {METADATA_TOPIC: raw_message.class_header(METADATA_TOPIC, _string_class())}
        self._sources = {}  # (topic, id(connection or class)) -> it (held, so that its id stays its own)
        self._rank = {}     # record topic -> its number, in order of first appearance
        self.keys = []      # (bag time, rank) of each record, in window order
        self.exact = True   # every stamp survives the trip through bag time
        self.stamps = []    # every record's stamp (float s), in window order
        self.crc = 0        # of the records (``records_crc``), so far
        self.first = None   # the earliest bag time
        self.last = None    # the latest bag time
        self.refused = collections.Counter()  # topic -> records refused (bytes not of their connection's type)
        self._check = payload_check.PayloadCheck()

    def add(self, records):
        """Take the next records of the window (checked: the reserved topic, bag times, one type per topic);
        return those to write: a record whose bytes are not a message of its connection's type is refused
        (``payload_check``), counted by topic in ``refused`` (the metadata's ``dropped``)."""
        records, refused = self._check.split(records)
        self.refused.update(refused)
        for record in records:
            if record.topic == METADATA_TOPIC:
                raise ValueError('topic %s: reserved for the window metadata' % METADATA_TOPIC)
        _add_headers(self.headers, self._sources, records)
        rank = self._rank
        for topic in self.headers:
            if topic != METADATA_TOPIC and topic not in rank:
                rank[topic] = len(rank)
        keys = [(bag_stamp(record.stamp), rank[record.topic]) for record in records]
        if keys:
            times = [key[0] for key in keys]
            earliest, latest = min(times), max(times)
            self.first = earliest if self.first is None else min(self.first, earliest)
            self.last = latest if self.last is None else max(self.last, latest)
        self.exact = self.exact and all(secs + nsecs / 1e9 == record.stamp
                                        for ((secs, nsecs), _), record in zip(keys, records))
        self.keys.extend(keys)
        self.stamps.extend(record.stamp for record in records)
        self.crc = _records_crc(self.crc, rank, ((record.topic, record.stamp, _data(record)) for record in records),
                                payloads=False)
        return records

    def state(self):
        """What ``restore`` needs to forget the records added after this call."""
        return (dict(self.headers), dict(self._sources), dict(self._rank), len(self.keys), self.exact, self.crc,
                self.first, self.last, collections.Counter(self.refused))

    def restore(self, state):
        """Back to ``state`` (of ``state()``)."""
        headers, sources, rank, count, self.exact, self.crc, self.first, self.last, self.refused = state
        self.headers, self._sources, self._rank = headers, sources, rank
        del self.keys[count:]
        del self.stamps[count:]

    def layout(self):
        """The ``"bag"`` object of the metadata (layout 3)."""
        topics = list(self._rank)
        layout = {'topics': topics}
        keys = self.keys
        if any(later < earlier for earlier, later in zip(keys, keys[1:])):
            read_order = sorted(range(len(keys)), key=keys.__getitem__)
            position = {index: place for place, index in enumerate(read_order)}
            layout['order'] = [position[i] for i in range(len(keys))]
        if not self.exact:
            layout['stamps'] = [msg_codec.encode_float(float(stamp)) for stamp in self.stamps]
        layout['crc32'] = _topics_crc(self.crc, topics, self.headers)
        return layout

    def metadata_data(self, metadata, final=True):
        """The serialized std_msgs/String of the window metadata; ``final``: with the layout of every record
        added (else a provisional one, without it, written first by a stream)."""
        meta = payload_check.with_dropped(metadata or {}, self.refused)
        meta.setdefault('codec', CODEC)
        meta['layout'] = LAYOUT_VERSION
        if final:
            meta['bag'] = self.layout()
        return raw_message.serialized(_string_class()(data=json.dumps(meta, allow_nan=False, separators=(',', ':'))))


class WindowStream(object):
    """A window written into a bag a part at a time (a long window, or one larger than the memory budget, is one
    file, as ``rosbag record`` writes one): ``append(records, metadata)`` writes a part (the first also writes
    a provisional metadata message, so that a file cut off mid-write is salvaged with it), ``finish(metadata)``
    writes the final metadata (the layout of every record, at the time of the latest record: rosbag takes a bag's
    end from its last chunk) and the index. A failed ``append`` is rolled back: the same part may be appended
    again."""

    def __init__(self, stream):
        self.bag = bag_writer.BagStream(stream)
        self._layout = _Layout()
        self.count = 0

    def append(self, records, metadata):
        """Write the next part of the window (``records``, in window order); ``metadata``: the window's so far."""
        if not records:
            return
        bag, layout = self.bag, self._layout
        bag.mark()
        saved = layout.state()
        try:
            records = layout.add(records)
            headers = layout.headers
            if self.count == 0 and records:
                bag.chunk_threshold = chunk_bytes(metadata) or bag.chunk_threshold
                bag.write(METADATA_TOPIC, *layout.first, layout.metadata_data(metadata, final=False),
                          headers[METADATA_TOPIC])
            write = bag.write
            for record in records:
                write(record.topic, *bag_stamp(record.stamp), _data(record), headers[record.topic])
            bag.flush()
            bag.stream.flush()  # a full disk fails here, in the part that filled it
        except BaseException:
            bag.rollback()
            layout.restore(saved)
            raise
        self.count += len(records)

    def finish(self, metadata):
        """Write the final metadata and close the bag; ValueError when no record was appended."""
        if not self.count:
            raise ValueError('window: has no records')
        layout, bag = self._layout, self.bag
        bag.mark()
        try:
            bag.write(METADATA_TOPIC, *layout.last, layout.metadata_data(metadata), layout.headers[METADATA_TOPIC])
            bag.close()
            bag.stream.flush()
        except BaseException:
            bag.rollback()
            raise


def _string_class():
    return raw_message.message_class({'type': 'std_msgs/String', 'message_definition': _STRING_DEFINITION})


def connection_headers(records):
    """topic -> the connection header its records are written with: the first record's own (a record with its
    connection header: held as serialized bytes, or read from a json-xz window that kept its publisher's
    ``callerid`` and ``latching``), else its message class's. ValueError when a topic's records are of two
    message types (a bag has one connection per topic, as rosbag writes it)."""
    headers = {}
    _add_headers(headers, {}, records)
    return headers


def _add_headers(headers, sources, records):
    """``connection_headers`` of more records into ``headers`` (``sources``: the connections and classes seen)."""
    for record in records:
        source = record.connection if record.connection else type(record.msg)
        key = (record.topic, id(source))
        if key in sources:
            continue
        sources[key] = source  # held, so that its id stays its own
        header = (dict(source, topic=record.topic) if record.connection else
                  raw_message.class_header(record.topic, source))
        first = headers.setdefault(record.topic, header)
        if first.get('md5sum') != header.get('md5sum'):
            raise ValueError('topic %s: messages of two types (%s and %s); a bag holds one type per topic'
                             % (record.topic, first.get('type'), header.get('type')))


def bag_message(record):
    """``(topic, secs, nsecs, serialized bytes)`` of a record, as ``bag_writer.write_bag`` takes it."""
    return (record.topic,) + bag_stamp(record.stamp) + (_data(record),)


def _held_raw(record):
    """Whether the record is written from its serialized bytes with its own connection header."""
    return record.raw is not None and bool(record.connection)


def _data(record):
    """The serialized bytes of a record (serialized now when it holds a decoded message)."""
    return record.raw if _held_raw(record) else raw_message.serialized(record.msg)


def records_crc(topics, headers, records, layout=LAYOUT_VERSION):
    """CRC-32 of a window's records: ``topics`` in order with their connection ``headers`` (topic -> dict;
    type, md5sum and message_definition count, str or bytes) and ``records`` ((topic, stamp, serialized bytes)
    in window order); layout 3 (a file written a part at a time) takes the records first, layout 2 the topics;
    layout 4 the records' lengths, not their bytes (the chunks' LZ4 checksums cover them)."""
    rank = {topic: number for number, topic in enumerate(topics)}
    if layout >= 3:
        return _topics_crc(_records_crc(0, rank, records, payloads=layout < 4), topics, headers)
    return _records_crc(_topics_crc(0, topics, headers), rank, records)


def _topics_crc(crc, topics, headers):
    for topic in topics:
        header = headers[topic]
        for part in (topic, header.get('type', ''), header.get('md5sum', ''), header.get('message_definition', '')):
            crc = zlib.crc32(part if isinstance(part, bytes) else part.encode(), crc)
            crc = zlib.crc32(b'\0', crc)
    return crc


def _records_crc(crc, rank, records, payloads=True):
    """``crc`` with ``records`` added: each one's topic number, stamp, length and (``payloads``) serialized bytes."""
    pack = _RECORD_HEAD.pack
    for topic, stamp, data in records:
        crc = zlib.crc32(pack(rank[topic], stamp, len(data)), crc)
        if payloads:
            crc = zlib.crc32(data, crc)
    return crc


_RECORD_HEAD = struct.Struct('<IdI')  # topic number, stamp, length of the serialized bytes


def write_record(bag, record, time):
    """Write one Record into an open rosbag at ``time``: its serialized bytes with the publisher's connection
    header when it has them (latching and callerid kept), else the decoded message."""
    if _held_raw(record):
        header = dict(record.connection, topic=record.topic)
        bag.write(record.topic, (header['type'], record.raw, header['md5sum'],
                                 raw_message.message_class(record.connection)), time, raw=True,
                  connection_header=header)
    else:
        bag.write(record.topic, record.msg, time)


def encoder(records, metadata):
    """A function that writes the window into a stream (one chunk in memory at a time)."""
    return lambda stream: write(stream, records, metadata)


def salvage(path):
    """What a bag cut off mid-write still holds (``bag_salvage.Salvaged``); ValueError when it is no rosbag."""
    return bag_salvage.salvage(path)


def read(path, stream=None):
    """``(metadata, records)`` of a bag-lz4 window file (``stream``: that file, already open), each record with
    its message, its serialized bytes and its topic's connection header (a dict of str);
    ValueError('<path>: <what is wrong>') otherwise, also before any message is read when a connection's
    message definition is unsafe (``safe_input.check_bag``)."""
    import rosbag
    try:
        stream = stream or safe_input.open_input(path)
        magic = stream.read(len(MAGIC))
        stream.seek(0)
    except OSError as error:
        raise ValueError('%s: cannot read (%s)' % (path, error.strerror or error))
    if magic != MAGIC:
        stream.close()
        raise ValueError('%s: not a rosbag 2.0 file' % path)
    metadata = None
    read_records, headers, classes = [], {}, {}
    with stream:
        try:
            bag = rosbag.Bag(stream)
        except Exception as error:  # rosbag raises ROSBag*Exception, struct.error, lz4 errors, ...
            raise ValueError('%s: corrupt or truncated bag (%s: %s)' % (path, type(error).__name__, error))
        with bag:
            safe_input.check_bag(bag, path)
            try:
                for topic, raw, time, header in bag.read_messages(raw=True, return_connection_header=True):
                    # raw: (type, serialized bytes, md5sum, position, class)
                    if topic == METADATA_TOPIC:
                        metadata = _chosen(metadata, _metadata(_deserialized(raw[4], raw[1]).data))
                        continue
                    if topic not in headers:
                        headers[topic], classes[topic] = header, raw[4]
                    read_records.append((time, Record(time.to_sec(), topic, None, 0, raw[1])))
            except _BadMetadata as error:
                raise ValueError('%s: bad metadata JSON on %s (%s)' % (path, METADATA_TOPIC, error))
            except Exception as error:
                raise ValueError('%s: corrupt or truncated bag (%s: %s)' % (path, type(error).__name__, error))
    if not isinstance(metadata, dict) or not isinstance(metadata.get('bag'), dict):
        raise ValueError('%s: not a cc_log window (no metadata on %s)' % (path, METADATA_TOPIC))
    layout = metadata.pop('bag')
    try:
        records = _restore(read_records, layout)
        if 'crc32' in layout and layout['crc32'] != records_crc(
                layout['topics'], headers, ((record.topic, record.stamp, record.raw) for record in records),
                metadata.get('layout', 2)):
            raise ValueError('the records do not match their crc32: the file is damaged')
    except (ValueError, TypeError, KeyError, IndexError) as error:
        raise ValueError('%s: metadata does not fit the records (%s)' % (path, error))
    connections = {topic: raw_message.text_header(header) for topic, header in headers.items()}
    try:
        return metadata, [Record(record.stamp, record.topic, _deserialized(classes[record.topic], record.raw), 0,
                                 record.raw, connections[record.topic]) for record in records]
    except Exception as error:  # genpy raises struct.error, DeserializationError, UnicodeDecodeError, ...
        raise ValueError('%s: corrupt bag (%s: %s)' % (path, type(error).__name__, error))


def read_metadata(path, stream=None):
    """``(metadata, counts)`` of a bag-lz4 window file without reading its messages: the metadata message
    (``read``'s metadata, its ``"bag"`` layout taken out) from the chunk(s) holding it, found by the bag's
    index, and ``counts`` ({topic: messages}) from the index's chunk infos. Only the chunks holding a metadata
    message are decompressed (the first, or for a file written a part at a time the last, which holds nothing
    else); the other messages are not read, so damage to them is not seen (``read`` checks them against the
    layout's crc32). A bag that cannot be read so (damaged, unindexed, no metadata there, an unsafe message
    definition) is read by ``read``: the same ValueError('<path>: <what is wrong>')."""
    if stream is not None:
        stream.close()  # the bag is opened by its path (bag_open checks it again)
    try:
        return _indexed_metadata(path)
    except ValueError:
        metadata, records = read(path)
        return metadata, dict(collections.Counter(record.topic for record in records))


def _indexed_metadata(path):
    """``read_metadata`` from the index and the chunks holding the metadata; ValueError when it cannot be."""
    from cc_log.storage.bag import bag_open, bag_reader
    bag = bag_open.open_bag(path, skip_index=True)
    try:
        topics = {connection.id: connection.topic for connection in bag._connections.values()}
        counts = collections.Counter()
        for info in bag._chunks:
            for connection, count in info.connection_counts.items():
                counts[topics.get(connection)] += count
    finally:
        bag.close()
    metadata = None
    if counts.pop(METADATA_TOPIC, 0):
        for run in bag_reader.read_runs(path, [METADATA_TOPIC]):
            for record in run:
                metadata = _chosen(metadata, _metadata(_string_data(record.raw)))
    if not isinstance(metadata, dict) or not isinstance(metadata.get('bag'), dict):
        raise ValueError('no metadata')
    del metadata['bag']
    return metadata, dict(counts)


def _chosen(metadata, found):
    """The metadata of a window after a metadata message ``found``: a stream's final metadata (with its layout)
    after its provisional one, else the first."""
    if metadata is None or (isinstance(found, dict) and 'bag' in found):
        return found
    return metadata


def _string_data(data):
    """The text of a serialized std_msgs/String (its length, then UTF-8); _BadMetadata when it is not one."""
    if len(data) < 4 or struct.unpack_from('<I', data)[0] != len(data) - 4:
        raise _BadMetadata('not a std_msgs/String')
    return bytes(data[4:])


def _deserialized(cls, data):
    msg = cls()
    msg.deserialize(data)
    return msg


class _BadMetadata(ValueError):
    pass


def _metadata(text):
    try:
        return safe_input.json_loads(text)
    except ValueError as error:
        raise _BadMetadata(error)


def _restore(read_records, layout):
    rank = {topic: number for number, topic in enumerate(layout['topics'])}
    timed = sorted(read_records, key=lambda item: (item[0], rank.get(item[1].topic, len(rank))))
    records = [record for _, record in timed]
    order = layout.get('order')
    if order is not None:
        if sorted(order) != list(range(len(records))):
            raise ValueError('order is not a permutation of the records')
        records = [records[place] for place in order]
    stamps = layout.get('stamps')
    if stamps is not None:
        if len(stamps) != len(records):
            raise ValueError('%d stamps for %d records' % (len(stamps), len(records)))
        records = [record._replace(stamp=msg_codec.decode_float(stamp)) for stamp, record in zip(stamps, records)]
    return records


def to_bag(records, out, compression='lz4', progress=None, names=None):
    """The records as one rosbag ``out`` (replaced), each at its stamp, as rosbag writes them
    (``bag.bag_writer``; chunks lz4, bz2 or none): a record read with its serialized bytes and connection
    header (from a bag-lz4 window) keeps them, the publisher's ``callerid`` and ``latching`` too, so ``rosbag
    play`` latches what was latched. ``progress()`` after each record; ``[out]``. ValueError when a topic
    holds messages of two types (a bag has one connection per topic). ``names``: the paths to try in order
    instead of replacing ``out`` (the first free one is taken, nothing is overwritten)."""
    headers = connection_headers(records)

    def messages():
        for record in records:
            yield bag_message(record)
            if progress:
                progress()

    target = safe_files.AtomicFile(out, names=names, overwrite=names is None)
    with target as stream:
        bag_writer.write_bag(stream, messages(), headers, compression=compression)
    return [target.path]
