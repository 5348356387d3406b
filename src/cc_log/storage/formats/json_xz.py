"""The ``json-xz`` window file: one self-contained, xz-compressed JSON document per window.

``xz -dc FILE | jq .`` shows it; docs/FORMAT.md describes the layout and the measurements behind it.
The document (layout 2)::

    {"metadata": {... window metadata, "layout": 2 ...},
     "topics": [
       {"topic": "/odom", "type": "nav_msgs/Odometry", "md5sum": "...", "count": 300,
        "stamps": "header.stamp",             # or a list of float seconds, one per message
        "constant": {"header.frame_id": "odom", "pose.covariance": [...], ...},
        "columns": {"header.seq": [855, 1, ...], "pose.pose.position.x": [8.251562792367952, 0.02311227020083, ...],
                    "twist.twist.linear.x": [...], ...},
        "delta": ["header.seq", "pose.pose.position.x", ...],   # columns written as differences
        "connection": {"callerid": "/odometry_node", "latching": "0"},  # when the records came with one
        "definition": "<full message definition, comments left out>"}, ...],
     "order": [0, 1, 0, ...]}                  # only when records are not in (stamp, section) order

Each topic is one section in order of first appearance. A field (the message's own dotted names, times
split into ``.secs``/``.nsecs``) is either in ``constant`` (the same JSON value in every message of the
window, stated once) or in ``columns`` (one value per message, in message order). Arrays (covariance,
ranges) are one value: a column of lists. Values follow ``msg_codec`` (base64 bytes, non-finite floats as
strings; float32 fields as the shortest decimal of their float32 value). ``stamps`` is
``"header.stamp"`` when every record's stamp equals ``header.stamp.to_sec()``.

A column named in ``delta`` (layout 2) holds its first value, then each value's exact difference from the
one before: integers as integers, floats as the exact decimal difference of their shortest texts (a reader
adds them up in decimal and gets every float back bit for bit; ``jq`` adds them as doubles). The writer
delta-codes an integer column when that makes its text shorter, and a column of finite floats when the
differences need at most ``DELTA_GAIN`` of the significant digits and few values repeat an earlier,
non-adjacent one (LZMA finds those repeats in the plain column, not in its differences): ``differences``.
Layout 1 (no ``delta``) is still read.

``connection`` (optional) keeps what the publisher's connection header said of it (``callerid``, ``latching``)
when the records came with connection headers (live, ``cclog replay``): that of the topic's first record with
one. A record read back carries a connection header of its class with these keys, so ``cclog export --to bag``
writes a latched topic (``/tf_static``) latched again.

``precision`` (optional, lossy): ``{field pattern: step}`` rounds every float of a field matching the
pattern (``fnmatch`` on the dotted name, e.g. ``pose.pose.position.*``) to a multiple of its step before
writing; the map is kept in the metadata (``precision``), and a reader reads what was written.

Records held as serialized bytes (``raw_message``) are not decoded one by one: ``decoded_records`` (what
``log_format.write_window`` calls) keeps those of a fixed layout (``raw_message.layout``: numbers, times,
fixed-size arrays, strings; e.g. Odometry, Imu, Twist) as bytes, and ``document`` reads each field of a section
for all its messages at once (numpy views at the fields' offsets), writing the same text as from the decoded
messages. Other types, and messages genpy reads differently (not UTF-8, a time's nanoseconds beyond a second),
are decoded.

Pure: no rospy, no rosbag.
"""
import base64
import decimal
import fnmatch
import functools
import json
import lzma
import math
import operator
import os
import re

import numpy

from cc_log.core import msg_codec, raw_message, safe_input
from cc_log.core.records import Record

CODEC = 'json-xz'
EXTENSION = '.json.xz'
#: Memory the writer needs per estimated byte of a part (``WindowBuffer``'s part_factor): it decodes the kept
#: messages' fields and builds the JSON text (nav_msgs/Odometry: 0.7 KB serialized, 3.5 KB decoded).
PART_FACTOR = 8.0
LAYOUT_VERSION = 2
#: Layouts this module reads.
LAYOUTS = (1, 2)
MAGIC = b'\xfd7zXZ\x00'

#: LZMA2 preset used when writing. 6 is xz's default; on windows of a few hundred messages presets 6..9
#: and "extreme" give the same size within 1% (see docs/FORMAT.md), so the cheap one is used.
DEFAULT_PRESET = 6
#: LZMA2 options on top of the preset when writing (``compress``): a shorter match search than the preset's
#: (hash chains over 3-byte prefixes, ``nice_len`` 48, ``depth`` 8, instead of binary trees, 273 and automatic)
#: and ``lc=1, pb=0`` (text: one literal context bit, no position bits). ``bench/lzma_options.py`` on Husky
#: windows (docs/FORMAT.md, "Preset"): odometry as one window 3.97% of row JSON (preset 6 alone: 3.94%),
#: odometry + IMU within 0.3% of preset 6 alone's bytes at 28-74% of its CPU. Any xz decoder reads it.
FILTER_OPTIONS = {'mf': lzma.MF_HC3, 'nice_len': 48, 'depth': 8, 'lc': 1, 'pb': 0}

