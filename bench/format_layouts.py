#!/usr/bin/env python3
"""Window file layouts on real odometry (and one LaserScan topic): size against row-per-message JSON, and the
cost of writing.

    source .catkin_ws/devel/setup.bash && /usr/bin/python3 bench/format_layouts.py [--window 300] [--quick]

For each bag's odometry topic (../shared/data/real/), the messages are cut into windows of ``--window``
messages (the unit cc_log writes) and, separately, taken as one window of the whole topic. Every layout is
LZMA-compressed (xz container) with each preset alone, and with preset 6 and the writer's LZMA2 options
(``6+opts``: ``json_xz.FILTER_OPTIONS``, what cc_log writes; ``bench/lzma_options.py`` compares option sets);
the table gives the summed file bytes and their share of
the uncompressed row-per-message JSON of the same messages (``msg_codec.row_json_bytes``), and the mean
milliseconds per window (building the document + compressing) on this machine.

Layouts:
  rows            row-per-message JSON lines (the paper's plain log), LZMA
  columns-v1      json-xz layout 1: column per field, constants once, arrays as a column of lists,
                  metadata + message definition included
  columns         the json-xz file as written (json_xz.encode, layout 2): as columns-v1, with slowly varying
                  columns (integers, positions, ...) as exact differences where json_xz.differences chooses
  columns-alldiff as columns, but every integer and finite-float column as differences (no choice)
  columns-elem    as columns, but fixed-size arrays split into one column per element
  columns-noconst as columns, without stating constant columns once
  lossy-4/5       json-xz with precision (opt-in, lossy): positions and linear velocity to 1e-4,
                  orientation and angular velocity to 1e-5 (LOSSY); the largest error per field is printed
  lossy-3/4       the same to 1e-3 and 1e-4
  bag-lz4         the bag-lz4 file (rosbag, LZ4 chunks), for reference (no preset)
  binary-floor    reference only, not a format: numeric fields as little-endian 64-bit arrays
                  (integers delta-coded), LZMA preset 9: roughly what a binary lossless coding reaches
"""
import argparse
import json
import lzma
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

import cc_log  # noqa: E402
from cc_log.base import msg_codec  # noqa: E402
from cc_log.storage.formats import json_rows, json_xz  # noqa: E402
from cc_log.base.records import Record  # noqa: E402

REAL = common.DATA

BAGS = [
    ('husky_outdoor_2015.bag', '/husky_velocity_controller/odom'),
    ('alfa_carbonZ_engine_failure.bag', '/mavros/local_position/odom'),
    ('sequor_E2_normal_safe_escape_straight.bag', '/odom'),
    ('sequor_N2_anomalous_jerky_driving.bag', '/odom'),
    ('sequor_N3_anomalous_crash_wall.bag', '/odom'),
    ('sequor_N2_anomalous_jerky_driving.bag', '/scan'),  # a side topic: float32 LaserScan, 128 beams
]
WRITTEN = '6+opts'  # preset 6 with json_xz.FILTER_OPTIONS, as the writer compresses
PRESETS = [('0', 0), ('1', 1), ('3', 3), ('6', 6), (WRITTEN, 6), ('9', 9), ('9e', 9 | lzma.PRESET_EXTREME)]
QUICK_PRESETS = [('1', 1), ('6', 6), (WRITTEN, 6), ('9e', 9 | lzma.PRESET_EXTREME)]
METADATA = {'codec': 'json-xz', 'reasons': ['classifier'], 'cc_log_version': cc_log.__version__}


def load(bag_name, topic):
    import rosbag
    records = []
    with rosbag.Bag(os.path.join(REAL, bag_name)) as bag:
        for _, msg, time_ in bag.read_messages(topics=[topic]):
            stamp = msg.header.stamp.to_sec() if msg.header.stamp.to_sec() > 0 else time_.to_sec()
            records.append(Record(stamp, topic, msg))
    return records


def xz(data, label, preset):
    """``data`` compressed at ``preset`` alone, or as the writer does for the WRITTEN label."""
    return json_xz.compress(data, preset, json_xz.FILTER_OPTIONS if label == WRITTEN else {})


# -- layouts: each returns the uncompressed bytes of one window ---------------------------------------

def rows_layout(records):
    return ''.join(msg_codec.row_json(record.msg) + '\n' for record in records).encode()


def columns_layout(records):
    return json_xz.dumps(json_xz.document(records, METADATA)).encode()


def v1_layout(records):
    return json_xz.dumps(json_xz.document(records, METADATA, delta=lambda values: None)).encode()


def alldiff_layout(records):
    return json_xz.dumps(json_xz.document(records, METADATA,
                                          delta=lambda values: json_xz.differences(values, choose=False))).encode()


#: Steps of the lossy rows: the Husky odometry's resolution (1e-4 m, 1e-5 rad) and ten times coarser.
LOSSY = [('lossy-4/5', {'pose.pose.position.*': 1e-4, 'pose.pose.orientation.*': 1e-5, 'twist.twist.linear.*': 1e-4,
                        'twist.twist.angular.*': 1e-5}),
         ('lossy-3/4', {'pose.pose.position.*': 1e-3, 'pose.pose.orientation.*': 1e-4, 'twist.twist.linear.*': 1e-3,
                        'twist.twist.angular.*': 1e-4})]


def lossy_layout(precision):
    return lambda records: json_xz.dumps(json_xz.document(records, dict(METADATA, precision=precision))).encode()


def lossy_errors(records, precision):
    """The largest error per rounded field over ``records`` (written and read back as one window)."""
    _, back = json_xz.decode(json_xz.encode(records, dict(METADATA, precision=precision)))
    errors = json_xz.max_errors(records, back)[records[0].topic]
    return dict((key, error) for key, error in errors.items() if error)


