"""ROS messages as plain data: nested dicts (rows), flat columns, and back.

Pure: only genpy (the message runtime) is used, never rospy or rosbag, so the core and offline tools can
read window files on any machine. A message is decoded from its type name and its full message
definition (``msg._full_text``), which every window file carries; no installed message package is needed.

Encoding rules (the same in every cc_log file):

- field names are the message's own (``pose.pose.position.x``), in definition order;
- ``time`` and ``duration`` are ``{"secs": int, "nsecs": int}`` (lossless);
- ``uint8[]``, ``uint8[N]``, ``char[]`` and ``char[N]`` (bytes in Python 3) are base64 strings
  (standard alphabet, with padding): 4 characters per 3 bytes instead of up to 4 per byte as a list;
- float fields that are not finite become the strings ``"NaN"``, ``"Infinity"``, ``"-Infinity"``
  (JSON has no such numbers); they are turned back into floats by the field's type when decoding;
- finite floats are written by ``json`` with Python's ``repr``, which round-trips exactly; with
  ``short_float32=True`` (the json-xz columns) a ``float32`` field holding a float32 value is written as
  the shortest decimal that gives the same float32 (``0.19016418`` instead of ``0.19016417860984802``);
- decoding rounds ``float32`` fields to float32, the value they have on the wire (so a float32 field
  reads back exactly as it was received, and serializes to the same bytes in every case);
- other numeric arrays are lists, message arrays are lists of dicts.
"""
import base64
import functools
import json
import math
import operator
import re
import struct
import threading

import genpy
import genpy.dynamic

from cc_log.base import safe_input

__all__ = ['to_dict', 'from_dict', 'generated_class', 'message_classes', 'row_json', 'row_json_bytes',
           'field_types', 'encode_float', 'decode_float', 'compact_definition', 'to_float32', 'short_float32',
           'NON_FINITE']

FLOAT_TYPES = frozenset(['float32', 'float64'])
INT_TYPES = frozenset(['int8', 'uint8', 'int16', 'uint16', 'int32', 'uint32', 'int64', 'uint64',
                       'byte', 'char'])
BYTES_TYPES = frozenset(['uint8', 'char'])  # arrays of these are bytes in Python 3
TIME_TYPES = frozenset(['time', 'duration'])
PRIMITIVE_TYPES = FLOAT_TYPES | INT_TYPES | TIME_TYPES | frozenset(['bool', 'string'])

NON_FINITE = {'NaN': float('nan'), 'Infinity': float('inf'), '-Infinity': float('-inf')}
_INF = float('inf')


def encode_float(value):
    """A float as JSON data: itself when finite, else ``'NaN'``, ``'Infinity'`` or ``'-Infinity'``."""
    if math.isfinite(value):
        return value
    if math.isnan(value):
        return 'NaN'
    return 'Infinity' if value > 0 else '-Infinity'


_FLOAT32 = struct.Struct('<f')


def to_float32(value):
    """``value`` rounded to the nearest float32 (as a Python float); values beyond float32 unchanged."""
    try:
        return _FLOAT32.unpack(_FLOAT32.pack(value))[0]
    except (OverflowError, struct.error):
        return value


def short_float32(value):
    """The shortest float that is the same float32 as ``value`` when ``value`` is a finite float32;
    else ``value`` itself (then it is written in full)."""
    if value != value or value in (_INF, -_INF) or to_float32(value) != value:
        return value
    for digits in (6, 7, 8):
        short = float('%.*g' % (digits, value))
        if to_float32(short) == value:
            return short
    return value  # 9 digits: repr of the double is as short as it gets


def decode_float(value):
    """The inverse of ``encode_float``; ints are turned into floats."""
    if isinstance(value, str):
        try:
            return NON_FINITE[value]
        except KeyError:
            raise ValueError('%r is not a number' % (value,))
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError('%r is not a number' % (value,))
    return float(value)


@functools.lru_cache(maxsize=None)
def split_type(slot_type):
    """``'float64[36]'`` -> ``('float64', True, 36)``; ``'string'`` -> ``('string', False, None)``."""
    if slot_type.endswith(']'):
        base, _, size = slot_type[:-1].partition('[')
        return base, True, (int(size) if size else None)
    return slot_type, False, None


