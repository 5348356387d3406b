"""Whether a message's serialized bytes are of its connection's type.

A buggy publisher, or a topic carrying two types in a replayed bag, can hand over bytes that are not one
message of the type its connection header names: a bag holding them cannot be read by rosbag (the message
decodes short, or leaves bytes over). Checked where a window file is written (the writer thread, never the
subscriber callback): the bytes must be exactly one message of the connection's class, nothing left over and
nothing missing. A type without strings or variable-length arrays is checked by its length alone; the others
by walking the lengths the bytes hold (strings, arrays), without decoding any value.

``PayloadCheck().split(records)`` -> ``(kept records, {topic: refused records})``: records held as decoded
messages are kept as they are (they are serialized from their class).
"""
import collections
import struct

from cc_log.base import msg_codec

__all__ = ['PayloadCheck', 'fits', 'with_dropped']

_SIZES = {'bool': 1, 'int8': 1, 'uint8': 1, 'byte': 1, 'char': 1, 'int16': 2, 'uint16': 2, 'int32': 4,
          'uint32': 4, 'float32': 4, 'int64': 8, 'uint64': 8, 'float64': 8, 'time': 8, 'duration': 8}
_U32 = struct.Struct('<I')
_FIXED, _STRING, _ARRAY = range(3)


class _Shape(object):
    """How the bytes of one message type are laid out: ``size`` (bytes, when fixed) and ``steps``."""
    __slots__ = ('size', 'steps')

    def __init__(self, steps):
        self.steps = []
        for step in steps:  # neighbouring fixed parts merged
            if step[0] == _FIXED and self.steps and self.steps[-1][0] == _FIXED:
                self.steps[-1] = (_FIXED, self.steps[-1][1] + step[1])
            else:
                self.steps.append(step)
        if not self.steps:
            self.size = 0
        elif len(self.steps) == 1 and self.steps[0][0] == _FIXED:
            self.size = self.steps[0][1]
        else:
            self.size = None

    def end(self, data, pos):
        """Where a message starting at ``pos`` of ``data`` ends (past ``len(data)`` when cut short)."""
        limit = len(data)
        for step in self.steps:
            kind = step[0]
            if kind == _FIXED:
                pos += step[1]
            elif kind == _STRING:
                if pos + 4 > limit:
                    return limit + 1
                pos += 4 + _U32.unpack_from(data, pos)[0]
            else:
                _, element, count = step
                if count is None:
                    if pos + 4 > limit:
                        return limit + 1
                    count = _U32.unpack_from(data, pos)[0]
                    pos += 4
                if element.size is not None:
                    pos += count * element.size
                else:  # each element takes at least 4 bytes: at most limit / 4 turns
                    for _ in range(count):
                        pos = element.end(data, pos)
                        if pos > limit:
                            return pos
            if pos > limit:
                return pos
        return pos


def _shape(msg_type, classes, shapes):
    """The ``_Shape`` of ``msg_type`` (its class in ``classes``: full type name -> genpy class)."""
    shape = shapes.get(msg_type)
    if shape is not None:
        return shape
    cls = classes[msg_type]
    steps = []
    for slot_type in cls._slot_types:
        base, is_array, count = msg_codec.split_type(slot_type)
        if base in _SIZES:
            element = _Shape([(_FIXED, _SIZES[base])])
        elif base == 'string':
            element = _Shape([(_STRING,)])
        else:
            element = _shape(_full_name(base, msg_type), classes, shapes)
        if not is_array:
            steps.extend(element.steps)
        elif count is not None and element.size is not None:
            steps.append((_FIXED, count * element.size))
        else:
            steps.append((_ARRAY, element, count))
    shape = shapes[msg_type] = _Shape(steps)
    return shape


def _full_name(base, parent_type):
    """The full name of a message type as a field of ``parent_type`` names it (as genmsg resolves it)."""
    if '/' in base:
        return base
    return 'std_msgs/Header' if base == 'Header' else parent_type.split('/')[0] + '/' + base


def connection_shape(connection):
    """The ``_Shape`` of the messages of ``connection`` (a header dict), or None when its definition does not
    build (nothing of it can be read)."""
    try:
        classes = msg_codec.message_classes(connection['type'], connection['message_definition'])
        return _shape(connection['type'], classes, {})
    except (KeyError, ValueError, TypeError):
        return None


def fits(data, shape):
    """Whether ``data`` is exactly one message of ``shape`` (``connection_shape``; None never fits)."""
    if shape is None:
        return False
    if shape.size is not None:
        return len(data) == shape.size
    return shape.end(data, 0) == len(data)


def with_dropped(metadata, counts):
    """``metadata`` (a dict, not changed) with ``counts`` ({topic: messages}) added to its ``dropped``: what a
    window does not hold of what it was handed (shed under overload, refused, undecodable), per topic."""
    meta = dict(metadata)
    if counts:
        meta['dropped'] = dropped = dict(meta.get('dropped') or {})
        for topic, count in counts.items():
            dropped[topic] = dropped.get(topic, 0) + count
    return meta


class PayloadCheck(object):
    """Records checked against their connections, each connection's shape found once (records of one
    connection share its header object)."""

    def __init__(self):
        self._shapes = {}  # id(connection) -> (connection, its shape): held, so that the id stays its own

    def refused(self, record):
        """Whether ``record`` holds serialized bytes that are not one message of its connection's type."""
        if record.msg is not None or record.raw is None or not record.connection:
            return False
        known = self._shapes.get(id(record.connection))
        if known is None or known[0] is not record.connection:
            known = self._shapes[id(record.connection)] = (record.connection, connection_shape(record.connection))
        return not fits(record.raw, known[1])

    def split(self, records):
        """``(kept records, collections.Counter(topic -> refused records))``, in their order."""
        refused = collections.Counter()
        kept = []
        for record in records:
            if self.refused(record):
                refused[record.topic] += 1
            else:
                kept.append(record)
        return kept, refused
