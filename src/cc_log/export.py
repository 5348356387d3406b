"""Window records out to other tools: one JSON-lines file, one rosbag, or one CSV per topic (``cclog export``).

Each writer takes records in stamp order and returns the files it wrote; every file is written atomically
(``safe_files.AtomicFile``). Pure.
"""
import collections
import csv
import json
import math
import os

from . import log_format, msg_codec
from .formats import bag_lz4, bag_writer
from .safe_files import AtomicFile

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


def to_bag(records, out, compression='lz4', progress=None, names=None):
    """The records as one rosbag ``out`` (replaced), each at its stamp, as rosbag writes them
    (``formats.bag_writer``; chunks lz4, bz2 or none): a record read with its serialized bytes and connection
    header (from a bag-lz4 window) keeps them, the publisher's ``callerid`` and ``latching`` too, so ``rosbag
    play`` latches what was latched. ``progress()`` after each record; ``[out]``. ValueError when a topic
    holds messages of two types (a bag has one connection per topic). ``names``: the paths to try in order
    instead of replacing ``out`` (the first free one is taken, nothing is overwritten)."""
    headers = bag_lz4.connection_headers(records)

    def messages():
        for record in records:
            yield bag_lz4.bag_message(record)
            if progress:
                progress()

    target = AtomicFile(out, names=names, overwrite=names is None)
    with target as stream:
        bag_writer.write_bag(stream, messages(), headers, compression=compression)
    return [target.path]


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
        target = AtomicFile(os.path.join(directory, base + '.csv'), text=True, newline='',
                            names=log_format.final_names(directory, base, '.csv'))
        with target as stream:
            writer = csv.writer(stream)
            writer.writerow(['stamp'] + fields)
            for record, row in zip(topic_records, rows):
                writer.writerow([repr(float(record.stamp))] + [_csv_cell(row.get(field, '')) for field in fields])
        files.append(target.path)
    return files
