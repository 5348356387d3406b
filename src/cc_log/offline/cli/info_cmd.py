"""``cclog info``: what window files hold."""
import collections
import os

from cc_log.base import why
from cc_log.offline import progress
from cc_log.offline.cli.common import (
    EXIT_OK, command_help, human_bytes, output_flags, print_json, say, size_ratio, stamp_text, window_paths)


def add_parser(subparsers):
    """The ``cclog info`` sub-parser."""
    p = subparsers.add_parser('info', **command_help(
        'windows, spans, counts, sizes, codec, triggers, scores, why',
        """
        Describe window files: time span, messages per topic, size on disk and as row-per-message JSON,
        codec, the trigger(s) that opened the window with their scores and what stood out (why), and the model
        threshold. PATH is a
        window file or a directory of them (read in time order). The figures of a file written by this cc_log
        come from its metadata, without reading its messages (its row JSON size is then an estimate from a
        sample of its messages); --full reads and counts every message (older files always are).
        """,
        """
          cclog info logs
          cclog info logs/cc_log_20150521T191138.027Z_classifier.json.xz --json
        """))
    p.add_argument('paths', nargs='+', metavar='PATH', help='window file or directory')
    p.add_argument('--full', action='store_true',
                   help='read every message: exact counts, sizes and row JSON bytes, and the files checked whole')
    output_flags(p)
    return p


def run(args):
    """Windows, time spans, message counts, sizes, codec, trigger and scores of window files."""
    windows = list(_summaries(args))
    total = collections.OrderedDict([
        ('windows', len(windows)),
        ('messages', sum(w['messages'] for w in windows)),
        ('bytes', sum(w['bytes'] for w in windows)),
        ('raw_json_bytes', sum(w['raw_json_bytes'] for w in windows)),
        ('start', min(w['start'] for w in windows) if windows else None),
        ('end', max(w['end'] for w in windows) if windows else None),
    ])
    total['ratio'] = size_ratio(total['raw_json_bytes'], total['bytes'])
    if args.json:
        print_json(collections.OrderedDict([('windows', windows), ('total', total)]))
        return EXIT_OK
    for w in windows:
        say(w['path'])
        if len(w['files']) > 1:
            split = ' (split at split_mb: %d files of its own)' % w['splits'] if w['splits'] else ''
            say('  files      %s%s' % (', '.join(os.path.basename(name) for name in w['files'][1:]), split))
        say('  codec      %s' % w['codec'])
        utc = ', from %s' % w['start_utc'] if w['start_utc'] else ''
        say('  span       %s .. %s  (%.2f s%s)' % (stamp_text(w['start']), stamp_text(w['end']),
                                                   w['duration'] or 0.0, utc))
        say('  messages   %d: %s' % (w['messages'], ', '.join('%s %d' % item for item in w['topics'].items())))
        say('  topic MB   %s (serialized)' % ', '.join(
            '%s %.2f' % (topic, size / 1e6) for topic, size in sorted(w['topic_bytes'].items(), key=lambda i: -i[1])))
        if w['dropped']:
            say('  DROPPED    %d messages not in the file (the writer fell behind; payloads not of their type): %s' % (
                sum(w['dropped'].values()), ', '.join('%s %d' % item for item in sorted(w['dropped'].items()))))
        say('  size       %s (row JSON %s, %s)' % (
            human_bytes(w['bytes']), human_bytes(w['raw_json_bytes']),
            '%.1fx' % w['ratio'] if w['ratio'] else '-'))
        if w['triggers']:
            scores = [t['score'] for t in w['triggers'] if t['score'] is not None]
            say('  trigger    %s, %d trigger(s)%s%s' % (
                w['reason'], len(w['triggers']),
                ', scores %.4g .. %.4g' % (min(scores), max(scores)) if scores else '',
                ', threshold %.4g' % w['threshold'] if isinstance(w['threshold'], (int, float)) else ''))
            for name, said in _whys(w['triggers']):
                say('  why        %s: %s' % (name, why.texts(said)))
        if w['part'] and len(w['files']) > 1:  # every part's files read as this window
            say('  parts      %s (a file per part, the window split at max_window)' % w['part'])
        elif w['part']:
            say('  part       %s of a window split at max_window' % w['part'])
    say('%d window(s), %d messages, %s on disk, %s as row JSON%s' % (
        total['windows'], total['messages'], human_bytes(total['bytes']), human_bytes(total['raw_json_bytes']),
        ' (%.1fx)' % total['ratio'] if total['ratio'] else ''))
    return EXIT_OK


def _whys(triggers):
    """``[(trigger name, its why)]``: for each trigger of a window that says why, the why of its most anomalous
    firing (the lowest score; the first when none has one), in order of first firing."""
    best = collections.OrderedDict()
    for trigger in triggers:
        if not trigger['why']:
            continue
        name = str(trigger['name'] or trigger['reason'])
        score = trigger['score'] if isinstance(trigger['score'], (int, float)) else float('inf')
        if name not in best or score < best[name][0]:
            best[name] = (score, trigger['why'])
    return [(name, said) for name, (_, said) in best.items()]


