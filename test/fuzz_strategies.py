"""Hypothesis strategies of hostile inputs, one per kind of input cc_log reads (issue 42), for
``test_fuzz_readers.py``.

- ``bags()``: rosbag 2.0 files built from valid bags (chunks of every compression: none, bz2, lz4; plain
  bags and cc_log's bag-lz4 windows), then mutated record by record: header fields (chunk ``size`` and
  ``compression``, ``count``, ``conn``, ``op``, the positions in the bag header, a connection's ``type``,
  ``md5sum`` and ``message_definition``), declared lengths of records inside chunks, chunks replaced by
  bombs (bz2 or LZ4 that expand 250 to 1000 times), records dropped, repeated or swapped, bytes flipped and
  files cut off.
- ``json_xz_documents()``: a valid json-xz window whose JSON is mutated (any value at any place replaced by
  a hostile one: huge or negative counts, other types, deep nesting) and compressed again; or xz of
  arbitrary text; or an xz bomb.
- ``model_documents()``, ``envelope_documents()``, ``vector_documents()``: model, envelope and feature vector
  JSON mutated the same way.
- ``config_documents()``: configuration YAML: every section and option key, triggers of every kind, with
  hostile values, and YAML text of its own (tags, aliases, anchors).
- ``option_values()``: any value a parameter, a flag or a configuration key may hold.
- ``diagnostics()``: ``/diagnostics`` statuses as ``cclog top`` hears them (any types, any lengths).
- ``names()``: file and topic names.

Every generated file is at most ``MAX_INPUT_BYTES`` (1 MB). Pure data: nothing here reads cc_log's readers.
"""
import bz2
import collections
import functools
import json
import lzma
import math
import os
import struct
import tempfile

import yaml
from hypothesis import strategies as st

MAX_INPUT_BYTES = 1 << 20
_U32 = struct.Struct('<I')
_MAGIC = b'#ROSBAG V2.0\n'

# -- values ------------------------------------------------------------------------------------------------

_EDGE_INTS = [0, 1, -1, 2, 255, 256, 65535, 2 ** 31 - 1, 2 ** 31, 2 ** 32 - 1, 2 ** 32, 2 ** 53 + 1, 2 ** 63,
              2 ** 64, -2 ** 63, 10 ** 9, 10 ** 30, 10 ** 400]
_EDGE_TEXTS = ['', ' ', '0', '-0', '1e308', '1e400', '-1e400', 'nan', 'NaN', 'inf', '-inf', 'Infinity', '5m', '250ms',
               '2h', '1.5GiB', '64MB', '1G', '500M', '0x10', '1_000', '\x00', '\n', '\u202e', '\x1b[2J', '/odom',
               '//', '/a/../..', 're:(a+)+', 're:.*', 're:[', 'topic:Hz', '/x:1e9', '/x:-1', '/x:0', 'true', 'no',
               '~', '~a', '*', 'a' * 300, '\U0001f600', '../../etc/passwd', 'bag-lz4', 'json-xz', 'ocsvm']


def _deep(depth):
    value = 0
    for _ in range(depth):
        value = [value]
    return value


scalars = st.one_of(
    st.none(), st.booleans(), st.sampled_from(_EDGE_INTS), st.integers(),
    st.floats(allow_nan=True, allow_infinity=True), st.sampled_from(_EDGE_TEXTS), st.text(max_size=40))

#: Any value of a YAML or JSON document: scalars, lists, mappings, deep nesting.
values = st.one_of(
    scalars,
    st.recursive(scalars, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.text(max_size=10), inner, max_size=4), max_leaves=12),
    st.sampled_from([99, 101, 150]).map(_deep))


def option_values():
    """Any value an option may be given (a parameter, a flag's text, a configuration key)."""
    return values


# -- JSON documents mutated --------------------------------------------------------------------------------

def _places(document, path=()):
    """Every path (tuple of keys and indexes) into ``document``, itself first."""
    yield path
    if len(path) > 12:  # not into deep nesting a mutation put there
        return
    if isinstance(document, dict):
        for key, value in document.items():
            yield from _places(value, path + (key,))
    elif isinstance(document, list):
        for index, value in enumerate(document[:50]):  # the first items of long lists
            yield from _places(value, path + (index,))


