"""Serialized messages: what rospy (``rospy.AnyMsg``) and rosbag (``read_messages(raw=True)``) hand over.

A ``window_buffer.Record`` may carry a message as its serialized bytes (``raw``) and its connection header
(``connection``: a dict with ``type``, ``md5sum``, ``message_definition`` and, live, ``callerid`` and
``latching``) with ``msg`` None: the message is decoded only when something reads its fields
(``decoded(record)``). ``message_class(connection)`` is the class decoding uses: the installed class of
the type when its md5sum matches, else one built from the connection's definition, which must pass
``safe_input.check_definition`` first (genpy runs the code it generates); a refused definition is a
ValueError naming the type. ``stamp(raw, connection, fallback)`` reads the header stamp straight from the
bytes of a type whose first field is a ``std_msgs/Header``.

Pure: roslib and genpy, no rospy.
"""
import functools
import struct

import genpy

from . import msg_codec
from . import safe_input

HEADER_TYPES = frozenset(['Header', 'std_msgs/Header', 'roslib/Header'])
_STAMP = struct.Struct('<II')  # secs, nsecs after the header's seq
_HEADER_STAMP = functools.partial(_STAMP.unpack_from, offset=4)
DECODE_ERRORS = (genpy.DeserializationError, ValueError, TypeError, struct.error, IndexError, KeyError)


class UndecodableRecord(ValueError):
    """A record of a batch that a trigger must read but cannot be decoded: ``index`` (its place in the batch;
    the records before it were taken), ``topic``, ``error`` (the decoding error)."""

    def __init__(self, index, topic, error):
        super(UndecodableRecord, self).__init__('%s: a message cannot be decoded (%s)' % (topic, error))
        self.index, self.topic, self.error = index, topic, error


_CLASSES = {}      # (type, md5sum, definition) -> class
_HAS_HEADER = {}   # (type, definition) -> bool


def type_of(record):
    """The message type of a record (``msg._type``, else the connection's ``type``)."""
    if record.msg is not None:
        return record.msg._type
    return record.connection['type']


def message_class(connection):
    """The class that decodes messages of ``connection`` (see the module docstring); cached. ValueError
    when the type name is malformed or the definition is refused."""
    msg_type = connection.get('type', '')
    md5sum = connection.get('md5sum', '')
    definition = connection.get('message_definition', '')
    key = (msg_type, md5sum, definition)
    cls = _CLASSES.get(key)
    if cls is None:
        safe_input.check_type_name(msg_type)  # before anything imports <package>.msg
        import roslib.message
        try:
            cls = roslib.message.get_message_class(msg_type)
        except Exception:  # a package that cannot be imported: build the class from the definition
            cls = None
        if cls is None or (md5sum not in ('', '*') and cls._md5sum != md5sum):
            cls = msg_codec.message_class(msg_type, definition)
        _CLASSES[key] = cls
    return cls


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


def _seconds(stamp):
    """Float seconds of a float or anything with ``to_sec``."""
    return stamp.to_sec() if hasattr(stamp, 'to_sec') else float(stamp)


def is_latched(connection):
    """Whether the publisher latches (connection header ``latching: '1'``)."""
    return connection is not None and connection.get('latching') == '1'