def _resolve(base, parent_type):
    """Full name of a message type as written in a field of ``parent_type``."""
    if base in PRIMITIVE_TYPES or '/' in base:
        return base
    if base == 'Header':
        return 'std_msgs/Header'
    return parent_type.split('/')[0] + '/' + base


# -- message -> data ------------------------------------------------------------------------------------

def encode_value(value, slot_type, short):
    """One field's value as ``to_dict`` writes it (``short``: short_float32)."""
    base, is_array, _ = split_type(slot_type)
    if is_array:
        if base in BYTES_TYPES:
            if not isinstance(value, (bytes, bytearray)):
                value = bytes(bytearray(value))
            return base64.b64encode(bytes(value)).decode('ascii')
        if base in FLOAT_TYPES:
            if short and base == 'float32':
                return [encode_float(short_float32(float(item))) for item in value]
            return [encode_float(float(item)) for item in value]
        if base in TIME_TYPES:
            return [{'secs': int(item.secs), 'nsecs': int(item.nsecs)} for item in value]
        if base in PRIMITIVE_TYPES:
            return list(value)
        return [to_dict(item, short) for item in value]
    if base in FLOAT_TYPES:
        if short and base == 'float32':
            return encode_float(short_float32(float(value)))
        return encode_float(float(value))
    if base in TIME_TYPES:
        return {'secs': int(value.secs), 'nsecs': int(value.nsecs)}
    if base in PRIMITIVE_TYPES:
        return value
    return to_dict(value, short)


def to_dict(msg, short_float32=False):
    """A ROS message as a nested dict (the row form), fields in definition order.

    ``short_float32``: write float32 fields as the shortest decimal of their float32 value (json-xz).
    """
    return {name: encode_value(getattr(msg, name), slot_type, short_float32)
            for name, slot_type in zip(msg.__slots__, msg._slot_types)}


def row_json(msg):
    """The message as one line of the plain row-per-message JSON log (no newline)."""
    return json.dumps(to_dict(msg))


def row_json_bytes(msg):
    """Bytes the message takes in the plain row-per-message JSON log: ``json.dumps`` of the row plus the
    newline. This is the "raw" size every compression figure of cc_log is relative to.

    Counted without building the text (``len(row_json(msg)) + 1`` exactly, several times faster): the
    smart logger counts every message it sees.
    """
    return _message_size(msg) + 1


# -- row JSON size without the text ----------------------------------------------------------------------
# json.dumps writes ', ' and ': ' separators, ASCII only, finite floats as repr(); a list of finite floats
# or of ints has the same length as its Python repr. Anything else falls back to json.dumps of the value.

_SIZERS = {}


def _message_size(msg):
    sizer = _SIZERS.get(type(msg))
    if sizer is None:
        fields = [(name, len(name) + 4, _field_size(slot_type))
                  for name, slot_type in zip(msg.__slots__, msg._slot_types)]
        overhead = 2 * len(fields) if fields else 2  # braces plus ', ' between fields

        def sizer(value, fields=fields, overhead=overhead):
            return overhead + sum(key + size(getattr(value, name)) for name, key, size in fields)
        _SIZERS[type(msg)] = sizer
    return sizer(msg)


def _list_size(sizes):
    return 2 * len(sizes) + sum(sizes) if sizes else 2


def _float_size(value):
    text = repr(float(value))
    return len(text) if 'n' not in text else len(json.dumps(encode_float(float(value))))


def _floats_size(values):
    text = repr(list(map(float, values)))
    return len(text) if 'n' not in text else len(json.dumps([encode_float(float(item)) for item in values]))


def _time_size(value):
    return 21 + len(str(int(value.secs))) + len(str(int(value.nsecs)))


def _json_size(value):
    return len(str(value)) if type(value) is int else len(json.dumps(value))


