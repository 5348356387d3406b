"""``cclog cat``: cc_log files as JSON lines."""
import json
import os
import sys

from cc_log.offline import export
from cc_log.storage import formats
from cc_log.offline.cli.common import EXIT_OK, CommandError, command_help, output_flags, plain, read_windows


def add_parser(subparsers):
    """The ``cclog cat`` sub-parser."""
    p = subparsers.add_parser('cat', **command_help(
        'decode cc_log files to JSON lines',
        """
        Decode cc_log files to JSON lines on stdout. A window file (json-xz or bag-lz4) or a directory of
        them gives one line per message: {"stamp", "topic", "type", "msg"} (msg_codec rows: times as
        {secs, nsecs}, byte arrays as base64, non-finite floats as strings). A model, feature-vector or
        truth file (JSON) is printed as one line.
        """,
        """
          cclog cat logs/cc_log_20150521T191138.027Z_classifier.json.xz | jq .msg.twist.twist.linear.x
          cclog cat logs --topic /odom --metadata
          cclog cat model.json | jq .threshold
        """))
    p.add_argument('paths', nargs='+', metavar='PATH', help='cc_log file or directory of window files')
    p.add_argument('--topic', action='append', metavar='T', help='only this topic (repeatable)')
    p.add_argument('--metadata', action='store_true', help='a {"file", "metadata"} line before each window')
    p.add_argument('--with-file', action='store_true', help='add "file" (the window file) to every line')
    output_flags(p, json_help=False)
    return p


def run(args):
    """Decode cc_log files to JSON lines on stdout (window records; models, vectors, truth as one line)."""
    topics = set(args.topic) if args.topic else None
    out = sys.stdout
    for argument in args.paths:
        if os.path.isfile(argument) and not _is_window_file(argument) and not formats.by_extension(argument):
            out.write(json.dumps(plain(_cc_log_json(argument)), allow_nan=False) + '\n')
            continue
        for path, metadata, records in read_windows(args, [argument], 'cat'):
            if args.metadata:
                out.write(json.dumps(plain({'file': path, 'metadata': metadata}), allow_nan=False) + '\n')
            for record in records:
                if topics is None or record.topic in topics:
                    out.write(json.dumps(plain(export.record_row(record, path if args.with_file else None)),
                                         allow_nan=False) + '\n')
    return EXIT_OK


def _cc_log_json(path):
    """A cc_log JSON file (model, feature vector, simulator truth); CommandError when it is none of them."""
    from cc_log.base import safe_input
    with safe_input.open_input(path) as stream:
        data = stream.read()
    try:
        document = safe_input.json_loads(data)
    except UnicodeDecodeError:
        raise CommandError('%s: not a cc_log file (not a window file and not JSON text)' % path)
    except ValueError as error:
        raise CommandError('%s: not a cc_log file (not a window file; invalid JSON: %s)' % (path, error))
    kind = document.get('format', '') if isinstance(document, dict) else ''
    if kind == 'cc_log-model' or str(kind).startswith('cc_log.') or (
            isinstance(document, dict) and 'features' in document and 'config' in document):
        return document
    raise CommandError('%s: not a cc_log file (JSON, but not a model, feature-vector or truth file)' % path)


def _is_window_file(path):
    from cc_log.storage import formats
    from cc_log.base import safe_input
    with safe_input.open_input(path) as stream:
        return formats.by_magic(stream.read(16)) is not None
