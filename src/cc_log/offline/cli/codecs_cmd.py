"""``cclog codecs``: the paper's Table 2 on a bag topic or on window files."""
import collections
import os

from cc_log.offline.progress import bar as _bar
from cc_log.offline.cli.common import (
    EXIT_OK, CommandError, command_help, human_bytes, output_flags, print_json, selected_records)


def add_parser(subparsers):
    """The ``cclog codecs`` sub-parser."""
    p = subparsers.add_parser('codecs', **command_help(
        "the paper's Table 2 on some data",
        """
        The paper's Table 2 on the row-per-message JSON of the data: every codec cc_log knows (none, LZ4,
        LZFSE when its Python binding is installed, ZIP, gzip, bzip2, LZMA-6, zstd) and cc_log's own
        window formats (json-xz, bag-lz4), with size, ratio and MB/s (of the raw JSON). For a BAG the data
        is the messages of --topic; for a LOG (window file or directory) all its messages (or --topic).
        """,
        """
          cclog codecs husky.bag --topic /husky_velocity_controller/odom
          cclog codecs husky.bag --topic /imu/data --json
          cclog codecs logs
        """))
    p.add_argument('path', metavar='BAG|LOG', help='a bag, a window file or a directory of window files')
    p.add_argument('--topic', action='append', metavar='T', help='topic to measure (repeatable; required for a bag)')
    output_flags(p)
    p.set_defaults(paths=None)
    return p


def run(args):
    """The paper's Table 2 on the row-per-message JSON of a bag topic or of window files."""
    from cc_log.storage import codecs
    from cc_log.base import msg_codec
    path = args.path
    if not os.path.exists(path):
        raise CommandError('%s: no such file or directory' % path)
    if os.path.isfile(path) and _is_plain_bag(path):
        from cc_log.storage.bag import bagio
        bag = bagio.open_bag(path)
        try:
            if not args.topic:
                topics = bagio.topics_of(bag)
                raise CommandError('topic: a bag needs --topic; its topics: %s' % ', '.join(
                    '%s (%s)' % (name, topics[name]) for name in sorted(topics)))
            for topic in args.topic:
                bagio.check_topic(bag, topic)
            total = bag.get_message_count(args.topic)
        finally:
            bag.close()
        records = []
        with _bar(args, 'read', total) as bar:
            for record in bagio.read_messages(path, args.topic):
                records.append(record)
                bar.update()
        source = collections.OrderedDict([('bag', path), ('topics', args.topic)])
    else:
        args.paths = [path]
        records = selected_records(args)
        source = collections.OrderedDict([('log', path), ('topics', sorted(set(r.topic for r in records)))])
    if not records:
        raise CommandError('%s: no messages on %s' % (path, ', '.join(args.topic or [])))
    data = b''.join(msg_codec.row_json(record.msg).encode('utf-8') + b'\n' for record in records)
    with _bar(args, 'codecs').busy():
        rows = list(codecs.codec_table(data))
        rows.extend(codecs.window_format_rows(records, len(data)))
    result = collections.OrderedDict([('source', source), ('messages', len(records)), ('raw_json_bytes', len(data)),
                                      ('rows', rows)])
    if args.json:
        print_json(result)
        return EXIT_OK
    print('%d messages, %s of row-per-message JSON (%s)' % (
        len(records), human_bytes(len(data)), ', '.join(source['topics'])))
    print(codecs.format_table(rows))
    print('ratio: compressed size in % of the raw JSON; MB/s: raw JSON compressed per second')
    return EXIT_OK


def _is_plain_bag(path):
    """True for a rosbag that is not a cc_log bag-lz4 window file (which ``codecs`` reads as a LOG)."""
    from cc_log.base import safe_input
    from cc_log.storage.formats import bag_lz4
    with safe_input.open_input(path) as stream:
        if not stream.read(16).startswith(bag_lz4.MAGIC):
            return False
    return not os.path.basename(path).startswith('cc_log_')
