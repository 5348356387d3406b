"""Serialized messages: what rospy (``rospy.AnyMsg``) and rosbag (``read_messages(raw=True)``) hand over.

A ``records.Record`` may carry a message as its serialized bytes (``raw``) and its connection header
(``connection``: a dict with ``type``, ``md5sum``, ``message_definition`` and, live, ``callerid`` and
``latching``) with ``msg`` None: the message is decoded only when something reads its fields
(``decoded(record)``). ``message_class(connection)`` is the one place cc_log resolves a message class: the
installed class of the type when its md5sum matches, else one built from the connection's definition
(``msg_codec.generated_class``), which must pass ``safe_input.check_definition`` first (genpy runs the code it
generates); a refused definition is a ValueError naming the type; ``installed_class(type)`` is the installed
class alone (a configuration's types); ``serialized(msg)`` is the other way, a message's bytes. ``stamp(raw, connection,
fallback)`` reads the header stamp straight from the bytes of a type whose first field is a ``std_msgs/Header``;
``in_stamp_order(items)`` puts messages read at one time from several connections in the order of those stamps.

``layout(cls)`` and ``blocks(fields, raws)`` find where each field lies in the bytes of many messages at
once (numpy views instead of a genpy decode per message: the json-xz writer).

Pure: roslib, genpy and numpy, no rospy.
"""
import collections
import functools
import heapq
import io
import struct

import genpy
import numpy

from cc_log.base import msg_codec, safe_input

HEADER_TYPES = frozenset(['Header', 'std_msgs/Header', 'roslib/Header'])
_STAMP = struct.Struct('<II')  # secs, nsecs after the header's seq
_HEADER_STAMP = functools.partial(_STAMP.unpack_from, offset=4)
DECODE_ERRORS = (genpy.DeserializationError, ValueError, TypeError, struct.error, IndexError, KeyError)


_CLASSES = {}      # (type, md5sum, definition or None) -> class (None: not installed, no definition given)
_HAS_HEADER = {}   # (type, definition) -> bool


def type_of(record):
    """The message type of a record (``msg._type``, else the connection's ``type``)."""
    if record.msg is not None:
        return record.msg._type
    return record.connection['type']


def message_class(connection):
    """The class that decodes messages of ``connection`` (a connection header: ``type``, ``md5sum`` ('' or
    '*': any), ``message_definition``; see the module docstring); cached. Without a ``message_definition``, the
    installed class or None. ValueError when the type name is malformed or the definition is refused."""
    msg_type = connection.get('type', '')
    md5sum = connection.get('md5sum', '')
    definition = connection.get('message_definition')
    key = (msg_type, md5sum, definition)
    if key in _CLASSES:
        return _CLASSES[key]
    safe_input.check_type_name(msg_type)  # before anything imports <package>.msg
    import roslib.message  # no rospy: only the installed message packages
    try:
        cls = roslib.message.get_message_class(msg_type)
    except Exception:  # a package that cannot be imported: build the class from the definition
        cls = None
    if definition is not None and (cls is None or (md5sum not in ('', '*') and cls._md5sum != md5sum)):
        cls = msg_codec.generated_class(msg_type, definition)
    _CLASSES[key] = cls
    return cls


def installed_class(msg_type):
    """The installed message class of ``msg_type`` (the name checked first), or None."""
    return message_class({'type': msg_type})


def serialized(msg):
    """The serialized bytes of a message object (what ``decode`` reads back)."""
    buff = io.BytesIO()
    msg.serialize(buff)
    return buff.getvalue()


def decode(raw, connection):
    """The message of ``raw`` bytes of ``connection`` (ValueError, genpy.DeserializationError, ...)."""
    msg = message_class(connection)()
    msg.deserialize(raw)
    return msg


def decoded(record):
    """``record`` with ``msg`` decoded from its bytes (itself when it has a message already)."""
    if record.msg is not None or record.raw is None:
        return record
    return record._replace(msg=decode(record.raw, record.connection))


def decoded_records(records):
    """``(records with messages, records that could not be decoded)`` of a list of records."""
    done, bad = [], 0
    for record in records:
        try:
            done.append(decoded(record))
        except DECODE_ERRORS:
            bad += 1
    return done, bad


def has_header(connection):
    """Whether messages of ``connection`` start with a std_msgs/Header (the first field of its definition)."""
    msg_type = connection.get('type', '')
    definition = connection.get('message_definition', '')
    key = (msg_type, definition)
    known = _HAS_HEADER.get(key)
    if known is None:
        known = False
        for line in definition.splitlines():
            line = line.split('#', 1)[0].strip()
            if not line:
                continue
            parts = line.split()
            known = len(parts) == 2 and '=' not in line and parts[0] in HEADER_TYPES
            break
        _HAS_HEADER[key] = known
    return known