def _replace(document, path, value):
    if not path:
        return value
    copy = dict(document) if isinstance(document, dict) else list(document)
    copy[path[0]] = _replace(copy[path[0]], path[1:], value)
    return copy


def _dropped(document, path):
    if not path:
        return document
    copy = dict(document) if isinstance(document, dict) else list(document)
    if len(path) == 1:
        copy.pop(path[0])
    else:
        copy[path[0]] = _dropped(copy[path[0]], path[1:])
    return copy


@st.composite
def mutated_json(draw, document):
    """``document`` with 1 to 4 places replaced by hostile values or removed."""
    places = list(_places(document))
    for _ in range(draw(st.integers(1, 4))):
        path = draw(st.sampled_from(places))
        if path and draw(st.integers(0, 4)) == 0:
            document = _dropped(document, path)
        else:
            document = _replace(document, path, draw(values))
        places = list(_places(document))
    return document


def _dump(document):
    """JSON text of any value (NaN and infinities as Python writes them, huge ints written out)."""
    try:
        return json.dumps(document)
    except (ValueError, RecursionError):
        return '[]'


@st.composite
def json_texts(draw, document):
    """UTF-8 JSON text of ``document`` mutated; sometimes the text itself cut off or spliced."""
    text = _dump(draw(mutated_json(document))).encode('utf-8', 'surrogatepass')
    how = draw(st.integers(0, 5))
    if how == 0:
        text = text[:draw(st.integers(0, len(text)))]
    elif how == 1:
        where = draw(st.integers(0, len(text)))
        text = text[:where] + draw(st.binary(max_size=20)) + text[where:]
    return text[:MAX_INPUT_BYTES]


# -- json-xz windows ---------------------------------------------------------------------------------------

def _odometry_records(n=30, start=1432235498.0):
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Imu
    from cc_log.base.records import Record
    out = []
    for i in range(n):
        msg = Odometry() if i % 3 else Imu()
        msg.header.seq = i
        msg.header.stamp.secs, msg.header.stamp.nsecs = int(start) + i // 10, (i % 10) * 100000000
        if i % 3:
            msg.header.frame_id = 'odom'
            msg.pose.pose.position.x = 0.1 * i
            msg.twist.twist.linear.x = math.sin(i)
        else:
            msg.linear_acceleration.z = 9.8 + 0.01 * i
        out.append(Record(msg.header.stamp.to_sec(), '/odom' if i % 3 else '/imu', msg))
    return out


@functools.lru_cache(maxsize=None)
def valid_window(fmt, precision=False):
    """``(file name, bytes)`` of a valid window file of format ``fmt`` (json-xz: with or without a precision)."""
    from cc_log.base.records import LogWindow, Trigger
    from cc_log.storage.log_format import write_window
    records = _odometry_records()
    with tempfile.TemporaryDirectory() as directory:
        path, _ = write_window(LogWindow(records, [Trigger(records[3].stamp, 'classifier', -1.5)]), directory, fmt,
                               {'precision': {'pose.pose.position.*': 1e-3}} if precision else None)
        with open(path, 'rb') as stream:
            return os.path.basename(path), stream.read()


@functools.lru_cache(maxsize=None)
def _xz_bomb():
    """An xz stream of 200 MB of spaces (about 30 kB)."""
    compressor = lzma.LZMACompressor(preset=1)
    block = b' ' * (1 << 20)
    return b''.join(compressor.compress(block) for _ in range(200)) + compressor.flush()


