"""Window records out to other tools: one JSON-lines file, one rosbag, one MCAP file, one CSV per topic, or the
camera frames as PNG/JPEG files (``cclog export``).

Each writer takes records in stamp order and returns the files it wrote; every file is written atomically
(``safe_files.AtomicFile``). Pure.
"""
import collections
import csv
import io
import itertools
import json
import math
import os
import re

import numpy

from cc_log.storage import log_format
from cc_log.base import msg_codec, raw_message, safe_files
from cc_log.storage.formats import bag_lz4
from cc_log.storage.formats.bag_lz4 import to_bag  # noqa: F401  (export.to_bag: --to bag)
from cc_log.storage.bag import bag_writer
from cc_log.base.safe_files import AtomicFile
from cc_log.base.safe_input import printable

BAG_COMPRESSIONS = bag_writer.COMPRESSIONS
MAX_CSV_NAME = 100  # characters of a topic name kept in its CSV file's name


def plain(value):
    """JSON-safe copy: numpy numbers to Python, NaN/inf to None, tuples to lists."""
    if isinstance(value, dict):
        return {str(key): plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(item) for item in value]
    if hasattr(value, 'tolist') and not isinstance(value, (str, bytes)):
        return plain(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def record_row(record, path=None):
    """``{"stamp", "topic", "type", "msg"[, "file"]}`` of one record (the JSON line of ``cat`` and ``jsonl``)."""
    row = collections.OrderedDict([('stamp', record.stamp), ('topic', record.topic),
                                   ('type', record.msg._type), ('msg', msg_codec.to_dict(record.msg))])
    if path is not None:
        row['file'] = path
    return row


def to_jsonl(records, out):
    """One JSON line per record into the file ``out`` (replaced); ``[out]``."""
    with AtomicFile(out, overwrite=True, text=True) as stream:
        for record in records:
            stream.write(json.dumps(plain(record_row(record)), allow_nan=False) + '\n')
    return [out]


MCAP_COMPRESSIONS = ('zstd', 'lz4', 'none')
#: The one line when the optional MCAP library is missing.
MCAP_MISSING = ('--to mcap needs the Python package mcap (an optional extra): /usr/bin/python3 -m pip install '
                '--break-system-packages mcap mcap-ros1-support')
#: The name of the MCAP Metadata record of each window exported.
MCAP_WINDOW_METADATA = 'cc_log.window'


def default_mcap_compression():
    """``zstd`` when the ``zstandard`` package imports (python3-zstandard), else ``lz4``."""
    try:
        import zstandard  # noqa: F401
    except ImportError:
        return 'lz4'
    return 'zstd'


def mcap_window_metadata(path, metadata):
    """The metadata of the window whose own file is ``path`` as MCAP Metadata (``{str: str}``): every key, a
    string as it is and anything else as JSON, plus ``file`` (the file's name) and ``scores`` (the triggers'
    scores, JSON)."""
    result = {'file': os.path.basename(path),
              'scores': json.dumps([plain(t.get('score')) for t in metadata.get('triggers') or []
                                    if isinstance(t, dict)])}
    for key, value in metadata.items():
        result[str(key)] = value if isinstance(value, str) else json.dumps(plain(value), sort_keys=True)
    return result


def to_mcap(records, out, compression=None, progress=None, windows=()):
    """The records as one MCAP file ``out`` (replaced) in its ROS 1 profile, for Foxglove, PlotJuggler and the
    ``mcap`` tools: one ``ros1msg`` schema per message type (its full definition), one ``ros1`` channel per
    topic (metadata ``md5sum``, ``callerid`` and ``latching`` where the window kept them), each message as its
    serialized bytes at its stamp (log and publish time). ``windows``: ``[(path, metadata)]`` of the windows
    exported, each written as a Metadata record ``cc_log.window`` (``mcap_window_metadata``) and its metadata
    as a JSON Attachment ``<file>.json`` at the window's start. ``compression``: chunks ``zstd``, ``lz4`` or
    ``none`` (None: ``default_mcap_compression``); ``progress()`` after each record; ``[out]``.
    ValueError(``MCAP_MISSING``) without the ``mcap`` package, and when a topic holds messages of two types."""
    try:
        from mcap.writer import CompressionType, Writer
    except ImportError:
        raise ValueError(MCAP_MISSING)
    compression = compression or default_mcap_compression()
    if compression not in MCAP_COMPRESSIONS:
        raise ValueError('compression: MCAP chunks are %s, not %s' % (', '.join(MCAP_COMPRESSIONS), compression))
    if compression == 'zstd' and default_mcap_compression() != 'zstd':
        raise ValueError('compression: zstd needs the Python package zstandard (Debian: python3-zstandard)')
    headers = bag_lz4.connection_headers(records)
    with AtomicFile(out, overwrite=True) as stream:
        writer = Writer(stream, compression=getattr(CompressionType, compression.upper()))
        writer.start(profile='ros1', library='cc_log')
        schemas, channels = {}, {}
        for topic, header in headers.items():
            text = raw_message.text_header(header)
            if text['type'] not in schemas:
                schemas[text['type']] = writer.register_schema(name=text['type'], encoding='ros1msg',
                                                               data=text['message_definition'].encode('utf-8'))
            metadata = {'md5sum': text['md5sum']}
            if 'callerid' in text:
                metadata['callerid'] = text['callerid']
            if 'latching' in text:
                metadata['latching'] = 'true' if raw_message.is_latched(text) else 'false'
            channels[topic] = writer.register_channel(topic=topic, message_encoding='ros1',
                                                      schema_id=schemas[text['type']], metadata=metadata)
        for sequence, record in enumerate(records):
            topic, secs, nsecs, data = bag_lz4.bag_message(record)
            stamp = secs * 1000000000 + nsecs
            writer.add_message(channel_id=channels[topic], log_time=stamp, publish_time=stamp, sequence=sequence,
                               data=data)
            if progress:
                progress()
        for path, metadata in windows:
            writer.add_metadata(MCAP_WINDOW_METADATA, mcap_window_metadata(path, metadata))
            secs, nsecs = bag_lz4.bag_stamp(metadata['start']) if _is_stamp(metadata.get('start')) else (0, 0)
            writer.add_attachment(create_time=secs * 1000000000 + nsecs, log_time=secs * 1000000000 + nsecs,
                                  name=os.path.basename(path) + '.json', media_type='application/json',
                                  data=json.dumps(plain(metadata), sort_keys=True, allow_nan=False).encode('utf-8'))
        writer.finish()
    return [out]


def _is_stamp(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value >= 0


def _csv_cell(value):
    if isinstance(value, (list, dict)):
        return json.dumps(value, allow_nan=False)
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        return repr(value)
    return value


def _flatten(row, prefix, out):
    """Dotted columns of a message dict; a time is one float column plus its ``.secs`` and ``.nsecs``."""
    for name, value in row.items():
        if isinstance(value, dict) and value and not set(value) == {'secs', 'nsecs'}:
            _flatten(value, prefix + name + '.', out)
        elif isinstance(value, dict):
            out[prefix + name] = value['secs'] + value['nsecs'] * 1e-9 if value else value
            out[prefix + name + '.secs'] = value['secs']
            out[prefix + name + '.nsecs'] = value['nsecs']
        else:
            out[prefix + name] = value
    return out


def csv_file_name(topic):
    """``/base/odom`` -> ``base_odom``: the topic's ASCII letters, digits, ``-`` and ``_``, anything else (``/``,
    ``.``, control characters) as ``_``, at most ``MAX_CSV_NAME`` characters; ``root`` for ``/`` (no extension)."""
    name = ''.join(c if c.isascii() and (c.isalnum() or c in '-_') else '_' for c in str(topic).strip('/'))
    return name[:MAX_CSV_NAME] or 'root'


def to_csv(records, directory):
    """One CSV per topic in ``directory`` (``stamp`` then the message's dotted fields); the files written, in the
    order of the sorted topics. A file takes the first free name of ``<csv_file_name>.csv``, ``..._1.csv``, ...:
    two topics of one name (``/a/b``, ``/a_b``) get a file each, and no file already there is overwritten."""
    by_topic = collections.OrderedDict()
    for record in records:
        by_topic.setdefault(record.topic, []).append(record)
    files = []
    for topic in sorted(by_topic):
        topic_records = by_topic[topic]
        rows = [_flatten(msg_codec.to_dict(record.msg), '', collections.OrderedDict()) for record in topic_records]
        fields = list(collections.OrderedDict.fromkeys(key for row in rows for key in row))
        base = csv_file_name(topic)
        names = log_format.final_names(directory, base, '.csv')
        first = next(names)
        target = AtomicFile(first, text=True, newline='', names=itertools.chain([first], names))
        with target as stream:
            writer = csv.writer(stream)
            writer.writerow(['stamp'] + fields)
            for record, row in zip(topic_records, rows):
                writer.writerow([repr(float(record.stamp))] + [_csv_cell(row.get(field, '')) for field in fields])
        files.append(target.path)
    return files


# -- camera frames ----------------------------------------------------------------------------------------

IMAGE_TYPES = ('sensor_msgs/Image', 'sensor_msgs/CompressedImage')
PNG_MAGIC = b'\x89PNG\r\n\x1a\n'
JPEG_MAGIC = b'\xff\xd8\xff'
#: The one line when Pillow, which writes the PNG files, is missing.
PNG_MISSING = '--to png needs Pillow, a dependency of cc_log: apt install python3-pil'
#: sensor_msgs/Image encoding -> (samples per pixel, sample type, channel order for PNG)
IMAGE_ENCODINGS = {
    'rgb8': (3, 'u1', None), 'bgr8': (3, 'u1', [2, 1, 0]), 'rgba8': (4, 'u1', None),
    'bgra8': (4, 'u1', [2, 1, 0, 3]), 'mono8': (1, 'u1', None), '8UC1': (1, 'u1', None),
    'mono16': (1, 'u2', None), '16UC1': (1, 'u2', None), '32FC1': (1, 'f4', None)}


def png_file(pixels):
    """The bytes of a PNG of ``pixels`` (height x width [x channels] uint8 or uint16; 1, 3 or 4 channels:
    grey, RGB, RGBA; uint16 as 16-bit grey), as Pillow (python3-pil) writes it. ValueError without Pillow."""
    try:
        from PIL import Image
    except ImportError:
        raise ValueError(PNG_MISSING)
    pixels = numpy.ascontiguousarray(pixels, dtype=numpy.uint16 if pixels.dtype.itemsize == 2 else numpy.uint8)
    stream = io.BytesIO()
    Image.fromarray(pixels).save(stream, format='PNG')
    return stream.getvalue()


def image_pixels(msg):
    """The pixels of a sensor_msgs/Image as an array for ``png_file``: rgb8/bgr8/rgba8/bgra8 as RGB(A), mono8
    as grey, 16UC1/mono16 as 16-bit grey with their values (millimetres of depth), 32FC1 depth (metres) as
    16-bit millimetres (NaN and below 0: 0). ValueError('<what is wrong>') for another encoding or a size that
    does not fit the data."""
    if msg.encoding not in IMAGE_ENCODINGS:
        raise ValueError('encoding %s is not supported' % (printable(msg.encoding[:40]) or '(empty)'))
    channels, sample, order = IMAGE_ENCODINGS[msg.encoding]
    size = channels * int(sample[1:])
    data = msg.data if isinstance(msg.data, bytes) else bytes(bytearray(msg.data))
    if not msg.width or not msg.height or msg.step < msg.width * size or len(data) < msg.step * msg.height:
        raise ValueError('%dx%d %s with step %d does not fit %d bytes of data'
                         % (msg.width, msg.height, printable(msg.encoding), msg.step, len(data)))
    rows = numpy.frombuffer(data, 'u1', msg.step * msg.height).reshape(msg.height, msg.step)
    dtype = numpy.dtype(sample).newbyteorder('>' if msg.is_bigendian else '<')
    pixels = numpy.ascontiguousarray(rows[:, :msg.width * size]).view(dtype).reshape(msg.height, msg.width, channels)
    if order is not None:
        pixels = pixels[:, :, order]
    if sample == 'f4':
        millimetres = numpy.nan_to_num(pixels.astype(numpy.float64) * 1000.0, nan=0.0, posinf=65535.0, neginf=0.0)
        pixels = numpy.clip(numpy.round(millimetres), 0, 65535).astype(numpy.uint16)
    return pixels[:, :, 0] if channels == 1 else pixels


def frame_file(msg):
    """``(bytes, extension)`` of one camera frame: an Image as PNG, a CompressedImage as its own JPEG or PNG
    bytes (compressedDepth: the PNG after its 12-byte header). ValueError('<what is wrong>') otherwise."""
    if msg._type == 'sensor_msgs/Image':
        return png_file(image_pixels(msg)), 'png'
    data = msg.data if isinstance(msg.data, bytes) else bytes(bytearray(msg.data))
    for offset in (0, 12):
        if data[offset:offset + len(PNG_MAGIC)] == PNG_MAGIC:
            return data[offset:], 'png'
        if data[offset:offset + len(JPEG_MAGIC)] == JPEG_MAGIC:
            return data[offset:], 'jpg'
    raise ValueError('compressed format %s is neither JPEG nor PNG' % (printable(msg.format[:40]) or '(empty)'))


def frame_name(topic, stamp, extension):
    """``/camera/image_raw`` at 1600000020.18 -> ``camera_image_raw_1600000020.180000.png``: letters, digits,
    ``_`` and ``-`` of the topic (never a path separator), at most 100 of them."""
    stem = re.sub(r'[^A-Za-z0-9_-]+', '_', topic).strip('_')[:100] or 'topic'
    return '%s_%.6f.%s' % (stem, stamp, extension)


def to_frames(records, directory, skipped=None, progress=None):
    """Every sensor_msgs/Image and CompressedImage of ``records`` as one PNG or JPEG file in ``directory``
    (created when missing; ``frame_name``; an existing file is never overwritten: the next free ``-2``,
    ``-3``... name is taken). Frames that cannot be written are counted in the dict ``skipped`` ({reason:
    count}; None: ValueError naming the frame); ``progress()`` after each frame; the files written."""
    files = []
    for record in records:
        if raw_message.type_of(record) not in IMAGE_TYPES:
            continue
        if progress:
            progress()
        try:
            data, extension = frame_file(raw_message.decoded(record).msg)
        except ValueError as error:
            if skipped is None:
                raise ValueError('%s at %.6f: %s' % (printable(record.topic), record.stamp, error))
            skipped[str(error)] = skipped.get(str(error), 0) + 1
            continue
        if not files:
            safe_files.make_dirs(directory)
        path = safe_files.inside(directory, frame_name(record.topic, record.stamp, extension), 'topic')
        stem = path[:-len(extension) - 1]
        target = AtomicFile(path, names=itertools.chain([path], ('%s-%d.%s' % (stem, n, extension)
                                                                 for n in itertools.count(2))))
        with target as stream:
            stream.write(data)
        files.append(target.path)
    return files