HEADER_STAMP = 'header.stamp'

#: A float column is delta-coded when its differences have at most this share of its values' significant
#: digits, and at most REPEATS_SHARE of its values repeat an earlier value that is not the one just before.
#: Measured on the Husky odometry (docs/FORMAT.md): positions (0.80 of the digits) compress 25% smaller,
#: angular velocity (0.87) 3.5%, linear velocity (0.84) 1% larger; orientations (0.53, but a third of their
#: values recur) 15% larger.
DELTA_GAIN = 0.87
REPEATS_SHARE = 0.1
#: Float columns longer than twice SAMPLE are first tried on their first SAMPLE values: beyond SAMPLE_GAIN of
#: the digits there, the column stays plain (the Husky positions: 0.88-0.91 on their first 50 values).
SAMPLE = 50
SAMPLE_GAIN = 0.97
#: Decimal arithmetic for differences: exact for any double's shortest text (at most 17 digits, exponents
#: -324..308) and any difference of two; a document needing more is refused (decimal.Inexact).
_EXACT = decimal.Context(prec=400, Emin=-999, Emax=999,
                         traps=[decimal.Inexact, decimal.Overflow, decimal.InvalidOperation])

#: Largest document (decompressed bytes) and file read. A window holds at most ``max_window`` (100,000)
#: driving messages: about 200 bytes each in the column layout (Husky odometry + IMU), at most ~2 kB when
#: every field changes, so 20-200 MB; 1 GiB is well above, and an xz bomb stops there.
MAX_DOCUMENT_BYTES = 1 << 30
#: Documents up to this size are decompressed in one pass; a larger one is first counted without being
#: kept, so a bomb costs decompression time up to MAX_DOCUMENT_BYTES but never that much memory.
ONE_PASS_BYTES = 64 << 20
#: Memory the xz decoder may use (its dictionary): cc_log writes at most 64 MiB dictionaries.
DECODER_MEMORY = 256 << 20


# -- columns --------------------------------------------------------------------------------------------

def _flatten(row, prefix, out):
    for name, value in row.items():
        if isinstance(value, dict) and value:
            _flatten(value, prefix + name + '.', out)
        else:
            out[prefix + name] = value
    return out


def _unflatten(flat):
    row = {}
    for key, value in flat.items():
        node = row
        parts = key.split('.')
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return row


_ROW_MAKERS = {}  # message class -> function(msg) -> flat row


def flat_row(msg):
    """``_flatten(msg_codec.to_dict(msg, short_float32=True))``, the same dict (keys, order, values) made by
    a function compiled once per message class: one getter and one encoder per leaf field."""
    cls = type(msg)
    make = _ROW_MAKERS.get(cls)
    if make is None:
        fields = _leaf_fields(msg, '', [])
        make = _ROW_MAKERS[cls] = lambda message: {key: encode(get(message)) for key, get, encode in fields}
    return make(msg)


def _same_value(value):
    return value


def _float(value):
    return msg_codec.encode_float(float(value))


def _float64s(values):
    values = list(map(float, values))
    return values if all(map(math.isfinite, values)) else [msg_codec.encode_float(value) for value in values]


def _float32(value):
    return msg_codec.encode_float(msg_codec.short_float32(float(value)))


def _leaf_fields(msg, prefix, out):
    """``(dotted key, attribute getter, encoder)`` of every leaf of ``msg`` as ``_flatten(to_dict(msg))``
    lists them; arrays and empty messages are leaves (as in ``to_dict``)."""
    for name, slot_type in zip(msg.__slots__, msg._slot_types):
        key = prefix + name
        base, is_array, _ = msg_codec.split_type(slot_type)
        value = getattr(msg, name)
        if is_array and base == 'float64':
            encode = _float64s
        elif is_array:
            encode = functools.partial(msg_codec.encode_value, slot_type=slot_type, short=True)
        elif base in msg_codec.TIME_TYPES:
            out.append((key + '.secs', operator.attrgetter(key + '.secs'), int))
            out.append((key + '.nsecs', operator.attrgetter(key + '.nsecs'), int))
            continue
        elif base in msg_codec.FLOAT_TYPES:
            encode = _float32 if base == 'float32' else _float
        elif base in msg_codec.PRIMITIVE_TYPES:
            encode = _same_value
        elif getattr(value, '__slots__', None):
            _leaf_fields(value, key + '.', out)
            continue
        else:
            encode = functools.partial(msg_codec.to_dict, short_float32=True)
        out.append((key, operator.attrgetter(key), encode))
    return out


def _same(value, first, first_repr):
    """Whether two JSON values are the same text: ``==`` alone takes 0 for 0.0, False or -0.0."""
    return value == first and repr(value) == first_repr