@st.composite
def json_xz_documents(draw):
    """Bytes of a json-xz window file: a valid window's document mutated and compressed again, xz of arbitrary
    text, an xz bomb, or a valid file's bytes flipped."""
    _, original = valid_window('json-xz', draw(st.booleans()))
    how = draw(st.integers(0, 9))
    if how == 0:
        return lzma.compress(draw(st.binary(max_size=200)), preset=0)
    if how == 1:
        return _xz_bomb() + draw(st.sampled_from([b'', lzma.compress(b'{}')]))
    if how == 2:
        data = bytearray(original)
        for where, xor in draw(st.lists(st.tuples(st.floats(0, 1), st.integers(1, 255)), min_size=1, max_size=4)):
            data[min(len(data) - 1, int(len(data) * where))] ^= xor
        return bytes(data)
    document = json.loads(lzma.decompress(original).decode('utf-8'))
    text = draw(json_texts(document))
    return lzma.compress(text, preset=draw(st.sampled_from([0, 6])))


# -- models, envelopes, feature vectors --------------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def valid_model():
    """The document of a small valid model (``AnomalyModel.to_dict``)."""
    import numpy as np
    from cc_log.learning.model import AnomalyModel
    from cc_log.features import FeatureConfig, vector_length, vector_names
    config = FeatureConfig('motion', '5s')
    d = vector_length(config)
    rng = np.random.default_rng(0)
    model = AnomalyModel(config, rng.normal(size=d), rng.uniform(0.5, 2, d), 'ocsvm',
                         {'support_vectors': rng.normal(size=(4, d)), 'dual_coef': [0.25] * 4, 'intercept': -0.5,
                          'gamma': 0.1}, threshold=-0.1, names=vector_names(config))
    return json.loads(json.dumps(model.to_dict()))


@functools.lru_cache(maxsize=None)
def valid_envelope():
    """The document of a small valid envelope (``Envelope.to_dict``) with its joint check and local part."""
    import numpy as np
    from cc_log.learning.envelope import learn
    from cc_log.features.envelope import ENVELOPE_COLUMNS
    rng = np.random.default_rng(0)
    envelope = learn([rng.uniform(0.1, 1.0, size=(60, len(ENVELOPE_COLUMNS)))], '/odom', 10, 5, 60.0)
    assert envelope.joint is not None and envelope.local is not None
    return json.loads(json.dumps(envelope.to_dict()))


@functools.lru_cache(maxsize=None)
def valid_vector():
    """The document of a feature vector file (``learning.write_vector``)."""
    from cc_log.features import FeatureConfig, vector_length
    config = FeatureConfig('motion', '5s')
    return {'config': config.to_dict(), 'features': [0.5] * vector_length(config), 'stamp': 1432235498.5}


def model_documents():
    """Bytes of a model file: a valid model's JSON mutated, or any bytes (a pickle's first byte too)."""
    return st.one_of(st.deferred(lambda: json_texts(valid_model())), st.deferred(lambda: json_texts(valid_model())),
                     st.binary(max_size=100), st.just(b'\x80\x04K\x01.'))


def envelope_documents():
    """Bytes of an envelope file: a valid envelope's JSON mutated."""
    return st.deferred(lambda: json_texts(valid_envelope()))


def vector_documents():
    """Bytes of a feature vector file: a valid one's JSON mutated."""
    return st.deferred(lambda: json_texts(valid_vector()))


# -- configurations ----------------------------------------------------------------------------------------