def _field_size(slot_type):
    base, is_array, _ = split_type(slot_type)
    if not is_array:
        if base in FLOAT_TYPES:
            return _float_size
        if base in TIME_TYPES:
            return _time_size
        if base in PRIMITIVE_TYPES:
            return _json_size
        return _message_size
    if base in BYTES_TYPES:
        return lambda value: 2 + 4 * ((len(value) + 2) // 3)  # base64 in quotes
    if base in FLOAT_TYPES:
        return _floats_size
    if base in TIME_TYPES:
        return lambda values: _list_size([_time_size(item) for item in values])
    if base in INT_TYPES or base == 'bool':
        return lambda values: len(repr(list(values))) if values else 2
    if base in PRIMITIVE_TYPES:
        return lambda values: len(json.dumps(list(values)))
    return lambda values: _list_size([_message_size(item) for item in values])


# -- row JSON bytes of a stream of messages, memoised ---------------------------------------------
# ``row_json_bytes(msg)`` is the definition. On a stream, most of its cost is repr() of the floats of fixed-size
# float arrays (covariances), which hardly ever change between messages. ``RowJsonCounter`` computes the same
# number from a per-type plan: constant JSON overhead (names, braces, separators), scalar floats and ints in one
# repr() each, fixed-size float arrays memoised by their exact bytes (struct, so -0.0 != 0.0), times and strings
# as row_json_bytes sizes them. A type with a field it does not plan for, and any message holding a non-finite
# float or an unexpected value type, is counted by ``row_json_bytes`` itself.
# test_smart_logger_cost checks it equals row_json_bytes on every message of the real bags.

_MEMO_LIMIT = 4096  # distinct array values / strings remembered per logger before the memo starts over


class _Unplanned(Exception):
    """The message type has a field kind the plan does not cover: use row_json_bytes."""


class RowJsonCounter(object):
    """``count(msg) == row_json_bytes(msg)`` (exact), cheaper on repeated covariances: for a stream of
    messages (the smart logger counts every one). Not thread-safe (its memo)."""

    def __init__(self):
        self._plans = {}
        self._arrays = {}
        self._strings = {}

    def count(self, msg):
        plan = self._plans.get(type(msg), False)
        if plan is False:
            plan = self._plans[type(msg)] = self._make_plan(msg)
        if plan is None:
            return row_json_bytes(msg)
        try:
            size = self._size(plan, msg)
        except (TypeError, ValueError, AttributeError, OverflowError, struct.error):
            size = None
        return row_json_bytes(msg) if size is None else size

    def _make_plan(self, msg):
        floats, ints, times, strings, arrays, blobs = [], [], [], [], [], []
        try:
            constant = self._walk(type(msg), '', floats, ints, times, strings, arrays, blobs)
        except _Unplanned:
            return None
        getter = operator.attrgetter
        return (constant + 1,  # + the newline
                getter(*floats) if floats else None, len(floats),
                getter(*ints) if ints else None, len(ints),
                [getter(path) for path in times],
                [getter(path) for path in strings],
                [(getter(path), struct.Struct('<%dd' % length)) for path, length in arrays],
                [getter(path) for path in blobs])

    def _walk(self, cls, prefix, floats, ints, times, strings, arrays, blobs):
        """Add the leaves of message class ``cls`` to the lists; return its constant JSON overhead."""
        slots = list(getattr(cls, '__slots__', ()))
        types = list(getattr(cls, '_slot_types', ()))
        if len(slots) != len(types):
            raise _Unplanned()
        constant = 2 * len(slots) if slots else 2
        for name, slot_type in zip(slots, types):
            constant += len(name) + 4
            path = prefix + name
            base, is_array, length = split_type(slot_type)
            if is_array:
                if base in BYTES_TYPES:
                    blobs.append(path)
                elif base in FLOAT_TYPES and length:
                    arrays.append((path, length))
                else:
                    raise _Unplanned()
            elif base in FLOAT_TYPES:
                floats.append(path)
            elif base in TIME_TYPES:
                times.append(path)
            elif base == 'string':
                strings.append(path)
            elif base in INT_TYPES or base == 'bool':
                ints.append(path)
            elif base in PRIMITIVE_TYPES:
                raise _Unplanned()
            else:
                sub = _slot_class(cls, name)
                if sub is None:
                    raise _Unplanned()
                constant += self._walk(sub, path + '.', floats, ints, times, strings, arrays, blobs)
        return constant

    def _size(self, plan, msg):
        constant, floats, nfloats, ints, nints, times, strings, arrays, blobs = plan
        size = constant
        if floats is not None:
            values = floats(msg)
            if nfloats == 1:
                values = (values,)
            text = repr(list(map(float, values)))
            if 'n' in text:  # nan, inf: msg_codec writes them as strings
                return None
            size += len(text) - 2 * nfloats
        if ints is not None:
            values = ints(msg)
            if nints == 1:
                values = (values,)
            for value in values:
                if type(value) is not int and type(value) is not bool:
                    return None
            size += len(repr(list(values))) - 2 * nints  # 'True'/'False' are as long as 'true'/'false'
        for getter in times:
            value = getter(msg)
            size += 21 + len(str(int(value.secs))) + len(str(int(value.nsecs)))
        memo = self._strings
        for getter in strings:
            value = getter(msg)
            known = memo.get(value)
            if known is None:
                if type(value) is not str:
                    return None
                if len(memo) >= _MEMO_LIMIT:
                    memo.clear()
                known = memo[value] = len(json.dumps(value))
            size += known
        memo = self._arrays
        for getter, packer in arrays:
            value = getter(msg)
            key = packer.pack(*value)
            known = memo.get(key)
            if known is None:
                text = repr(list(map(float, value)))
                if 'n' in text:
                    return None
                if len(memo) >= _MEMO_LIMIT:
                    memo.clear()
                known = memo[key] = len(text)
            size += known
        for getter in blobs:
            size += 2 + 4 * ((len(getter(msg)) + 2) // 3)
        return size


def _slot_class(cls, name):
    """The message class of the nested field ``name`` of ``cls`` (from a default instance), or None."""
    try:
        value = getattr(cls(), name)
    except Exception:
        return None
    if not hasattr(value, '__slots__') or not hasattr(value, '_slot_types'):
        return None
    return type(value)


# -- message classes from definitions --------------------------------------------------------------------

_CLASSES = {}
_CLASSES_LOCK = threading.Lock()  # the background writer and the main thread may both build classes


def message_classes(msg_type, definition):
    """All classes (by full type name) generated from ``definition`` of ``msg_type``; cached. The definition
    is checked first (``safe_input.check_definition``): ValueError('message definition of ...: ...')."""
    if type(msg_type) is not str or type(definition) is not str:  # from JSON: maybe a list, never a key
        safe_input.check_definition(msg_type, definition)
    key = (msg_type, definition)
    classes = _CLASSES.get(key)
    if classes is None:
        with _CLASSES_LOCK:
            classes = _CLASSES.get(key)
            if classes is None:
                safe_input.check_definition(msg_type, definition)  # genpy runs what it generates
                try:
                    classes = genpy.dynamic.generate_dynamic(msg_type, definition)
                except Exception as error:  # genpy raises several kinds for a bad definition
                    raise ValueError('%s: cannot build the message class from its definition: %s'
                                     % (msg_type, error))
                if msg_type not in classes:
                    raise ValueError('%s: the definition does not define this type' % msg_type)
                _CLASSES[key] = classes
    return classes


def generated_class(msg_type, definition):
    """The message class of ``msg_type`` generated from its full definition text (cached), never the installed
    one: ``raw_message.message_class`` resolves which class decodes."""
    return message_classes(msg_type, definition)[msg_type]


_STRING_CONSTANT = re.compile(r'^string\s+\w+\s*=')
_SEPARATOR_LINE = '=' * 80


def compact_definition(text):
    """A full message definition without comments and blank lines.

    It defines the same types with the same md5sums (genpy ignores comments), at about a third of the size;
    ``string NAME=value`` constants are kept whole since their value may hold a ``#``.
    """
    lines = []
    for line in text.splitlines():
        line = line.strip()
        if not _STRING_CONSTANT.match(line):
            line = ' '.join(line.split('#', 1)[0].split())
        if line == _SEPARATOR_LINE and lines and lines[-1].startswith('MSG: '):
            lines.append('')  # a section with no field keeps its newline: genpy needs "MSG: pkg/Type\n"
        if line:
            lines.append(line)
    return '\n'.join(lines) + '\n'


# -- data -> message ------------------------------------------------------------------------------------

def _decode_value(data, slot_type, parent_type, classes, path):
    base, is_array, size = split_type(slot_type)
    base = _resolve(base, parent_type)
    try:
        if is_array:
            if base in BYTES_TYPES:
                if isinstance(data, str):
                    value = base64.b64decode(data.encode('ascii'), validate=True)
                else:
                    value = bytes(bytearray(data))
                items = value
            elif base == 'float32':
                items = value = tuple(to_float32(decode_float(item)) for item in data)
            elif base in FLOAT_TYPES:
                items = value = tuple(decode_float(item) for item in data)
            elif base in TIME_TYPES:
                cls = genpy.Time if base == 'time' else genpy.Duration
                items = value = [cls(item['secs'], item['nsecs']) for item in data]
            elif base == 'string' or base not in PRIMITIVE_TYPES:
                if base == 'string':
                    items = value = [str(item) for item in data]
                else:
                    items = value = [_from_dict(item, classes[base], classes, '%s[%d]' % (path, i))
                                     for i, item in enumerate(data)]
            else:
                items = value = tuple(data)
            if size is not None and len(items) != size:
                raise ValueError('has %d items, the type says %d' % (len(items), size))
            return value
        if base == 'float32':
            return to_float32(decode_float(data))
        if base in FLOAT_TYPES:
            return decode_float(data)
        if base in TIME_TYPES:
            cls = genpy.Time if base == 'time' else genpy.Duration
            return cls(int(data['secs']), int(data['nsecs']))
        if base == 'string':
            if not isinstance(data, str):
                raise ValueError('%r is not a string' % (data,))
            return data
        if base == 'bool':
            return data
        if base in INT_TYPES:
            if isinstance(data, bool) or not isinstance(data, int):
                raise ValueError('%r is not an integer' % (data,))
            return data
        return _from_dict(data, classes[base], classes, path)
    except ValueError as error:
        if str(error).startswith('field '):
            raise
        raise ValueError('field %s (%s): %s' % (path, slot_type, error))
    except (TypeError, KeyError, AttributeError, base64.binascii.Error) as error:
        raise ValueError('field %s (%s): %s: %s' % (path, slot_type, type(error).__name__, error))


def _from_dict(data, cls, classes, path=''):
    if not isinstance(data, dict):
        raise ValueError('field %s: expected an object, got %r' % (path or '(message)', type(data).__name__))
    values = {}
    for name, slot_type in zip(cls.__slots__, cls._slot_types):
        field_path = path + '.' + name if path else name
        if name not in data:
            raise ValueError('field %s: missing' % field_path)
        values[name] = _decode_value(data[name], slot_type, cls._type, classes, field_path)
    return cls(**values)


def from_dict(data, msg_type, definition):
    """Build a message of ``msg_type`` from its row dict and full message definition text.

    Raises ValueError naming the field when the data does not fit the definition.
    """
    classes = message_classes(msg_type, definition)
    return _from_dict(data, classes[msg_type], classes)


def field_types(msg_type, definition):
    """``{'header.seq': 'uint32', 'pose.covariance': 'float64[36]', ...}``: the leaves of the row form
    (primitives, primitive arrays, time/duration and message arrays), in definition order."""
    classes = message_classes(msg_type, definition)
    leaves = {}

    def walk(cls, prefix):
        for name, slot_type in zip(cls.__slots__, cls._slot_types):
            base, is_array, _ = split_type(slot_type)
            base = _resolve(base, cls._type)
            if is_array or base in PRIMITIVE_TYPES:
                leaves[prefix + name] = slot_type
            else:
                walk(classes[base], prefix + name + '.')
    walk(classes[msg_type], '')
    return leaves