def _columns(rows):
    """Split flat rows into (constant, columns), keys in the order of the first row."""
    return _split_columns(dict((key, [row[key] for row in rows]) for key in rows[0]))


def _split_columns(values, same=()):
    """Split ``{key: one value per message}`` into (constant, columns), keys in order; the keys in ``same``
    are known to hold the same value (its very object) in every message."""
    constant, columns = {}, {}
    for key, column in values.items():
        first = column[0]
        if len(column) > 1 and key in same:
            constant[key] = first
            continue
        if len(column) > 1 and column.count(first) == len(column):  # count: a quick no; _same: the text
            first_repr = repr(first)
            if all(_same(value, first, first_repr) for value in column[1:]):
                constant[key] = first
                continue
        columns[key] = column
    return constant, columns


def _header_stamp(msg):
    header = getattr(msg, 'header', None)
    stamp = getattr(header, 'stamp', None)
    return stamp.to_sec() if stamp is not None and hasattr(stamp, 'to_sec') else None


def _all_equal(header_stamps, stamps):
    """Whether every record's stamp equals its header stamp (``header_stamps``: a list, or an array)."""
    if isinstance(header_stamps, numpy.ndarray) and all(type(stamp) is float for stamp in stamps):
        return bool((header_stamps == numpy.array(stamps)).all())
    return all(header == stamp for header, stamp in zip(list(header_stamps), stamps))


def decoded_records(records):
    """``raw_message.decoded_records`` for this writer: a record of serialized bytes that ``document`` reads
    in bulk (a ``raw_message.layout`` type whose bytes fit it) stays as it is; the others are decoded (those
    that cannot be are counted)."""
    raws = {}  # class -> indices of its records in bytes
    kept = list(records)
    bad = set()
    classes = {}
    for index, record in enumerate(kept):
        if record.msg is None and record.raw is not None:
            try:
                cls = _class_of(record, classes)
            except raw_message.DECODE_ERRORS:
                bad.add(index)
                continue
            raws.setdefault(cls, []).append(index)
    for cls, indices in raws.items():
        fields = raw_message.layout(cls)
        if fields is not None:
            indices = [indices[rest] for rest in raw_message.blocks(fields, [kept[i].raw for i in indices])[1]]
        for index in indices:
            try:
                kept[index] = raw_message.decoded(kept[index])
            except raw_message.DECODE_ERRORS:
                bad.add(index)
    return [record for index, record in enumerate(kept) if index not in bad], len(bad)


def _class_of(record, classes):
    """The class of a record's message (``raw_message.message_class`` of its connection when it has no message),
    ``classes``: a cache by connection object (records of one connection share it)."""
    if record.msg is not None:
        return type(record.msg)
    cls = classes.get(id(record.connection))
    if cls is None:
        cls = classes[id(record.connection)] = raw_message.message_class(record.connection)
    return cls


def _section_values(recs):
    """``({key: one value per record}, keys holding the same value in every record, header stamps)`` of a
    section's records, as ``flat_row`` makes them: records of serialized bytes of a ``raw_message.layout`` type
    read column by column from their bytes (one numpy view per field; a field with the same bytes in every
    message read once), the others (and messages genpy reads differently) decoded, row by row."""
    classes = {}
    raw = [index for index, record in enumerate(recs) if record.msg is None]
    cls = _class_of(recs[raw[0]], classes) if raw else None
    fields = raw_message.layout(cls) if cls is not None else None
    if fields is None or any(_class_of(recs[index], classes) is not cls for index in raw):
        recs = [raw_message.decoded(record) for record in recs]
        raw, fields = [], None
    rows = {}  # index -> flat row, of the records not read from the bytes
    blocks = []
    if fields is not None:
        blocks, rest = raw_message.blocks(fields, [recs[index].raw for index in raw])
        positions = numpy.array(raw, dtype=numpy.intp)
        blocks = [block._replace(rows=positions[block.rows]) for block in blocks]
        rows.update((raw[index], flat_row(raw_message.decoded(recs[raw[index]]).msg)) for index in rest)
    rows.update((index, flat_row(record.msg)) for index, record in enumerate(recs) if record.msg is not None)
    keys = [field.key for field in fields] if fields is not None else list(rows[0])
    if fields is not None and rows and list(next(iter(rows.values()))) != keys:
        return _section_values([raw_message.decoded(record) for record in recs])
    values, same = {}, ()
    for block in blocks:
        whole = len(block.rows) == len(recs)
        try:
            if whole:
                same = _same_fields(block, fields)
                first = block._replace(rows=block.rows[:1], table=block.table[:1])
                columns = [_block_values(first, field) * len(recs) if field.key in same else
                           _block_values(block, field) for field in fields]
            else:
                columns = [_block_values(block, field) for field in fields]
        except UnicodeDecodeError:  # genpy replaces what is not UTF-8: its row
            rows.update((index, flat_row(raw_message.decoded(recs[index]).msg)) for index in block.rows.tolist())
            same = ()
            continue
        if whole:
            values = dict(zip(keys, columns))
            break
        for key, column in zip(keys, columns):
            target = values.setdefault(key, [None] * len(recs))
            for index, value in zip(block.rows.tolist(), column):
                target[index] = value
    if rows and not values:
        values = dict((key, [None] * len(recs)) for key in keys)
    for index, row in rows.items():
        for key in keys:
            values[key][index] = row[key]
    if fields is None or 'header.stamp.secs' not in keys or not _is_time(cls, 'header.stamp'):
        return values, same, [_header_stamp(record.msg) if record.msg is not None else None for record in recs]
    secs = numpy.array(values['header.stamp.secs'], dtype=numpy.float64)
    return values, same, secs + numpy.array(values['header.stamp.nsecs'], dtype=numpy.float64) / 1e9