@st.composite
def config_documents(draw):
    """Bytes of a configuration YAML file: sections and keys of the configuration (and others), hostile values,
    triggers of every kind; or YAML text with tags, anchors and aliases."""
    from cc_log.logger import options
    from cc_log import triggers
    sections = options.sections()
    how = draw(st.integers(0, 5))
    if how == 0:
        return draw(st.sampled_from([
            b'a: !!python/object/apply:os.system ["touch x"]\n', b'&a [*a]\n', b'a: &x [1]\nb: *x\n',
            b'a: &a [' + b'*a,' * 50 + b']\n', b'{a: 1, a: 2}\n', b'windows: {pre: !!float nan}\n',
            b'\xff\xfe\x00', b'%YAML 9.9\n---\n', b'---\n...\n---\n', b'? [1]\n: 2\n',
            b'x: &a ["lol","lol"]\ny: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\nz: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]\n'
            b'w: [*c,*c,*c,*c,*c,*c,*c,*c,*c]\n']))
    document = {}
    for top in draw(st.lists(st.sampled_from(list(sections) + ['unknown']), max_size=5, unique=True)):
        subs = sections.get(top) or []
        if subs and draw(st.integers(0, 4)):
            document[top] = {key: draw(values) for key in draw(st.lists(st.sampled_from(subs + ['bogus']),
                                                                        max_size=4, unique=True))}
        elif top == 'triggers':
            entries = []
            for _ in range(draw(st.integers(0, 3))):
                kind = draw(st.sampled_from(sorted(triggers.kinds()) + ['nope']))
                known = list(triggers.get(kind).config_keys) if kind in triggers.kinds() else []
                entry = {'kind': kind, 'name': draw(st.sampled_from(['r', 'a b', '', 5]))}
                for key in draw(st.lists(st.sampled_from(known + ['pre', 'post', 'keep', 'x']), max_size=4,
                                         unique=True)):
                    entry[key] = draw(values)
                entries.append(entry if draw(st.integers(0, 5)) else draw(values))
            document[top] = entries
        else:
            document[top] = draw(values)
    try:
        text = yaml.safe_dump(document, allow_unicode=draw(st.booleans())).encode('utf-8', 'surrogatepass')
    except (yaml.YAMLError, RecursionError, UnicodeEncodeError):
        text = b'{}'
    if how == 1:
        where = draw(st.integers(0, len(text)))
        text = text[:where] + draw(st.binary(max_size=10)) + text[where:]
    return text[:MAX_INPUT_BYTES]


# -- /diagnostics ------------------------------------------------------------------------------------------

Status = collections.namedtuple('Status', 'name level message values')
KeyValue = collections.namedtuple('KeyValue', 'key value')

_DIAGNOSTIC_TEXT = st.one_of(st.text(max_size=30), st.sampled_from(_EDGE_TEXTS), st.text(min_size=2000, max_size=3000),
                             st.integers(), st.none(), st.binary(max_size=10))
_NODE_NAMES = st.one_of(st.sampled_from(['cc_log: /smart', 'cc_log: /a', 'cc_log: ', 'cc_log:', 'other']),
                        st.text(max_size=20).map(lambda t: 'cc_log: ' + t), _DIAGNOSTIC_TEXT)
_KEYS = st.one_of(st.sampled_from(['messages seen', 'messages lost', 'topic /odom Hz', 'topic /odom MB/s',
                                   'topic /odom dropped', 'topic  Hz', 'topic Hz', 'windows written']),
                  _DIAGNOSTIC_TEXT)


@st.composite
def diagnostics(draw):
    """A list of batches ``(statuses, now)`` of ``/diagnostics`` as ``cclog top`` hears them: names of cc_log
    nodes and others, any level, any message, many values of any types, times that go back and jump."""
    batches, now = [], draw(st.floats(0, 1e9))
    for _ in range(draw(st.integers(1, 4))):
        statuses = []
        for _ in range(draw(st.integers(0, 5))):
            pairs = [KeyValue(draw(_KEYS), draw(_DIAGNOSTIC_TEXT)) for _ in range(draw(st.integers(0, 6)))]
            if draw(st.integers(0, 6)) == 0:
                pairs = pairs * 200  # more values than MAX_VALUES
            level = draw(st.one_of(st.integers(-300, 300), st.binary(max_size=2), st.none()))
            statuses.append(Status(draw(_NODE_NAMES), level, draw(_DIAGNOSTIC_TEXT), pairs))
        if draw(st.integers(0, 5)) == 0:
            statuses = statuses + [Status('cc_log: %d' % i, 0, '', []) for i in range(100)]  # more than MAX_NODES
        near = st.floats(now - 100, now + 100) if math.isfinite(now) else st.just(0.0)
        now = draw(st.one_of(st.just(now), near, st.floats(allow_nan=True)))
        batches.append((statuses, now))
    return batches


# -- names -------------------------------------------------------------------------------------------------

_NAME_PARTS = ['cc_log_', 'run_', '20150521T191138.027Z', '20150521T191138Z', '_classifier', '_manual-2', '_part3',
               '+numeric_1', '+r', '.001', '.000', '.999', '.bag', '.json.xz', '.tmp-123', '.tmp-', '.1', '\n', '/',
               '..', '_', '+', '.', 'context_', '\x00'[:0]]