def stamp(raw, connection, fallback):
    """The header stamp (float s) of ``raw`` when its type has a header and the stamp is not zero, else
    ``fallback`` (float s, or anything with ``to_sec``)."""
    if has_header(connection) and len(raw) >= 12:
        secs, nsecs = _STAMP.unpack_from(raw, 4)
        if secs or nsecs:
            return secs + nsecs * 1e-9
    return _seconds(fallback)


def stamps(raws, connections, fallbacks):
    """``stamp`` of each of ``raws`` (with its connection and fallback), the header's bytes read in bulk."""
    distinct = dict(zip(map(id, connections), connections)).values()
    headers = [has_header(connection) for connection in distinct]
    if all(headers):
        try:
            return [secs + nsecs * 1e-9 if secs or nsecs else _seconds(fallback)
                    for (secs, nsecs), fallback in zip(map(_HEADER_STAMP, raws), fallbacks)]
        except struct.error:  # a message shorter than a header: its fallback
            pass
    elif not any(headers):
        return list(map(_seconds, fallbacks))
    return list(map(stamp, raws, connections, fallbacks))


def in_stamp_order(items):
    """Serialized messages ``(topic, data, connection)`` read at one time from several connections (each topic's
    in the order it was sent), merged in the order of their header stamps: the order they were published in, which
    one read over several sockets loses. Each topic keeps its own order (a message without a header stamp follows
    the one before it); the items themselves when they are of one topic."""
    if len(items) < 2 or all(item[0] == items[0][0] for item in items):
        return items
    runs = collections.defaultdict(list)  # topic -> (stamp, place) of its items, in order
    for place, (topic, data, connection) in enumerate(items):
        run = runs[topic]
        run.append((stamp(data, connection, run[-1][0] if run else 0.0), place))
    return [items[place] for _, place in heapq.merge(*runs.values())]


def _seconds(stamp):
    """Float seconds of a float or anything with ``to_sec``."""
    return stamp.to_sec() if hasattr(stamp, 'to_sec') else float(stamp)


PUBLISHER_KEYS = ('callerid', 'latching')  # what a connection header says of its publisher


CONNECTION_KEYS = ('type', 'md5sum', 'message_definition')  # what a connection header says of the bytes


def header_problem(connection):
    """What is wrong with the connection header of serialized bytes, '' when nothing: a dict whose
    ``CONNECTION_KEYS`` are all text (rospy passes on a publisher's header without checking them)."""
    if not isinstance(connection, dict):
        return 'no connection header'
    missing = [key for key in CONNECTION_KEYS if not isinstance(connection.get(key), str)]
    return 'its connection header has no %s' % ', '.join(missing) if missing else ''


def class_header(topic, cls):
    """The connection header rosbag writes for messages of the genpy class ``cls`` on ``topic``."""
    return {'topic': topic, 'type': cls._type, 'md5sum': cls._md5sum, 'message_definition': cls._full_text}


def publisher_keys(connection):
    """The ``PUBLISHER_KEYS`` of a connection header (a dict; {} for None)."""
    return dict((key, connection[key]) for key in PUBLISHER_KEYS if key in (connection or {}))


def text_header(header):
    """A bag connection header (bytes values, as rosbag reads it) as a dict of str."""
    return {_text(key): _text(value) for key, value in header.items()}


def _text(value):
    return value.decode('utf-8', 'replace') if isinstance(value, bytes) else str(value)


def is_latched(connection):
    """Whether the publisher latches (connection header ``latching: '1'``)."""
    return connection is not None and connection.get('latching') == '1'


# -- fields read in bulk from the bytes -----------------------------------------------------------------

_DTYPES = {'float64': '<f8', 'float32': '<f4', 'int8': 'i1', 'byte': 'i1', 'uint8': 'u1', 'char': 'u1',
           'bool': 'u1', 'int16': '<i2', 'uint16': '<u2', 'int32': '<i4', 'uint32': '<u4', 'int64': '<i8',
           'uint64': '<u8'}
_TIME_DTYPES = {'time': '<u4', 'duration': '<i4'}
_NSECS_PER_SEC = 1000000000


class Field(collections.namedtuple('Field', 'key base dtype count')):
    """A leaf field of a message's bytes: dotted ``key`` (times split into ``.secs``/``.nsecs``), ``base``
    type (``nsecs`` for a time's nanoseconds, ``string``), numpy ``dtype`` and ``count`` (None: one value, else
    the length of a fixed-size array)."""

    @property
    def size(self):
        """Bytes of a numeric field (not of a string: its length is in the message)."""
        return numpy.dtype(self.dtype).itemsize * (self.count or 1)