def _same_fields(block, fields):
    """The keys of the fields whose bytes are the same in every message of ``block``."""
    equal = (block.table == block.table[0]).all(axis=0)
    same = set()
    for field in fields:
        offset = block.offsets[field.key]
        start, size = (offset[0], offset[1]) if field.base == 'string' else (offset, field.size)
        if equal[start:start + size].all():
            same.add(field.key)
    return same


def _is_time(cls, dotted):
    """Whether the field ``dotted`` of ``cls`` is a time or a duration (its value has ``to_sec``)."""
    value = cls()
    for name in dotted.split('.'):
        value = getattr(value, name, None)
    return hasattr(value, 'to_sec')


def _block_values(block, field):
    """The values of ``field`` of the messages of a ``raw_message.Block``, each as ``flat_row`` writes it."""
    if field.base == 'string':
        data = block.bytes_column(field)
        if (data == data[0]).all():
            return [data[0].tobytes().decode('utf-8')] * len(data)
        return [row.tobytes().decode('utf-8') for row in data]
    if field.count and field.base in msg_codec.BYTES_TYPES:
        return [base64.b64encode(row.tobytes()).decode('ascii') for row in block.bytes_column(field)]
    array = block.column(field)
    if field.count is None:
        array = array[:, 0]
    if field.base == 'bool':
        return array.astype(bool).tolist()
    values = array.tolist()
    if field.base == 'float32':
        return [_float32(value) for value in values] if field.count is None else \
            [[_float32(value) for value in row] for row in values]
    if field.base == 'float64' and not numpy.isfinite(array).all():
        return list(map(_float if field.count is None else _float64s, values))
    return values


# -- differences ----------------------------------------------------------------------------------------

def _is_int(value):
    return isinstance(value, int) and not isinstance(value, bool)


def _is_plain_float(value):
    """A finite float that is not -0.0 (whose sign a sum of differences does not keep)."""
    return isinstance(value, float) and math.isfinite(value) and not (value == 0.0 and math.copysign(1.0, value) < 0)


def decimal_text(value):
    """The JSON text of a Decimal: ``0``, else the shorter of plain and scientific notation, no trailing
    zeros."""
    if not value:
        return '0'
    value = value.normalize(_EXACT)
    scientific = str(value)
    if 'E' not in scientific:
        return scientific  # plain already, as format(value, 'f') writes it
    plain = format(value, 'f')
    return plain if len(plain) <= len(scientific) else scientific


def differences(values, choose=True):
    """``values`` as their first value and differences (ints, or Decimals for floats), or None when they
    are not all integers or all finite floats (no -0.0), or (``choose``) when the plain column is likely
    smaller (integers: not shorter as text; floats: see DELTA_GAIN, REPEATS_SHARE and SAMPLE)."""
    if len(values) < 3:
        return None
    if set(map(type, values)) == {int} or all(_is_int(value) for value in values):
        deltas = values[:1] + [b - a for a, b in zip(values, values[1:])]
        return deltas if not choose or len(str(deltas)) < len(str(values)) else None
    if not _plain_floats(values):
        return None
    if choose and len(values) > 2 * SAMPLE and _digit_share(values[:SAMPLE])[0] > SAMPLE_GAIN:
        return None  # decided on a sample: noisy columns (IMU axes) are not worth the decimal arithmetic
    texts = list(map(repr, values))
    if choose:  # the repeats first: they are cheaper to count than the digits
        adjacent = sum(1 for a, b in zip(texts, texts[1:]) if a == b)
        if len(texts) - len(set(texts)) - adjacent > REPEATS_SHARE * len(texts):
            return None
    share, deltas = _digit_share(values, texts)
    return None if choose and share > DELTA_GAIN else deltas


def _plain_floats(values):
    """``all(_is_plain_float(value) for value in values)``, in bulk for a list of floats."""
    if set(map(type, values)) != {float}:
        return all(_is_plain_float(value) for value in values)
    return all(map(math.isfinite, values)) and (0.0 not in values or all(map(_is_plain_float, values)))