def _variant(records, split_arrays, constants):
    doc = json_xz.document(records, METADATA)
    for section in doc['topics']:
        columns = dict(section['columns'])
        for key, value in section['constant'].items():
            columns[key] = [value] * section['count']
        if split_arrays:
            for key in list(columns):
                values = columns[key]
                if isinstance(values[0], list) and len(set(len(value) for value in values)) == 1:
                    del columns[key]
                    for index in range(len(values[0])):
                        columns['%s[%d]' % (key, index)] = [value[index] for value in values]
        rows = [dict((key, values[i]) for key, values in columns.items()) for i in range(section['count'])]
        if constants:
            section['constant'], section['columns'] = json_rows.columns_of(rows)
        else:
            section['constant'], section['columns'] = {}, columns
        section['delta'] = [key for key in section.get('delta', ()) if key in section['columns']]
    return json_xz.dumps(doc).encode()


def elem_layout(records):
    return _variant(records, True, True)


def noconst_layout(records):
    return _variant(records, False, False)


LAYOUTS = [('rows', rows_layout), ('columns-v1', v1_layout), ('columns', columns_layout),
           ('columns-alldiff', alldiff_layout), ('columns-elem', elem_layout), ('columns-noconst', noconst_layout)] \
    + [(name, lossy_layout(precision)) for name, precision in LOSSY]


def bag_bytes(records):
    from cc_log.storage.formats import bag_lz4
    with tempfile.TemporaryDirectory() as directory:
        path = os.path.join(directory, 'w.bag')
        bag_lz4.write(path, records, dict(METADATA, codec='bag-lz4'))
        return os.path.getsize(path)


def binary_floor(records):
    import struct
    columns = {}
    for record in records:
        for key, value in json_rows.flatten(msg_codec.to_dict(record.msg), '', {}).items():
            columns.setdefault(key, []).append(value)
    blob = bytearray()
    for key, values in columns.items():
        if all(isinstance(value, float) for value in values):
            blob += struct.pack('<%dd' % len(values), *values)
        elif all(isinstance(value, int) and not isinstance(value, bool) for value in values):
            deltas = [values[0]] + [b - a for a, b in zip(values, values[1:])]
            blob += struct.pack('<%dq' % len(values), *deltas)
        else:
            blob += json.dumps(values).encode()
    return len(lzma.compress(bytes(blob), preset=9))


def windows(records, size):
    if size <= 0 or size >= len(records):
        return [records]
    return [records[i:i + size] for i in range(0, len(records), size) if len(records[i:i + size]) == size]


def measure(records, size, presets):
    """Rows of (layout, preset, bytes, percent, ms per window) for the windows of ``size`` records."""
    chunks = windows(records, size)
    raw = sum(msg_codec.row_json_bytes(record.msg) for chunk in chunks for record in chunk)
    results = []
    for name, layout in LAYOUTS:
        for label, preset in presets:
            total, seconds = 0, 0.0
            for chunk in chunks:
                start = time.perf_counter()
                total += len(xz(layout(chunk), label, preset))
                seconds += time.perf_counter() - start
            results.append((name, label, total, 100.0 * total / raw, 1000.0 * seconds / len(chunks)))
    start = time.perf_counter()
    total = sum(bag_bytes(chunk) for chunk in chunks)
    results.append(('bag-lz4', '-', total, 100.0 * total / raw, 1000.0 * (time.perf_counter() - start) / len(chunks)))
    total = sum(binary_floor(chunk) for chunk in chunks)
    results.append(('binary-floor', '9', total, 100.0 * total / raw, float('nan')))
    return raw, len(chunks), results


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--window', type=int, default=300, help='messages per window (default 300)')
    parser.add_argument('--quick', action='store_true',
                        help='a smoke run: presets 1, 6, 6+opts, 9e; Husky and ALFA; windows only')
    parser.add_argument('--no-whole', action='store_true', help='skip the whole-topic-as-one-window rows')
    args = parser.parse_args(argv)
    presets = QUICK_PRESETS if args.quick else PRESETS
    began = time.perf_counter()
    print('# format_layouts: json-xz layouts and LZMA presets against row-per-message JSON')
    print('machine: %s' % common.machine())
    print('load: %.2f %.2f %.2f (os.getloadavg: 1, 5, 15 min)' % os.getloadavg())
    print('data: %s (see SOURCES.md there)' % REAL)
    print('row JSON = msg_codec.row_json_bytes (json.dumps of the nested message dict + newline)')
    for bag_name, topic in (BAGS[:2] if args.quick else BAGS):
        records = load(bag_name, topic)
        whole = not (args.no_whole or args.quick) and len(records) > args.window
        sizes = [args.window] + ([len(records)] if whole else [])
        for size in sizes:
            raw, count, results = measure(records, size, presets)
            print()
            print('%s %s: %d msgs, windows of %d msgs: %d window(s), row JSON %d bytes'
                  % (bag_name, topic, len(records), min(size, len(records)), count, raw))
            print('  %-16s %-6s %10s %9s %12s' % ('layout', 'preset', 'bytes', '% row', 'ms/window'))
            for name, label, total, percent, ms in results:
                print('  %-16s %-6s %10d %8.2f%% %12s' % (name, label, total, percent,
                                                          '-' if ms != ms else '%.1f' % ms))
            if size == args.window:
                for name, precision in LOSSY:
                    errors = lossy_errors(records, precision)
                    print('  %s largest error per field (all %d msgs): %s' % (name, len(records), ', '.join(
                        '%s %.3g' % (key, error) for key, error in sorted(errors.items())) or 'none'))
    print()
    print('total %.1f s' % (time.perf_counter() - began))
    return 0


if __name__ == '__main__':
    sys.exit(main())