_LAYOUTS = {}  # message class -> tuple of Fields in serialization order, or None


def layout(cls):
    """The leaf ``Field``s of ``cls`` in serialization order (numbers, times, fixed-size arrays of numbers,
    strings), or None when its bytes have anything else (a variable-length or message array, an empty
    message): then only genpy decodes it. Cached."""
    if cls not in _LAYOUTS:
        _LAYOUTS[cls] = _fields(cls(), '', [])
    return _LAYOUTS[cls]


def _fields(msg, prefix, out):
    for name, slot_type in zip(msg.__slots__, msg._slot_types):
        key = prefix + name
        base, is_array, count = msg_codec.split_type(slot_type)
        value = getattr(msg, name)
        if base in _TIME_DTYPES and not is_array:
            out += [Field(key + '.secs', base, _TIME_DTYPES[base], None), Field(key + '.nsecs', 'nsecs',
                                                                                _TIME_DTYPES[base], None)]
        elif base == 'string' and not is_array:
            out.append(Field(key, base, None, None))
        elif base in _DTYPES and (not is_array or count):
            out.append(Field(key, base, _DTYPES[base], count))
        elif not is_array and getattr(value, '__slots__', None):
            if _fields(value, key + '.', out) is None:
                return None
        else:
            return None
    return tuple(out)


class Block(collections.namedtuple('Block', 'rows table offsets')):
    """Messages of the same length whose fields lie at the same offsets: ``rows`` (their indices in the
    list given to ``blocks``), ``table`` (their bytes, a row each: uint8 array) and ``offsets`` (field key ->
    offset; a string's: of its first byte, its length beside: ``(offset, length)``)."""

    def column(self, field):
        """The values of a numeric ``field`` (an array: one row per message, a column per array element)."""
        dtype = numpy.dtype(field.dtype)
        return numpy.ndarray((len(self.rows), field.count or 1), dtype, self.table, self.offsets[field.key],
                             (self.table.shape[1], dtype.itemsize))

    def bytes_column(self, field):
        """The bytes of a string or byte-array ``field``: a uint8 array, one row per message."""
        offset, length = self.offsets[field.key] if field.base == 'string' else (self.offsets[field.key], field.count)
        return self.table[:, offset:offset + length]


def blocks(fields, raws):
    """``(Blocks, indices of the others)``: the messages of ``raws`` (serialized, of a class with the
    ``layout`` ``fields``) split into Blocks, bytes beyond the fields ignored as genpy does; the others
    (too short, a string longer than the message, a time's nanoseconds outside [0, 1e9): genpy would read
    them differently or not at all) are left to genpy."""
    by_size = {}
    for index, raw in enumerate(raws):
        by_size.setdefault(len(raw), []).append(index)
    done, rest = [], []
    for size, indices in by_size.items():
        rows = numpy.array(indices, dtype=numpy.intp)
        table = numpy.frombuffer(b''.join([raws[index] for index in indices]), numpy.uint8).reshape(len(rows), size)
        _place(fields, 0, rows, table, 0, {}, done, rest)
    return done, rest


def _place(fields, start, rows, table, offset, offsets, done, rest):
    size = table.shape[1]
    for number in range(start, len(fields)):
        field = fields[number]
        if field.base != 'string':
            offsets[field.key] = offset
            offset += field.size
            if offset > size:
                rest.extend(rows.tolist())
                return
            continue
        if offset + 4 > size:
            rest.extend(rows.tolist())
            return
        lengths = numpy.ascontiguousarray(table[:, offset:offset + 4]).view('<u4')[:, 0]
        for length in numpy.unique(lengths).tolist():
            chosen = lengths == length
            part = (rows, table) if chosen.all() else (rows[chosen], table[chosen])
            if offset + 4 + length > size:
                rest.extend(part[0].tolist())
                continue
            placed = dict(offsets)
            placed[field.key] = (offset + 4, length)
            _place(fields, number + 1, part[0], part[1], offset + 4 + length, placed, done, rest)
        return
    block = Block(rows, table, offsets)
    bad = numpy.zeros(len(rows), dtype=bool)
    for field in fields:
        if field.base == 'nsecs':
            nsecs = block.column(field)[:, 0]
            bad |= (nsecs < 0) | (nsecs >= _NSECS_PER_SEC)
    if bad.any():
        rest.extend(rows[bad].tolist())
        block = Block(rows[~bad], numpy.ascontiguousarray(table[~bad]), offsets)
    if len(block.rows):
        done.append(block)