def _digit_share(values, texts=None):
    """(significant digits of the differences / of the values, the differences); (inf, None) when they
    cannot be computed exactly. ``texts``: ``repr`` of the values, if already made. The differences are a
    ``_Deltas`` list: their texts (``decimal_text``) are kept for ``dumps``."""
    texts = list(map(repr, values)) if texts is None else texts
    exact = list(map(decimal.Decimal, texts))
    try:
        deltas = _Deltas(exact[:1] + list(map(_EXACT.subtract, exact[1:], exact)))
    except decimal.DecimalException:
        return math.inf, None
    deltas.texts = _decimal_texts(deltas)
    return _digit_sum(deltas.texts) / max(1, _digit_sum(texts)), deltas


class _Deltas(list):
    """Differences (Decimals) with their ``texts``."""

    texts = None


_NORMALIZED = operator.methodcaller('normalize', _EXACT)


def _decimal_texts(values):
    """``decimal_text`` of each of the Decimals ``values``, in bulk: ``str`` of the normalized value is that
    text unless it is scientific (then the shorter of the two notations) or ``-0``."""
    texts = list(map(str, map(_NORMALIZED, values)))
    if '-0' in texts or 'E' in ''.join(texts):
        texts = [decimal_text(value) if 'E' in text or text == '-0' else text for value, text in zip(values, texts)]
    return texts


_EXPONENT = re.compile('[eE][-+]?[0-9]+')


def _digit_sum(texts):
    """``sum(map(_digits, texts))`` counted over the joined texts, exponents left out: every digit, less the
    zeros that lead a number (``0.00``...) and the texts that are ``0``."""
    joined = ',' + ',,'.join(texts) + ','  # every text between its own two commas
    if 'e' in joined or 'E' in joined:
        joined = _EXPONENT.sub('', joined)  # the mantissa's digits count
    joined = joined.replace(',-', ',')
    count = len(joined) - joined.count(',') - joined.count('.') - joined.count(',0,')
    lead = ',0.'
    leading = joined.count(lead)
    while leading:
        count -= leading
        lead += '0'
        leading = joined.count(lead)
    return count


def _digits(text):
    """Significant digits of a number's text (what LZMA pays for: leading zeros and the exponent are cheap)."""
    return len(text.lower().split('e')[0].lstrip('-').replace('.', '').lstrip('0'))


def _sums(values, key):
    """The values of a delta column (first value, then differences) added up; floats exact in decimal."""
    if not values or not all(_is_int(value) or isinstance(value, decimal.Decimal) for value in values):
        raise ValueError('delta column %s: holds something other than numbers' % key)
    total = values[0]
    out = [total]
    try:
        for delta in values[1:]:
            exact = isinstance(total, decimal.Decimal) or isinstance(delta, decimal.Decimal)
            total = _EXACT.add(total, delta) if exact else total + delta
            out.append(total)
    except decimal.DecimalException:
        raise ValueError('delta column %s: differences do not add up exactly' % key)
    return out


# -- precision (lossy) ----------------------------------------------------------------------------------

_ROUNDING = decimal.Context(prec=60, rounding=decimal.ROUND_HALF_EVEN)


def check_precision(precision, name='precision'):
    """``{field pattern: step}`` with every step a finite number > 0, else ValueError('<name>: ...').
    ``precision`` is such a mapping, None (no rounding) or text ``'pattern=step, pattern=step'`` (a node
    parameter, a command-line option)."""
    if precision is None:
        return {}
    if isinstance(precision, str):
        items = [item.strip() for item in precision.split(',') if item.strip()]
        if not all(item.count('=') == 1 for item in items):
            raise ValueError('%s: %r is not "pattern=step, pattern=step, ..."' % (name, precision))
        precision = dict((pattern.strip(), step.strip()) for pattern, step in (item.split('=') for item in items))
    if not isinstance(precision, dict):
        raise ValueError('%s: a mapping of field patterns to steps (e.g. {"pose.pose.position.*": 1e-4}), '
                         'not %r' % (name, precision))
    checked = {}
    for pattern, step in precision.items():
        if not isinstance(pattern, str) or not pattern:
            raise ValueError('%s: %r is not a field pattern' % (name, pattern))
        if isinstance(step, str):
            try:
                step = float(step)
            except ValueError:
                pass
        if isinstance(step, bool) or not isinstance(step, (int, float)) or not 0 < step < float('inf'):
            raise ValueError('%s: %s: step %r is not a number > 0' % (name, pattern, step))
        checked[pattern] = float(step)
    return checked