def names():
    """File names: pieces of cc_log's own names in any order, and any text."""
    return st.one_of(st.lists(st.sampled_from(_NAME_PARTS), max_size=8).map(''.join),
                     st.text(max_size=60), st.text(min_size=200, max_size=400).map(lambda t: 'cc_log_' + t + '.bag'))


# -- rosbag 2.0 files --------------------------------------------------------------------------------------

def _fields(header):
    """[(name, value)] of a record header (a valid one)."""
    out, pos = [], 0
    while pos < len(header):
        size, = _U32.unpack_from(header, pos)
        name, _, value = header[pos + 4:pos + 4 + size].partition(b'=')
        out.append((name, value))
        pos += 4 + size
    return out


def header_bytes(fields):
    """A record header of ``[(name, value)]``."""
    return b''.join(_U32.pack(len(name) + 1 + len(value)) + name + b'=' + value for name, value in fields)


def record_bytes(fields, data):
    """A rosbag record: its header of ``fields`` and its data."""
    header = header_bytes(fields)
    return _U32.pack(len(header)) + header + _U32.pack(len(data)) + data


def parse_records(data, pos=0):
    """``[[fields, data]]`` of the records of a valid bag (from ``pos``: after the magic)."""
    out = []
    while pos + 8 <= len(data):
        size, = _U32.unpack_from(data, pos)
        header = data[pos + 4:pos + 4 + size]
        length, = _U32.unpack_from(data, pos + 4 + size)
        body = data[pos + 8 + size:pos + 8 + size + length]
        out.append([_fields(header), body])
        pos += 8 + size + length
    return out


@functools.lru_cache(maxsize=None)
def valid_bags():
    """``[(name, bytes)]``: plain bags of two topics in several chunks, one per compression (none, bz2, lz4), and
    cc_log's bag-lz4 window."""
    import rosbag
    out = []
    with tempfile.TemporaryDirectory() as directory:
        for compression in ('none', 'bz2', 'lz4'):
            path = os.path.join(directory, '%s.bag' % compression)
            with rosbag.Bag(path, 'w', compression=compression, chunk_threshold=2000) as bag:
                for record in _odometry_records():
                    bag.write(record.topic, record.msg, _time(record.stamp))
            with open(path, 'rb') as stream:
                out.append(('plain_%s.bag' % compression, stream.read()))
    out.append(valid_window('bag-lz4'))
    return out


def _time(stamp):
    import rospy
    return rospy.Time.from_sec(stamp)


@functools.lru_cache(maxsize=None)
def _bombs():
    """Chunk data that expands far beyond its size: bz2 of 64 MiB and LZ4 (roslz4) of 16 MiB of zeros."""
    import roslz4
    zeros = b'\0' * (1 << 20)
    compressor = bz2.BZ2Compressor(9)
    bz2_bomb = b''.join(compressor.compress(zeros) for _ in range(64)) + compressor.flush()
    return {b'bz2': bz2_bomb, b'lz4': roslz4.compress(zeros * 16)}


_FIELD_NAMES = [b'op', b'size', b'compression', b'count', b'conn', b'ver', b'chunk_pos', b'index_pos', b'conn_count',
                b'chunk_count', b'time', b'start_time', b'end_time', b'topic', b'x']
_CONNECTION_FIELDS = [b'topic', b'type', b'md5sum', b'message_definition', b'callerid', b'latching']
_U32_EDGES = [0, 1, 2, 7, 8, 0x7fffffff, 0x80000000, 0xffffffff, 1 << 28, (1 << 28) + 1, 1 << 24]
_FIELD_VALUES = [b'', b'none', b'bz2', b'lz4', b'zstd', b'\x02', b'\x05', b'\x06', b'\x07', b'\x04', b'\x03', b'\xff',
                 b'nav_msgs/Odometry', b'sensor_msgs/Imu', b'../x/Y', b'a/b/c', b'std_msgs/String', b'*',
                 b'0' * 32, b'string __import__("os").system("touch pwned")\n',
                 b'Header header\nfloat64[1000000000] x\n', b'MSG: a/B\nB b\n', b'uint8[] data\n', b'1',
                 b'\x00' * 8, b'\xff' * 8]


