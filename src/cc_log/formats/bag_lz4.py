"""The ``bag-lz4`` window file: one LZ4-compressed rosbag (format 2.0) per window.

``rosbag info``, ``rosbag play`` and rqt_bag open it. Records are written on their own topics with their
stamp as the bag time; a record held as serialized bytes is written as they are, with its original
connection header (``callerid``, ``latching``, the publisher's definition), without decoding it. The
window metadata is a JSON object in one ``std_msgs/String`` message on
``/cc_log/metadata``, written first at the time of the first record (``rostopic echo -b FILE
/cc_log/metadata`` shows it; ``rosbag play FILE --topics ...`` can leave it out). The JSON also holds a
``"bag"`` object that ``read`` uses and removes:

- ``topics``: the record topics in order of first appearance (ties in bag time are read in this order);
- ``order``: only when the records were not in (bag time, topic) order: the index in bag read order of
  each record, in window order;
- ``stamps``: only when some record stamp (float seconds) does not survive the trip through bag time
  (secs, nsecs): every record's stamp, in window order.

Edge module: rosbag is imported inside the functions only, so importing cc_log.bag_lz4 costs nothing.
"""
import functools
import json
import math
import os

from .. import msg_codec, raw_message, safe_files, safe_input
from ..window_buffer import Record

CODEC = 'bag-lz4'
RAW_RECORDS = True  # write_window hands records over as they are: serialized bytes are written as bytes
EXTENSION = '.bag'
LAYOUT_VERSION = 1
MAGIC = b'#ROSBAG V2.0\n'
METADATA_TOPIC = '/cc_log/metadata'
_STRING_DEFINITION = 'string data\n'


def bag_time(stamp):
    """Float seconds -> a genpy.Time (``BagTime``), nanoseconds rounded to nearest; ValueError for negative or
    not finite."""
    stamp = float(stamp)
    if not math.isfinite(stamp) or stamp < 0:
        raise ValueError('stamp %r cannot be a bag time (must be finite and >= 0)' % stamp)
    secs = int(math.floor(stamp))
    nsecs = int(round((stamp - secs) * 1e9))
    if nsecs >= 1000000000:
        secs, nsecs = secs + 1, nsecs - 1000000000
    return _bag_time_class()(secs, nsecs)


@functools.lru_cache(maxsize=None)
def _bag_time_class():
    """``BagTime``: a genpy.Time that compares as the tuple (secs, nsecs). rosbag's writer keeps each
    connection's index sorted by inserting every message's time with a binary search, and genpy's comparisons
    go through three Python calls each (a fifth of the writer's CPU on Husky windows); the bag written is the
    same, byte for byte."""
    import genpy

    class BagTime(genpy.Time):
        __slots__ = ()
        __hash__ = genpy.Time.__hash__

        def __eq__(self, other):
            return isinstance(other, genpy.Time) and (self.secs, self.nsecs) == (other.secs, other.nsecs)

        def __lt__(self, other):
            return (self.secs, self.nsecs) < (other.secs, other.nsecs)

        def __le__(self, other):
            return (self.secs, self.nsecs) <= (other.secs, other.nsecs)

        def __gt__(self, other):
            return (self.secs, self.nsecs) > (other.secs, other.nsecs)

        def __ge__(self, other):
            return (self.secs, self.nsecs) >= (other.secs, other.nsecs)

    return BagTime