def _rounder(precision):
    """A function ``(key, value) -> value`` rounding the floats of fields matching ``precision``."""
    steps = [(pattern, decimal.Decimal(repr(step))) for pattern, step in check_precision(precision).items()]
    chosen = {}

    def round_value(value, step):
        if isinstance(value, list):
            return [round_value(item, step) for item in value]
        if not isinstance(value, float) or not math.isfinite(value):
            return value
        count = _ROUNDING.divide(decimal.Decimal(repr(value)), step).to_integral_value(decimal.ROUND_HALF_EVEN)
        return float(_ROUNDING.multiply(count, step)) + 0.0  # + 0.0: no -0.0

    def rounded(key, value):
        if key not in chosen:
            chosen[key] = next((step for pattern, step in steps if fnmatch.fnmatchcase(key, pattern)), None)
        step = chosen[key]
        return value if step is None else round_value(value, step)
    return rounded


def max_errors(records, back):
    """``{topic: {field: largest absolute difference}}`` of every float field (array elements included)
    between ``records`` and ``back`` (the same messages read back, e.g. after rounding); non-finite values
    must stay the same (else the error is ``inf``)."""
    errors = {}
    for a, b in zip(records, back):
        topic = errors.setdefault(a.topic, {})
        flat_b = _flatten(msg_codec.to_dict(b.msg), '', {})
        for key, value in _flatten(msg_codec.to_dict(a.msg), '', {}).items():
            pairs = zip(value, flat_b[key]) if isinstance(value, list) else [(value, flat_b[key])]
            for old, new in pairs:
                if isinstance(old, float) or isinstance(new, float):
                    error = abs(new - old) if math.isfinite(old) else (0.0 if repr(old) == repr(new) else math.inf)
                    topic[key] = max(topic.get(key, 0.0), error)
    return errors


def document(records, metadata, delta=differences):
    """The JSON document (a dict) of a window's records and its metadata; ``metadata['precision']`` (if any)
    rounds fields (module docstring). Delta columns of floats hold Decimals: write it with ``dumps``.
    ``delta(values)``: a column's differences, or None to write it plain (bench/format_layouts.py compares
    choices)."""
    if not records:
        raise ValueError('window: has no records')
    meta = dict(metadata or {})
    precision = check_precision(meta.get('precision'), 'precision')
    rounded = _rounder(precision) if precision else None
    sections = []
    index = {}
    order = []
    classes = {}
    for record in records:
        msg = _class_of(record, classes)
        if record.topic not in index:
            index[record.topic] = len(sections)
            sections.append({'topic': record.topic, 'type': msg._type, 'md5sum': msg._md5sum,
                             'definition': msg_codec.compact_definition(msg._full_text),
                             'records': [], 'connection': None})
        section = sections[index[record.topic]]
        if section['connection'] is None and record.connection:  # the first record with a connection header
            section['connection'] = raw_message.publisher_keys(record.connection)
        if msg._type != section['type']:
            raise ValueError('topic %s: holds both %s and %s' % (record.topic, section['type'], msg._type))
        section['records'].append(record)
        order.append(index[record.topic])
    topics = []
    for section in sections:
        recs = section.pop('records')
        values, same, header_stamps = _section_values(recs)
        if rounded is not None:
            values = dict((key, [rounded(key, column[0])] * len(column) if key in same else
                           [rounded(key, value) for value in column]) for key, column in values.items())
        constant, columns = _split_columns(values, same)
        delta_keys = []
        for key, values in columns.items():
            deltas = delta(values)
            if deltas is not None:
                columns[key] = deltas
                delta_keys.append(key)
        stamps = [record.stamp for record in recs]
        if _all_equal(header_stamps, stamps):
            stamps = HEADER_STAMP
        else:
            stamps = [msg_codec.encode_float(float(stamp)) for stamp in stamps]
        topic = {'topic': section['topic'], 'type': section['type'], 'md5sum': section['md5sum'],
                 'count': len(recs), 'stamps': stamps, 'constant': constant, 'columns': columns}
        if delta_keys:
            topic['delta'] = delta_keys
        if section['connection']:
            topic['connection'] = section['connection']
        topic['definition'] = section['definition']
        topics.append(topic)
    meta.setdefault('codec', CODEC)
    if precision:
        meta['precision'] = precision
    meta['layout'] = LAYOUT_VERSION
    doc = {'metadata': meta, 'topics': topics}
    if not _merges_back(records, order):
        doc['order'] = order
    return doc


def _json(value):
    return json.dumps(value, separators=(',', ':'), allow_nan=False)


def dumps(doc):
    """The compact JSON text of a ``document`` (Decimals of delta columns written exactly)."""
    sections = []
    for section in doc['topics']:
        parts = []
        for key, value in section.items():
            if key == 'columns':
                value = '{%s}' % ','.join('%s:%s' % (_json(name), _column_text(values))
                                          for name, values in value.items())
            else:
                value = _json(value)
            parts.append('%s:%s' % (_json(key), value))
        sections.append('{%s}' % ','.join(parts))
    text = '{"metadata":%s,"topics":[%s]' % (_json(doc['metadata']), ','.join(sections))
    if 'order' in doc:
        text += ',"order":%s' % _json(doc['order'])
    return text + '}'