def _u32_values():
    return st.one_of(st.sampled_from(_U32_EDGES), st.integers(0, 0xffffffff)).map(_U32.pack)


def _field_values():
    return st.one_of(_u32_values(), st.sampled_from(_FIELD_VALUES), st.binary(max_size=16),
                     st.integers(0, 2 ** 64 - 1).map(lambda v: struct.pack('<Q', v)))


@st.composite
def _mutate_fields(draw, fields, names):
    fields = list(fields)
    how = draw(st.integers(0, 4))
    if how == 0 and fields:
        del fields[draw(st.integers(0, len(fields) - 1))]
    elif how == 1:
        fields.append((draw(st.sampled_from(names)), draw(_field_values())))
    else:
        name = draw(st.sampled_from([n for n, _ in fields] + names))
        value = draw(_field_values())
        fields = [(n, value if n == name else v) for n, v in fields]
        if name not in [n for n, _ in fields]:
            fields.append((name, value))
    return fields


@st.composite
def _mutate_record(draw, records):
    index = draw(st.integers(0, len(records) - 1))
    fields, data = records[index]
    ops = dict(fields).get(b'op', b'')
    how = draw(st.integers(0, 6))
    if how <= 1:  # the record's header fields (chunk size and compression, counts, positions, op)
        records[index] = [draw(_mutate_fields(fields, _FIELD_NAMES)), data]
    elif how == 2 and ops == b'\x07':  # a connection's type, md5sum, definition (in its data)
        records[index] = [fields, header_bytes(draw(_mutate_fields(_fields(data), _CONNECTION_FIELDS)))]
    elif how == 3 and ops == b'\x05':  # a chunk: its records' declared lengths (a u32 anywhere in its data)
        if data:
            where = draw(st.integers(0, max(0, len(data) - 4)))
            data = data[:where] + draw(_u32_values()) + data[where + 4:]
        records[index] = [fields, data[:len(records[index][1])]]
    elif how == 4 and ops == b'\x05':  # a chunk replaced by a bomb, declaring its size or not
        compression = draw(st.sampled_from([b'bz2', b'lz4']))
        bomb = _bombs()[compression]
        size = draw(st.sampled_from([len(bomb) * 1000, 1 << 24, 1 << 26, 0x7fffffff]))
        records[index] = [[(n, compression if n == b'compression' else _U32.pack(size) if n == b'size' else v)
                           for n, v in fields], bomb]
    elif how == 5:  # records dropped, repeated, swapped
        other = draw(st.integers(0, len(records) - 1))
        choice = draw(st.integers(0, 2))
        if choice == 0:
            del records[index]
        elif choice == 1:
            records.insert(other, records[index])
        else:
            records[index], records[other] = records[other], records[index]
    else:
        records[index] = [fields, data[:draw(st.integers(0, len(data)))]]
    return records


@st.composite
def bags(draw):
    """``(file name, bytes)`` of a rosbag 2.0 file: a valid bag (plain: compression none, bz2 or lz4; or a
    bag-lz4 window) with 1 to 3 record mutations, then maybe bytes flipped and the file cut off."""
    name, original = draw(st.sampled_from(valid_bags()))
    records = parse_records(original, len(_MAGIC))
    for _ in range(draw(st.integers(0, 3))):
        if not records:
            break
        records = draw(_mutate_record(records))
    data = bytearray(_MAGIC + b''.join(record_bytes(fields, body) for fields, body in records))
    for where, xor in draw(st.lists(st.tuples(st.floats(0, 1), st.integers(1, 255)), max_size=2)):
        data[min(len(data) - 1, int(len(data) * where))] ^= xor
    if draw(st.integers(0, 4)) == 0:
        data = data[:draw(st.integers(0, len(data)))]
    return name, bytes(data[:MAX_INPUT_BYTES])