def write(target, records, metadata):
    """Write ``records`` (window order) and ``metadata`` (a JSON-able dict) as an LZ4 bag into ``target``: a
    binary file object open for writing (rosbag closes it when done), or the path of a new file (created
    with ``safe_files.create``: never over a file, never through a link)."""
    import rosbag
    if isinstance(target, (str, bytes, os.PathLike)):
        with os.fdopen(safe_files.create(target), 'w+b') as stream:
            return write(stream, records, metadata)
    if not records:
        raise ValueError('window: has no records')
    topics = list(dict.fromkeys(record.topic for record in records))
    if METADATA_TOPIC in topics:
        raise ValueError('topic %s: reserved for the window metadata' % METADATA_TOPIC)
    times = [bag_time(record.stamp) for record in records]
    rank = {topic: number for number, topic in enumerate(topics)}
    read_order = sorted(range(len(records)), key=lambda i: (times[i], rank[records[i].topic]))
    layout = {'topics': topics}
    if read_order != list(range(len(records))):
        position = {index: place for place, index in enumerate(read_order)}
        layout['order'] = [position[i] for i in range(len(records))]
    if any(time.to_sec() != record.stamp for time, record in zip(times, records)):
        layout['stamps'] = [msg_codec.encode_float(float(record.stamp)) for record in records]
    meta = dict(metadata or {})
    meta.setdefault('codec', CODEC)
    meta['layout'] = LAYOUT_VERSION
    meta['bag'] = layout
    string_class = msg_codec.message_class('std_msgs/String', _STRING_DEFINITION)
    text = json.dumps(meta, allow_nan=False, separators=(',', ':'))
    bag = rosbag.Bag(target, 'w', compression=rosbag.Compression.LZ4)
    bag.write(METADATA_TOPIC, string_class(data=text), min(times))
    for record, time in zip(records, times):
        write_record(bag, record, time)
    bag.close()  # on an error the owner of ``target`` closes it (a failed rosbag close would leave it open)


def write_record(bag, record, time):
    """Write one Record into an open rosbag at ``time``: its serialized bytes with the publisher's connection
    header when it has them (latching and callerid kept), else the decoded message."""
    if record.raw is not None and record.connection:
        header = dict(record.connection, topic=record.topic)
        bag.write(record.topic, (header['type'], record.raw, header['md5sum'],
                                 raw_message.message_class(record.connection)), time, raw=True,
                  connection_header=header)
    else:
        bag.write(record.topic, record.msg, time)


def encoder(records, metadata):
    """A function that writes the window into a stream (rosbag encodes while it writes)."""
    return lambda stream: write(stream, records, metadata)


def salvage(path):
    """What a bag cut off mid-write still holds (``bag_salvage.Salvaged``); ValueError when it is no rosbag."""
    from . import bag_salvage
    return bag_salvage.salvage(path)


def read(path, stream=None):
    """``(metadata, records)`` of a bag-lz4 window file (``stream``: that file, already open);
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
    read_records = []
    with stream:
        try:
            bag = rosbag.Bag(stream)
        except Exception as error:  # rosbag raises ROSBag*Exception, struct.error, lz4 errors, ...
            raise ValueError('%s: corrupt or truncated bag (%s: %s)' % (path, type(error).__name__, error))
        with bag:
            safe_input.check_bag(bag, path)
            try:
                for topic, msg, time in bag.read_messages():
                    if topic == METADATA_TOPIC:
                        if metadata is None:
                            metadata = _metadata(msg.data)
                        continue
                    read_records.append((time, Record(time.to_sec(), topic, msg)))
            except _BadMetadata as error:
                raise ValueError('%s: bad metadata JSON on %s (%s)' % (path, METADATA_TOPIC, error))
            except Exception as error:
                raise ValueError('%s: corrupt or truncated bag (%s: %s)' % (path, type(error).__name__, error))
    if not isinstance(metadata, dict) or not isinstance(metadata.get('bag'), dict):
        raise ValueError('%s: not a cc_log window (no metadata on %s)' % (path, METADATA_TOPIC))
    layout = metadata.pop('bag')
    try:
        records = _restore(read_records, layout)
    except (ValueError, TypeError, KeyError, IndexError) as error:
        raise ValueError('%s: metadata does not fit the records (%s)' % (path, error))
    return metadata, records


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
        records = [Record(msg_codec.decode_float(stamp), record.topic, record.msg)
                   for stamp, record in zip(stamps, records)]
    return records
