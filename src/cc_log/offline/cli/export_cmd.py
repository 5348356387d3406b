"""``cclog export``: window files to a bag, MCAP, CSV, JSON lines or PNG frames."""
import collections
import os

from cc_log.offline import export
from cc_log.offline.progress import bar as _bar
from cc_log.offline.cli.common import (
    EXIT_OK, CommandError, command_help, output_flags, parent_exists, print_json, say, selected_windows,
    writable_dir)

EXPORT_TARGETS = ('bag', 'mcap', 'csv', 'jsonl', 'png')


def add_parser(subparsers):
    """The ``cclog export`` sub-parser."""
    p = subparsers.add_parser('export', **command_help(
        'window files to a bag, MCAP, CSV, JSON lines or PNG frames',
        """
        Export the messages of window files (merged, in stamp order) to one rosbag (messages on their own
        topics, stamp as bag time), to one MCAP file (ROS 1 profile, for Foxglove and PlotJuggler; each
        window's metadata, its triggers, reasons, scores and span, as a Metadata record "cc_log.window" and a
        JSON attachment; needs the optional Python package mcap: /usr/bin/python3 -m pip install
        --break-system-packages mcap), to CSV
        (--out is a directory: one <topic>.csv per topic, a "stamp" column then one column per field; arrays
        as JSON), to one JSON-lines file, or the camera frames to
        images (--to png, --out is a directory: each sensor_msgs/Image as <topic>_<stamp>.png, rgb8, bgr8,
        rgba8, bgra8, mono8, 16UC1/mono16 with their values, 32FC1 depth as 16-bit millimetres; each
        CompressedImage as its own .jpg or .png bytes; existing files are never overwritten).
        """,
        """
          cclog export logs --to bag --out anomalies.bag
          cclog export logs --to mcap --out anomalies.mcap --compression zstd
          cclog export logs/cc_log_20150521T191138.027Z_classifier.json.xz --to csv --out csv/
          cclog export logs --to jsonl --out all.jsonl --topic /odom
          cclog export logs --to png --out frames/ --topic /camera/image_raw
        """))
    p.add_argument('paths', nargs='+', metavar='PATH', help='window file or directory')
    p.add_argument('--to', required=True, choices=EXPORT_TARGETS, help='output kind')
    p.add_argument('--out', required=True, metavar='PATH',
                   help='output file (bag, mcap, jsonl) or directory (csv, png)')
    p.add_argument('--topic', action='append', metavar='T', help='only this topic (repeatable)')
    p.add_argument('--compression', choices=sorted(set(export.BAG_COMPRESSIONS + export.MCAP_COMPRESSIONS)),
                   help='chunk compression: bag lz4, bz2 or none (default: none); MCAP zstd, lz4 or none '
                        '(default: zstd when the Python package zstandard imports, else lz4)')
    p.add_argument('--force', action='store_true', help='overwrite an existing bag or MCAP file')
    output_flags(p)
    return p


def run(args):
    """Window files to one bag, one CSV per topic, or one JSON-lines file (``export``)."""
    records, windows = selected_windows(args)
    if args.to == 'jsonl':
        parent_exists(args.out, 'out')
        files = export.to_jsonl(records, args.out)
    elif args.to in ('bag', 'mcap'):
        parent_exists(args.out, 'out')
        if os.path.exists(args.out) and not args.force:
            raise CommandError('out: %s exists (use --force to overwrite)' % args.out)
        with _bar(args, 'export', len(records)) as bar:
            if args.to == 'bag':
                files = export.to_bag(records, args.out, args.compression or 'none', bar.update)
            else:
                files = export.to_mcap(records, args.out, args.compression, bar.update, windows)
    elif args.to == 'png':
        return _export_frames(args, records)
    else:
        writable_dir(args.out, 'out')
        files = export.to_csv(records, args.out)
    summary = collections.OrderedDict([('to', args.to), ('messages', len(records)),
                                       ('topics', sorted(set(record.topic for record in records))),
                                       ('files', files)])
    if args.json:
        print_json(summary)
    else:
        print('%d messages of %d topic(s) -> %s' % (len(records), len(summary['topics']), ', '.join(files)))
    return EXIT_OK


def _export_frames(args, records):
    """``export --to png``: every camera frame as a PNG (or its own JPEG) file in the directory ``--out``."""
    from cc_log.base import raw_message
    frames = [record for record in records if raw_message.type_of(record) in export.IMAGE_TYPES]
    if not frames:
        raise CommandError('%s: no sensor_msgs/Image or CompressedImage messages' % ', '.join(args.paths)[:200])
    writable_dir(args.out, 'out')
    skipped = {}
    with _bar(args, 'export', len(frames)) as bar:
        files = export.to_frames(frames, args.out, skipped, bar.update)
    summary = collections.OrderedDict([('to', args.to), ('frames', len(files)),
                                       ('topics', sorted(set(record.topic for record in frames))),
                                       ('directory', args.out), ('skipped', skipped), ('files', files)])
    if args.json:
        print_json(summary)
        return EXIT_OK
    say('%d frame(s) of %s -> %s' % (len(files), ', '.join(summary['topics']), args.out))
    for reason, count in sorted(skipped.items()):
        say('  skipped %d frame(s): %s' % (count, reason))
    return EXIT_OK
