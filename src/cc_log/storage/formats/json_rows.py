"""Rows and columns of a json-xz section (``json_xz``'s module docstring): a message's flat row (its dotted
leaf fields as ``msg_codec.to_dict`` writes them, by getters compiled once per class), a section's values read
column by column from the serialized bytes of a ``raw_message.layout`` type (numpy views at the fields'
offsets, the same values as the rows), and the split into constant fields and columns.
"""
import base64
import functools
import math
import operator

import numpy

from cc_log.base import msg_codec, raw_message


# -- columns --------------------------------------------------------------------------------------------

def flatten(row, prefix, out):
    for name, value in row.items():
        if isinstance(value, dict) and value:
            flatten(value, prefix + name + '.', out)
        else:
            out[prefix + name] = value
    return out


def unflatten(flat):
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
    """``flatten(msg_codec.to_dict(msg, short_float32=True))``, the same dict (keys, order, values) made by
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
    """``(dotted key, attribute getter, encoder)`` of every leaf of ``msg`` as ``flatten(to_dict(msg))``
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


def columns_of(rows):
    """Split flat rows into (constant, columns), keys in the order of the first row."""
    return split_columns(dict((key, [row[key] for row in rows]) for key in rows[0]))


def split_columns(values, same=()):
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


def all_equal(header_stamps, stamps):
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
                cls = class_of(record, classes)
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


def class_of(record, classes):
    """The class of a record's message (``raw_message.message_class`` of its connection when it has no message),
    ``classes``: a cache by connection object (records of one connection share it)."""
    if record.msg is not None:
        return type(record.msg)
    cls = classes.get(id(record.connection))
    if cls is None:
        cls = classes[id(record.connection)] = raw_message.message_class(record.connection)
    return cls


def section_values(recs):
    """``({key: one value per record}, keys holding the same value in every record, header stamps)`` of a
    section's records, as ``flat_row`` makes them: records of serialized bytes of a ``raw_message.layout`` type
    read column by column from their bytes (one numpy view per field; a field with the same bytes in every
    message read once), the others (and messages genpy reads differently) decoded, row by row."""
    classes = {}
    raw = [index for index, record in enumerate(recs) if record.msg is None]
    cls = class_of(recs[raw[0]], classes) if raw else None
    fields = raw_message.layout(cls) if cls is not None else None
    if fields is None or any(class_of(recs[index], classes) is not cls for index in raw):
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
        return section_values([raw_message.decoded(record) for record in recs])
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