def _column_text(values):
    if values and isinstance(values[0], decimal.Decimal):  # the first as written (8.0, not 8), then differences
        texts = values.texts if isinstance(values, _Deltas) else _decimal_texts(values)
        return '[%s]' % ','.join([str(values[0])] + texts[1:])
    return _json(values)


def _merges_back(records, order):
    """Whether a reader without ``order`` (merging sections by stamp, then section, then position in the
    section) gets the records back in their own order."""
    seen = {}
    keys = []
    for record, section in zip(records, order):
        position = seen.get(section, 0)
        seen[section] = position + 1
        keys.append((record.stamp, section, position))
    return all(a < b for a, b in zip(keys, keys[1:]))


def encode(records, metadata, preset=DEFAULT_PRESET):
    """The ``.json.xz`` bytes of a window: compact JSON, one xz stream (CRC64)."""
    data = dumps(document(records, metadata)).encode('utf-8')
    return compress(data, preset)


def encoder(records, metadata):
    """A function that writes the window into a stream; the document is encoded now, before the file exists
    (a crash while encoding leaves no empty leftover)."""
    data = encode(records, metadata)
    return lambda stream: stream.write(data)


def compress(data, preset=DEFAULT_PRESET, options=FILTER_OPTIONS):
    """xz-compress with LZMA2 at ``preset`` with ``options`` (FILTER_OPTIONS; ``{}``: the preset alone) and a
    dictionary no larger than the data needs (the output is the same as with the preset's own dictionary;
    memory stays small on the robot)."""
    dict_size = 1 << 16
    while dict_size < len(data) and dict_size < (1 << 26):
        dict_size <<= 1
    filters = [dict(options, id=lzma.FILTER_LZMA2, preset=preset, dict_size=dict_size)]
    return lzma.compress(data, format=lzma.FORMAT_XZ, check=lzma.CHECK_CRC64, filters=filters)


# -- reading --------------------------------------------------------------------------------------------

def decompress(data, name='<bytes>', limit=MAX_DOCUMENT_BYTES):
    """xz ``data`` decompressed as ``lzma.decompress`` does (concatenated streams; trailing garbage after
    a stream ignored), refused with ValueError('<name>: ...') beyond ``limit`` bytes or when corrupt."""
    try:
        if limit > ONE_PASS_BYTES:
            try:
                return _decompress(data, ONE_PASS_BYTES, keep=True)
            except _TooLarge:
                _decompress(data, limit, keep=False)
        return _decompress(data, limit, keep=True)
    except _TooLarge:
        raise ValueError('%s: decompresses to more than %d bytes (the limit of a window document)' % (name, limit))
    except (lzma.LZMAError, EOFError) as error:
        raise ValueError('%s: corrupt or truncated xz data (%s)' % (name, error))


class _TooLarge(Exception):
    pass


def _decompress(data, limit, keep):
    """The streams of ``data``, joined when ``keep`` (else only counted, 1 MiB at a time); _TooLarge beyond
    ``limit``."""
    parts, size, streams = [], 0, 0
    while True:
        decompressor = lzma.LZMADecompressor(format=lzma.FORMAT_XZ, memlimit=DECODER_MEMORY)
        try:
            if keep:
                part = decompressor.decompress(data, max_length=limit - size + 1)
            else:
                part = decompressor.decompress(data, max_length=1 << 20)
                while not decompressor.eof and not decompressor.needs_input and size + len(part) <= limit:
                    size += len(part)
                    part = decompressor.decompress(b'', max_length=1 << 20)
        except lzma.LZMAError:
            if streams:
                break  # what follows a complete stream is not one: ignored, as lzma.decompress does
            raise
        size += len(part)
        if size > limit:
            raise _TooLarge()
        if keep:
            parts.append(part)
        if not decompressor.eof:
            raise lzma.LZMAError('Compressed data ended before the end-of-stream marker was reached')
        streams += 1
        data = decompressor.unused_data
        if not data:
            break
    return b''.join(parts)


def decode(data, name='<bytes>'):
    """``(metadata, records)`` from ``.json.xz`` bytes; ValueError('<name>: <what is wrong>') otherwise (also
    for a document beyond MAX_DOCUMENT_BYTES, nested beyond safe_input.MAX_JSON_DEPTH, or holding an unsafe
    message definition)."""
    if not data.startswith(MAGIC):
        raise ValueError('%s: not an xz file' % name)
    text = decompress(data, name)
    try:
        doc = safe_input.json_loads(text, parse_float=_parse_decimal)
    except ValueError as error:
        raise ValueError('%s: not a JSON document (%s)' % (name, error))
    try:
        return from_document(doc)
    except ValueError as error:
        raise ValueError('%s: %s' % (name, error))