def _counts_of(value):
    """``{topic: count}`` of a metadata entry that should be one (anything else: {})."""
    if not isinstance(value, dict):
        return {}
    return dict((str(key), count) for key, count in value.items()
                if isinstance(count, int) and not isinstance(count, bool) and count >= 0)


def _summaries(args):
    """What ``info`` reports about each window of ``args.paths`` (a window with routes or split: its files as one): from
    its metadata's summaries when they hold one (``window_info.summary_of``) and --full is not given, else from its
    records."""
    from cc_log.storage import log_format, window_info
    sets = log_format.window_sets(window_paths(args.paths))
    with progress.bar(args, 'info', len(sets)) as meter:
        for files in sets:
            summaries = []
            if not args.full:
                metadatas = [log_format.read_metadata(path) for path in files]
                summaries = [window_info.summary_of(metadata) for metadata in metadatas]
            if not summaries or None in summaries:
                metadata, records = log_format.read_window_set(files)
                yield _window_summary(files[0], metadata, records)
            else:
                metadata = log_format.merged_metadata(metadatas, files) if len(files) > 1 else metadatas[0]
                yield _metadata_summary(files[0], metadata, window_info.merged_summary(summaries))
            meter.update()


def _window_summary(path, metadata, records):
    """What ``info`` reports about one window file, counted from its records."""
    from cc_log.base import msg_codec
    from cc_log.storage.formats import bag_lz4
    counts = collections.OrderedDict()
    types = collections.OrderedDict()
    topic_bytes = collections.OrderedDict()   # serialized (ROS wire) bytes per topic
    raw = 0
    for record in records:
        counts[record.topic] = counts.get(record.topic, 0) + 1
        types.setdefault(record.topic, record.msg._type)
        topic_bytes[record.topic] = topic_bytes.get(record.topic, 0) + len(bag_lz4.bag_message(record)[-1])
        raw += msg_codec.row_json_bytes(record.msg)
    stamps = [record.stamp for record in records]
    return _described(path, metadata, counts, types, topic_bytes, raw,
                      (min(stamps), max(stamps)) if stamps else (None, None))


def _metadata_summary(path, metadata, summary):
    """What ``info`` reports about one window file, from its metadata's summary (a ``window_info.WindowSummary``)."""
    spans = summary.topic_spans.values()
    return _described(path, metadata, summary.counts, summary.types, summary.topic_bytes, summary.raw_json_bytes,
                      (min(span[0] for span in spans), max(span[1] for span in spans)) if spans else (None, None))


def _described(path, metadata, counts, types, topic_bytes, raw, span):
    """``info``'s entry of a window file: its records' ``counts``, ``types`` and ``topic_bytes`` per topic, their
    row JSON bytes ``raw`` and (first, last) stamp ``span``, with what its ``metadata`` says."""
    start, end = span
    size = sum(os.path.getsize(name) for name in metadata.get('files', [path]))  # every file of the window
    triggers = []
    for trigger in metadata.get('triggers') or []:
        score = trigger.get('score')
        if isinstance(score, str):  # non-finite scores are stored as 'NaN' / 'Infinity' strings
            score = None
        triggers.append({'stamp': trigger.get('stamp'), 'reason': trigger.get('reason'), 'score': score,
                         'name': trigger.get('name'), 'why': trigger.get('why') or []})
    scores = [trigger['score'] for trigger in triggers if isinstance(trigger['score'], (int, float))]
    return collections.OrderedDict([
        ('path', path),
        ('files', metadata.get('files', [path])),  # a window with routes: its own file and one per route
        ('codec', metadata.get('codec')),
        ('start', start),
        ('end', end),
        ('duration', (end - start) if start is not None else None),
        ('start_utc', metadata.get('start_utc')),
        ('messages', sum(counts.values())),
        ('topics', counts),
        ('types', types),
        ('topic_bytes', topic_bytes),
        ('bytes', size),
        ('raw_json_bytes', raw),
        ('ratio', size_ratio(raw, size)),
        ('reason', metadata.get('reason') or (triggers[0]['reason'] if triggers else None)),
        ('triggers', triggers),
        ('min_score', min(scores) if scores else None),
        ('threshold', metadata.get('threshold')),
        ('driving_topic', metadata.get('driving_topic')),
        ('part', metadata.get('part', 0)),
        ('splits', metadata.get('splits', 0)),  # files of its own, split at split_mb (0: one)
        ('dropped', _counts_of(metadata.get('dropped'))),
        ('pre', metadata.get('pre')),
        ('post', metadata.get('post')),
        ('model', metadata.get('model')),
    ])
