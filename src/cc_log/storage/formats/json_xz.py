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

``read_metadata`` decompresses only the start of a document, as far as its metadata goes (``cclog info``).

Rows and columns (``flat_row``, a section's values read from the bytes) are ``json_rows``'s; the differences
(``DELTA_GAIN``, ``differences``) and the rounding (``check_precision``) are ``json_deltas``'s; this module makes
the document and its text, compresses it, and reads it back. Pure: no rospy, no rosbag.
"""
import codecs
import decimal
import json
import lzma
import os

from cc_log.base import msg_codec, raw_message, safe_input
from cc_log.base.records import Record
from cc_log.storage.formats.json_deltas import (  # noqa: F401  (json_xz.check_precision, ...: the format's API)
    Deltas, check_precision, decimal_text, decimal_texts, differences, max_errors, rounder, sums)
from cc_log.storage.formats.json_rows import (  # noqa: F401  (json_xz.flat_row, json_xz.decoded_records)
    all_equal, class_of, decoded_records, flat_row, section_values, split_columns, unflatten)

CODEC = 'json-xz'
EXTENSION = '.json.xz'
# Messages of these types are large (images, point clouds, scans: MB/s per topic): json-xz writes each value as
# text and LZMA compresses it at about CARRIES_MB_S per core, where bag-lz4 writes their bytes as they came.
HEAVY_TYPES = frozenset(['sensor_msgs/Image', 'sensor_msgs/CompressedImage', 'sensor_msgs/PointCloud2',
                         'sensor_msgs/PointCloud', 'sensor_msgs/LaserScan', 'sensor_msgs/MultiEchoLaserScan',
                         'stereo_msgs/DisparityImage', 'theora_image_transport/Packet'])
CARRIES_MB_S = 16  # MB/s of messages one core turns into json-xz (LZMA; docs/RESULTS.md, heavy sensors)
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

#: Largest document (decompressed bytes) and file read. A window holds at most ``max_window`` (100,000)
#: driving messages: about 200 bytes each in the column layout (Husky odometry + IMU), at most ~2 kB when
#: every field changes, so 20-200 MB; 1 GiB is well above, and an xz bomb stops there.
MAX_DOCUMENT_BYTES = 1 << 30
#: Documents up to this size are decompressed in one pass; a larger one is first counted without being
#: kept, so a bomb costs decompression time up to MAX_DOCUMENT_BYTES but never that much memory.
ONE_PASS_BYTES = 64 << 20
#: Fewest document bytes a message costs (``decode`` refuses a document declaring more messages than its bytes
#: pay for, beyond FREE_MESSAGES): a message's own values in the columns or stamps are ~50-2,000 bytes, a
#: message of constant fields alone (its section states them once) is not, hence the free allowance.
MIN_MESSAGE_BYTES = 16
#: Messages a document may declare beyond what its bytes pay for at MIN_MESSAGE_BYTES each.
FREE_MESSAGES = 10000
#: Most messages one document may declare (10 times ``max_window``'s 100,000 driving messages): each costs ~1 kB
#: of memory and ~25 us once read.
MAX_DOCUMENT_MESSAGES = 1000000
#: Memory the xz decoder may use (its dictionary): cc_log writes at most 64 MiB dictionaries.
DECODER_MEMORY = 256 << 20


def document(records, metadata, delta=differences):
    """The JSON document (a dict) of a window's records and its metadata; ``metadata['precision']`` (if any)
    rounds fields (module docstring). Delta columns of floats hold Decimals: write it with ``dumps``.
    ``delta(values)``: a column's differences, or None to write it plain (bench/format_layouts.py compares
    choices)."""
    if not records:
        raise ValueError('window: has no records')
    meta = dict(metadata or {})
    precision = check_precision(meta.get('precision'), 'precision')
    rounded = rounder(precision) if precision else None
    sections = []
    index = {}
    order = []
    classes = {}
    for record in records:
        msg = class_of(record, classes)
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
        values, same, header_stamps = section_values(recs)
        if rounded is not None:
            values = dict((key, [rounded(key, column[0])] * len(column) if key in same else
                           [rounded(key, value) for value in column]) for key, column in values.items())
        constant, columns = split_columns(values, same)
        delta_keys = []
        for key, values in columns.items():
            deltas = delta(values)
            if deltas is not None:
                columns[key] = deltas
                delta_keys.append(key)
        stamps = [record.stamp for record in recs]
        if all_equal(header_stamps, stamps):
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
        texts = values.texts if isinstance(values, Deltas) else decimal_texts(values)
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
        return from_document(doc, len(text))
    except ValueError as error:
        raise ValueError('%s: %s' % (name, error))


def read(path, stream=None):
    """``(metadata, records)`` of a ``.json.xz`` window file (``stream``: that file, already open)."""
    with (stream or safe_input.open_input(path)) as stream:
        if os.fstat(stream.fileno()).st_size > MAX_DOCUMENT_BYTES:
            raise ValueError('%s: larger than %d bytes: not a cc_log window' % (path, MAX_DOCUMENT_BYTES))
        stream.seek(0)
        return decode(stream.read(), path)


#: The start of every document cc_log writes (``dumps``): its metadata comes first.
METADATA_START = '{"metadata":'
#: Decompressed bytes ``read_metadata`` takes at a time; it looks for the end of the metadata after the first
#: of them, then each time it holds twice as many as when it last looked.
METADATA_STEP = 16 << 10


def heavy_topic_advice(topic, msg_type, fmt):
    """The warning for ``topic`` written in format ``fmt`` (``routes.format_of``) when that is json-xz and its type
    ``msg_type`` is heavy (``HEAVY_TYPES``), with the route that keeps it as bag-lz4; else None."""
    if fmt != CODEC or msg_type not in HEAVY_TYPES:
        return None
    topic, msg_type = safe_input.printable(topic), safe_input.printable(msg_type)
    return ('json-xz carries about %d MB/s per core: %s (%s) is better kept as bag-lz4 (a route: routes: '
            '[{name: sensors, topics: [%s], format: bag-lz4}], or format: bag-lz4)' % (
                CARRIES_MB_S, topic, msg_type, topic))


def read_metadata(path, stream=None):
    """``(metadata, None)`` of a ``.json.xz`` window file, decompressing only the start of its document, as far
    as the metadata goes (the document starts with it: ``{"metadata": {...}, "topics": ...``); a document that
    does not start so, whose metadata goes on beyond ONE_PASS_BYTES, or whose start is not as ``read`` reads it
    (corrupt, cut off before the end of the metadata, not JSON, nested too deep) is read whole, by ``read``: the
    same ValueError('<path>: ...'), and a bomb refused in the same bounded memory. What follows the metadata is
    not read (damage there, or a file cut off after the metadata, is not seen: the xz check of the whole stream is
    ``read``'s). No message counts (the metadata's ``counts`` are the window's)."""
    with (stream or safe_input.open_input(path)) as stream:
        if os.fstat(stream.fileno()).st_size > MAX_DOCUMENT_BYTES:
            raise ValueError('%s: larger than %d bytes: not a cc_log window' % (path, MAX_DOCUMENT_BYTES))
        stream.seek(0)
        if stream.read(len(MAGIC)) != MAGIC:
            raise ValueError('%s: not an xz file' % path)
        stream.seek(0)
        metadata = _leading_metadata(stream)
        if metadata is None:  # not a document as cc_log writes it, or not whole: read whole (read's errors)
            stream.seek(0)
            return decode(stream.read(), path)[0], None
    metadata = _floats(metadata)
    if metadata.get('layout') not in LAYOUTS:
        raise ValueError('%s: json-xz layout %r is not supported (this cc_log reads layouts %s)'
                         % (path, metadata.get('layout'), ', '.join(str(number) for number in LAYOUTS)))
    return metadata, None


def _leading_metadata(stream):
    """The metadata object at the start of the xz-compressed document of ``stream`` (parsed as ``decode`` parses
    it), decompressing as little as needed; None when the document does not start with METADATA_START, its
    metadata does not end within ONE_PASS_BYTES, or what is read of it is not what ``decode`` reads (corrupt,
    cut off, not UTF-8 or JSON, nested too deep: ``decode`` says what)."""
    decompressor = lzma.LZMADecompressor(format=lzma.FORMAT_XZ, memlimit=DECODER_MEMORY)
    text = codecs.getincrementaldecoder('utf-8')()
    parts, size, look_at = [], 0, METADATA_STEP
    parser = json.JSONDecoder(parse_float=_parse_decimal)
    while True:
        block = stream.read(1 << 16) if decompressor.needs_input else b''
        ended = decompressor.eof or (decompressor.needs_input and not block)
        if not ended:
            try:
                part = decompressor.decompress(block, max_length=METADATA_STEP)
                parts.append(text.decode(part))
            except (lzma.LZMAError, UnicodeDecodeError):
                return None
            size += len(part)
            if size > ONE_PASS_BYTES:
                return None  # metadata that large (or a bomb): read whole, in the bounded memory of ``decompress``
            if size < look_at:
                continue
        look_at = 2 * size
        document = ''.join(parts)
        parts = [document]
        if not document.startswith(METADATA_START[:len(document)]):
            return None
        try:
            safe_input.check_json_depth(document)
            metadata = parser.raw_decode(document, len(METADATA_START))[0]
        except json.JSONDecodeError:  # not whole yet, or not JSON
            if ended:
                return None
            continue
        except (ValueError, RecursionError):
            return None
        return metadata if isinstance(metadata, dict) else None


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


def from_document(doc, size=None):
    """``(metadata, records)`` of a JSON document parsed with ``parse_float=decimal.Decimal`` (as ``decode``
    does: delta columns are added up exactly); ValueError saying what does not fit, also before any message is
    built when its sections declare more messages than ``size`` (the document's bytes, when known) pays for
    (``message_cap``)."""
    if not isinstance(doc, dict) or not isinstance(doc.get('metadata'), dict) \
            or not isinstance(doc.get('topics'), list):
        raise ValueError('not a cc_log json-xz window (needs "metadata" and "topics")')
    declared = sum(section['count'] for section in doc['topics'] if isinstance(section, dict)
                   and isinstance(section.get('count'), int) and section['count'] > 0)
    if declared > message_cap(size):
        raise ValueError('the topic sections declare %d messages, more than the %d a document of %s bytes may hold'
                         % (declared, message_cap(size), 'unknown' if size is None else size))
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


def message_cap(size=None):
    """Most messages a document of ``size`` bytes (None: unknown) may declare: MIN_MESSAGE_BYTES per message
    beyond FREE_MESSAGES, at most MAX_DOCUMENT_MESSAGES."""
    if size is None:
        return MAX_DOCUMENT_MESSAGES
    return min(MAX_DOCUMENT_MESSAGES, size // MIN_MESSAGE_BYTES + FREE_MESSAGES)


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
            values = sums(values, key)
        columns[key] = _floats(values)
    cls = msg_codec.generated_class(msg_type, definition)  # a document is decoded from its definitions
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
            msg = msg_codec.from_dict(unflatten(flat), msg_type, definition)
        except ValueError as error:
            raise ValueError('message %d: %s' % (i, error))
        if stamps == HEADER_STAMP:
            stamp = msg.header.stamp.to_sec()
        else:
            stamp = stamps[i]
        records.append(Record(stamp, topic, msg, connection=connection))
    return records