def read(path, stream=None):
    """``(metadata, records)`` of a ``.json.xz`` window file (``stream``: that file, already open)."""
    with (stream or safe_input.open_input(path)) as stream:
        if os.fstat(stream.fileno()).st_size > MAX_DOCUMENT_BYTES:
            raise ValueError('%s: larger than %d bytes: not a cc_log window' % (path, MAX_DOCUMENT_BYTES))
        stream.seek(0)
        return decode(stream.read(), path)


def _parse_decimal(text):
    """A JSON number with a fraction or exponent, exactly; ValueError (not decimal's own exception) for an
    exponent beyond what Decimal holds."""
    try:
        return decimal.Decimal(text)
    except decimal.DecimalException:
        raise ValueError('number %s... is out of range' % text[:20])


def _floats(value):
    """``value`` (parsed JSON) with every Decimal turned into the float its text reads as."""
    if isinstance(value, decimal.Decimal):
        return float(value)
    if isinstance(value, list):
        return [_floats(item) for item in value]
    if isinstance(value, dict):
        return dict((key, _floats(item)) for key, item in value.items())
    return value


def from_document(doc):
    """``(metadata, records)`` of a JSON document parsed with ``parse_float=decimal.Decimal`` (as ``decode``
    does: delta columns are added up exactly); ValueError saying what does not fit."""
    if not isinstance(doc, dict) or not isinstance(doc.get('metadata'), dict) \
            or not isinstance(doc.get('topics'), list):
        raise ValueError('not a cc_log json-xz window (needs "metadata" and "topics")')
    metadata = _floats(doc['metadata'])
    layout = metadata.get('layout')
    if layout not in LAYOUTS:
        raise ValueError('json-xz layout %r is not supported (this cc_log reads layouts %s)'
                         % (layout, ', '.join(str(number) for number in LAYOUTS)))
    per_topic = []
    for number, section in enumerate(doc['topics']):
        try:
            per_topic.append(_section_records(section))
        except (KeyError, TypeError, AttributeError, IndexError) as error:
            raise ValueError('topic section %d: %s: %s' % (number, type(error).__name__, error))
        except ValueError as error:
            raise ValueError('topic %s: %s' % (section.get('topic', number), error))
    order = doc.get('order')
    if order is None:
        merged = []
        for number, recs in enumerate(per_topic):
            merged.extend((record.stamp, number, i) for i, record in enumerate(recs))
        merged.sort()
        return metadata, [per_topic[number][i] for _, number, i in merged]
    records = []
    positions = [0] * len(per_topic)
    try:
        for number in order:
            records.append(per_topic[number][positions[number]])
            positions[number] += 1
    except (IndexError, TypeError):
        raise ValueError('"order" does not fit the topic sections')
    if positions != [len(recs) for recs in per_topic]:
        raise ValueError('"order" does not fit the topic sections')
    return metadata, records


def _section_records(section):
    topic, msg_type, definition = section['topic'], section['type'], section['definition']
    count = section['count']
    constant, columns = _floats(section['constant']), dict(section['columns'])
    if not isinstance(count, int) or count < 1:
        raise ValueError('count %r is not a positive integer' % (count,))
    delta = section.get('delta', [])
    if not isinstance(delta, list) or any(key not in columns for key in delta):
        raise ValueError('"delta" names a column that is not there')
    for key, values in columns.items():
        if not isinstance(values, list) or len(values) != count:
            raise ValueError('column %s does not hold %d values' % (key, count))
        if key in delta:
            values = _sums(values, key)
        columns[key] = _floats(values)
    cls = msg_codec.message_class(msg_type, definition)
    if section.get('md5sum') not in (None, cls._md5sum):
        raise ValueError('md5sum %s does not match the definition (%s)' % (section['md5sum'], cls._md5sum))
    connection = section.get('connection')
    if connection is not None:
        if not isinstance(connection, dict) or not set(connection) <= set(raw_message.PUBLISHER_KEYS) \
                or not all(isinstance(value, str) for value in connection.values()):
            raise ValueError('"connection" must map %s to text' % ' and '.join(raw_message.PUBLISHER_KEYS))
        connection = dict(raw_message.class_header(topic, cls), **connection)
    stamps = _floats(section['stamps'])
    if stamps != HEADER_STAMP:
        if not isinstance(stamps, list) or len(stamps) != count:
            raise ValueError('stamps do not hold %d values' % count)
        stamps = [msg_codec.decode_float(stamp) for stamp in stamps]
    records = []
    for i in range(count):
        flat = dict(constant)
        for key, values in columns.items():
            flat[key] = values[i]
        try:
            msg = msg_codec.from_dict(_unflatten(flat), msg_type, definition)
        except ValueError as error:
            raise ValueError('message %d: %s' % (i, error))
        if stamps == HEADER_STAMP:
            stamp = msg.header.stamp.to_sec()
        else:
            stamp = stamps[i]
        records.append(Record(stamp, topic, msg, connection=connection))
    return records
