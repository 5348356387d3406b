"""``cclog``: the offline cc_log tool. No roscore is needed for any command.

    rosrun cc_log cclog <command> [options]      (see ``cclog <command> --help`` and docs/CLI.md)

Commands: ``collect`` (feature vectors from a bag), ``learn`` (train / evaluate a model), ``replay`` (the
smart logger over a bag), ``info``, ``cat``, ``export`` (window files), ``codecs`` (the paper's Table 2 on
some data), ``plot`` (a timeline of a run), ``tune`` (a threshold for a false-window budget), ``simulate`` (a
simulated BWIBot bag with labelled anomalies).

Conventions shared by every command:

- results go to stdout: readable text, or with ``--json`` one JSON object (``cat`` writes JSON lines);
- progress bars go to stderr, only when stderr is a terminal or with ``--progress``; never to stdout;
- bad input (missing file, truncated or unindexed bag, topic not in the bag, wrong message type, a model
  of another feature configuration, bad option values) prints one line
  ``cclog <command>: error: <what is wrong>`` on stderr and exits with status 1 (2 for bad command-line
  syntax, 130 when interrupted).

Library modules are imported inside the commands, so ``cclog --help`` is quick and a command only needs
what it uses (rosbag for bags, matplotlib for ``plot``).
"""
import argparse
import collections
import contextlib
import copy
import json
import math
import os
import re
import sys
import textwrap

from cc_log.offline import export
from cc_log.storage import formats
from cc_log.offline.progress import bar as _bar, call as _call

PROG = 'cclog'
EXIT_OK = 0
EXIT_BAD_INPUT = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
INTERRUPT_GRACE = 0.5  # seconds Ctrl-C leaves a command to finish what it is writing before it stops anyway

EXPORT_TARGETS = ('bag', 'mcap', 'csv', 'jsonl', 'png')


class CommandError(ValueError):
    """Bad input found by a command itself (the message is the one line printed)."""


# -- output helpers ---------------------------------------------------------------------------------------

_plain = export.plain


def _print_json(document):
    sys.stdout.write(json.dumps(_plain(document), allow_nan=False, sort_keys=False) + '\n')


# control characters (a terminal escape sequence starts with one) and the bidirectional overrides
_UNPRINTABLE = re.compile('[\x00-\x1f\x7f-\x9f\u200e\u200f\u202a-\u202e\u2066-\u2069]')


def printable(text):
    """``text`` with control characters shown as ``\\xNN`` / ``\\uNNNN``: names read from files (topics,
    reasons, paths) never reach the terminal as escape sequences."""
    return _UNPRINTABLE.sub(lambda found: ascii(found.group())[1:-1], str(text))


def _say(text):
    """Print a line of a report made of names read from files (see ``printable``)."""
    print(printable(text))


def human_bytes(count):
    """``1536`` -> ``'1.5 kB'`` (powers of 1000, as in the paper's tables)."""
    count = float(count)
    for unit in ('B', 'kB', 'MB', 'GB'):
        if abs(count) < 1000 or unit == 'GB':
            return ('%d %s' % (count, unit)) if unit == 'B' else ('%.1f %s' % (count, unit))
        count /= 1000.0


def _ratio(raw, stored):
    return float(raw) / stored if stored else None


def _stamp_text(stamp):
    return '%.3f' % stamp if stamp is not None else '-'


def _existing_file(path, what='file'):
    if not os.path.exists(path):
        raise CommandError('%s: no such %s' % (path, what))
    if os.path.isdir(path):
        raise CommandError('%s: is a directory, not a %s' % (path, what))
    return path


def _writable_dir(path, name):
    """Create directory ``path`` if needed; CommandError('<name>: ...') when that is impossible."""
    from cc_log.core import safe_files
    if os.path.exists(path) and not os.path.isdir(path):
        raise CommandError('%s: %s exists and is not a directory' % (name, path))
    try:
        safe_files.make_dirs(path)
    except OSError as error:
        raise CommandError('%s: cannot create %s (%s)' % (name, path, error.strerror or error))
    return path


def _parent_exists(path, name):
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CommandError('%s: directory %s does not exist' % (name, folder))
    return path


def _span(name):
    """argparse type for a count (``500``) or a duration (``5s``) checked by Span.parse."""
    def parse(value):
        from cc_log.core.spans import Span
        try:
            Span.parse(value, name)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error))
        return value
    parse.__name__ = name
    return parse


def _spans(name):
    """argparse type for a comma-separated list of counts or durations (``1s,2s,5s``), each checked by Span.parse."""
    single = _span(name)

    def parse(value):
        return [single(item.strip()) for item in value.split(',')]
    parse.__name__ = name
    return parse


def _positive_float(name, zero=False):
    """argparse type for a finite number > 0 (>= 0 with ``zero``)."""
    def parse(value):
        try:
            number = float(value)
        except ValueError:
            number = float('nan')
        if not (math.isfinite(number) and (number >= 0 if zero else number > 0)):
            kind = 'non-negative' if zero else 'positive'
            raise argparse.ArgumentTypeError('%s: %r must be a %s number' % (name, value, kind))
        return number
    parse.__name__ = name
    return parse


def _non_negative_int(name, minimum=0):
    def parse(value):
        try:
            number = int(value)
        except ValueError:
            raise argparse.ArgumentTypeError('%s: %r is not a whole number' % (name, value))
        if number < minimum:
            raise argparse.ArgumentTypeError('%s: %r must be at least %d' % (name, value, minimum))
        return number
    parse.__name__ = name
    return parse


# -- reading window files ---------------------------------------------------------------------------------

def window_paths(paths):
    """Window files named by ``paths`` (files as given; directories: their window files, by time).

    CommandError for a path that does not exist or a directory without window files.
    """
    from cc_log.storage import log_format
    found = []
    for path in paths:
        if not os.path.exists(path):
            raise CommandError('%s: no such file or directory' % path)
        if os.path.isdir(path):
            files = log_format.window_files(path)
            if not files:
                raise CommandError('%s: no cc_log window files (cc_log_*.json.xz / cc_log_*.bag) in this directory'
                                   % path)
            found.extend(files)
        else:
            found.append(path)
    return found


def _read_windows(args, paths, label):
    """Yield ``(path, metadata, records)`` of every window file named by ``paths``, with a progress bar."""
    from cc_log.storage import log_format
    files = window_paths(paths)
    with _bar(args, label, len(files)) as bar:
        for path in files:
            metadata, records = log_format.read_window(path)
            yield path, metadata, records
            bar.update()


def _counts_of(value):
    """``{topic: count}`` of a metadata entry that should be one (anything else: {})."""
    if not isinstance(value, dict):
        return {}
    return dict((str(key), count) for key, count in value.items()
                if isinstance(count, int) and not isinstance(count, bool) and count >= 0)


def _window_summary(path, metadata, records):
    """What ``info`` reports about one window file."""
    from cc_log.core import msg_codec
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
    start = min(stamps) if stamps else None
    end = max(stamps) if stamps else None
    size = os.path.getsize(path)
    triggers = []
    for trigger in metadata.get('triggers') or []:
        score = trigger.get('score')
        if isinstance(score, str):  # non-finite scores are stored as 'NaN' / 'Infinity' strings
            score = None
        triggers.append({'stamp': trigger.get('stamp'), 'reason': trigger.get('reason'), 'score': score})
    scores = [trigger['score'] for trigger in triggers if isinstance(trigger['score'], (int, float))]
    return collections.OrderedDict([
        ('path', path),
        ('codec', metadata.get('codec')),
        ('start', start),
        ('end', end),
        ('duration', (end - start) if stamps else None),
        ('start_utc', metadata.get('start_utc')),
        ('messages', len(records)),
        ('topics', counts),
        ('types', types),
        ('topic_bytes', topic_bytes),
        ('bytes', size),
        ('raw_json_bytes', raw),
        ('ratio', _ratio(raw, size)),
        ('reason', metadata.get('reason') or (triggers[0]['reason'] if triggers else None)),
        ('triggers', triggers),
        ('min_score', min(scores) if scores else None),
        ('threshold', metadata.get('threshold')),
        ('driving_topic', metadata.get('driving_topic')),
        ('part', metadata.get('part', 0)),
        ('dropped', _counts_of(metadata.get('dropped'))),
        ('pre', metadata.get('pre')),
        ('post', metadata.get('post')),
        ('model', metadata.get('model')),
    ])


# -- many bags (fleet) ------------------------------------------------------------------------------------

def _fleet_wanted(args, paths, single_dir=None):
    """True for the fleet path: several inputs, a directory (unless ``single_dir(path)`` says it is one input)
    or a glob, or --workers / --scheduler given."""
    import glob
    return (len(paths) > 1 or glob.has_magic(paths[0]) or args.workers is not None or args.scheduler is not None
            or (os.path.isdir(paths[0]) and not (single_dir and single_dir(paths[0]))))


def _engine(args):
    from cc_log.offline import fleet
    return fleet.Engine(args.workers, args.scheduler)


def _run_fleet(args, label, work):
    """``work(engine, progress)`` -> Outcomes on the engine of --workers / --scheduler with a bar of bags;
    returns ``(outcomes, summary)``; each failed bag is one line on stderr."""
    from cc_log.offline import fleet
    engine = _engine(args)
    interrupt = getattr(args, 'interrupt', None)
    if interrupt is not None and not engine.local:
        interrupt.grace = None  # Ctrl-C: let the cluster close (its workers end) however long it takes
    with engine, _bar(args, label) as bar:
        meter = fleet.Meter(lambda done, total, text: (setattr(bar, 'label', '%s (%s)' % (label, text)),
                                                       bar.set(done, total)))
        outcomes = work(engine, meter.update)
        summary = meter.summary(engine)
    for line in fleet.failures(outcomes):
        sys.stderr.write('%s %s: error: %s\n' % (PROG, label, line))
    return outcomes, summary


def _fleet_rows(outcomes, fields):
    """Per bag: ``{'bag', 'directory', <fields of its result>}`` or ``{'bag', 'error'}``."""
    rows = []
    for outcome in outcomes:
        row = collections.OrderedDict([('bag', outcome.item.path), ('directory', outcome.item.out)])
        if outcome.ok:
            row.update((field, outcome.value[field]) for field in fields)
        else:
            row['error'] = outcome.value
        rows.append(row)
    return rows


def _fleet_end(args, summary, rows, text):
    """Print the JSON document or the text lines of a fleet run; exit status 1 when a bag failed."""
    failed = sum('error' in row for row in rows)
    summary['bags'] = rows
    summary['failed'] = failed
    if args.json:
        _print_json(summary)
    else:
        print('\n'.join(text))
        print('%d bags (%d failed), %d messages in %.1f s: %.0f messages/s (%s)' % (
            len(rows), failed, summary['messages'], summary['seconds'], summary['messages_per_second'],
            summary['engine']))
    return EXIT_BAD_INPUT if failed else EXIT_OK


@contextlib.contextmanager
def _leftovers_removed(directories):
    """On the way out (Ctrl-C, a worker lost), remove the half-written vector files of ended processes."""
    from cc_log.core import collector
    try:
        yield
    finally:
        for directory in directories:
            collector.remove_vector_leftovers(directory)


@contextlib.contextmanager
def _cut_off_reported(directory):
    """On Ctrl-C, one line per window file whose writing it cut off (a ``*.tmp-<pid>`` leftover below
    ``directory``, kept for ``cclog recover``); the windows written before are whole under their final names."""
    from cc_log.storage import recovery
    try:
        yield
    except KeyboardInterrupt:
        for root, _, _ in os.walk(directory):
            for path in recovery.scan(root):
                sys.stderr.write('%s replay: interrupted while writing %s (cclog recover makes it a window file)\n'
                                 % (PROG, path))
        raise


def _collect_many(args, specs, label, stride):
    from cc_log.offline import fleet
    bags = fleet.expand_bags(args.bag)
    with _leftovers_removed([os.path.join(args.out, name) for name in fleet.output_names(bags)]):
        outcomes, summary = _run_fleet(args, 'collect', lambda engine, progress: fleet.collect_many(
            engine, bags, args.out, specs, label, stride, single=not args.config, progress=progress))
    rows = _fleet_rows(outcomes, ('vectors', 'messages'))
    summary['vectors'] = sum(row.get('vectors', 0) for row in rows)
    lines = ['%s: %d feature vectors -> %s' % (row['bag'], row['vectors'], row['directory'])
             for row in rows if 'error' not in row]
    return _fleet_end(args, summary, rows, lines)


def _replay_many(args, cfg):
    from cc_log.offline import fleet
    bags = fleet.expand_bags(args.bag)
    _writable_dir(args.out, 'out')
    outcomes, summary = _run_fleet(args, 'replay', lambda engine, progress: fleet.replay_many(
        engine, bags, args.out, cfg, progress=progress))
    rows = _fleet_rows(outcomes, ('input_messages', 'raw_json_bytes', 'stored_bytes', 'windows', 'drift'))
    reports = {}
    for row in rows:
        row['windows'] = [collections.OrderedDict((key, w[key]) for key in ('start', 'end', 'messages', 'path'))
                          for w in row.get('windows', ())]
        reports[row['bag']] = ''.join('\n  %s' % monitor.report() for monitor in row.get('drift', ()))
        row['drift'] = [monitor.as_dict() for monitor in row.get('drift', ())]
    good = [row for row in rows if 'error' not in row]
    summary['windows'] = sum(len(row['windows']) for row in good)
    summary['saved_messages'] = sum(w['messages'] for row in good for w in row['windows'])
    summary['stored_bytes'] = sum(row['stored_bytes'] for row in good)
    return _fleet_end(args, summary, rows, ['%s: %d messages in, %d saved in %d window(s) (%s) -> %s%s' % (
        row['bag'], row['input_messages'], sum(w['messages'] for w in row['windows']), len(row['windows']),
        human_bytes(row['stored_bytes']), row['directory'], reports[row['bag']]) for row in good])


def _vector_dir(path):
    from cc_log.offline import fleet
    return fleet.holds_vectors(path)


def _sweep(args, flat, many):
    """``replay --sweep``: every combination of the --sweep values over one reading of each bag; a table."""
    from cc_log.offline import fleet, replay, sweep
    from cc_log.core.spans import Span
    from cc_log.triggers import RETRIGGER_MODES
    sweeps = []
    for combination in sweep.parse_sweep(args.sweep):
        options = copy.deepcopy(flat)
        for key, value in combination.items():
            if key in ('pre', 'post', 'classify_every'):
                Span.parse(value, 'sweep: ' + key)
                (options if key != 'classify_every' else options['classifier'])[key] = value
            elif key == 'retrigger':
                if value not in RETRIGGER_MODES:
                    raise CommandError('sweep: retrigger: %r is not one of %s' % (value, ', '.join(RETRIGGER_MODES)))
                options['classifier'][key] = value
        threshold = combination.get('threshold')
        if threshold is not None:
            threshold = _number('sweep: threshold', threshold)
        cfg = _configuration(args, options)
        replay.replay_setup(cfg)  # a bad configuration is one line before any bag
        sweeps.append(sweep.Sweep(sweep.sweep_label(combination), cfg, threshold))
    bags = fleet.expand_bags(args.bag) if many else [args.bag]
    _writable_dir(args.out, 'out')
    if not many:
        args.workers = 0
    outcomes, summary = _run_fleet(args, 'replay', lambda engine, progress: sweep.sweep_many(
        engine, bags, args.out, sweeps, progress=progress))
    rows = _fleet_rows(outcomes, ('seconds', 'anomalies', 'rows'))
    table = sweep.sweep_table([outcome.value for outcome in outcomes if outcome.ok])
    summary['configurations'] = table
    width = max([len('configuration')] + [len(line['label']) for line in table])
    text = ['%-*s %8s %10s %6s %10s %7s %9s' % (width, 'configuration', 'windows', 'kept', 'kept%', 'stored',
                                                'recall', 'false/h')]
    for line in table:
        text.append('%-*s %8d %10d %5.1f%% %10s %7s %9s' % (
            width, line['label'], line['windows'], line['kept'], 100.0 * line['kept'] / max(line['messages'], 1),
            human_bytes(line['stored_bytes']), '-' if line['recall'] is None else '%.2f' % line['recall'],
            '-' if line['false_per_hour'] is None else '%.1f' % line['false_per_hour']))
    return _fleet_end(args, summary, rows, text)


def _number(name, value):
    try:
        number = float(value)
    except ValueError:
        number = float('nan')
    if not math.isfinite(number):
        raise CommandError('%s: %r is not a number' % (name, value))
    return number


def _learn_many(args):
    """Train over every vector directory of --train (partitions) on the engine: ``(model, info)``."""
    from cc_log.offline import fleet, learn_main, partition_learning
    from cc_log.core import learning
    directories = fleet.expand_vector_dirs(args.train)
    with _engine(args) as engine:
        if args.method == partition_learning.STREAM_METHOD:
            model, info = partition_learning.train_streamed(engine, partition_learning.load_partition, directories,
                                                            nu=args.nu, gamma=args.gamma)
        else:
            vectors, config, worker_rss = partition_learning.gather_vectors(engine, directories)
            nominal, anomalous = learn_main.split_labels(vectors)
            if nominal is None:
                raise CommandError('train: %s have no %s/ vectors' % (' '.join(args.train), learn_main.NOMINAL))
            model, info = learning.train(nominal, anomalous, config, nu=args.nu, gamma=args.gamma,
                                         method=args.method)
            info['worker_peak_rss_mb'] = worker_rss
        info['partitions'] = len(directories)
        info['engine'] = engine.describe()
    return model, info


# -- commands ---------------------------------------------------------------------------------------------

def cmd_collect(args):
    """Feature vectors of a bag's driving topic into ``OUT/<label>/``, as collect mode writes them; with
    ``--config``, of every classifier's feature set into ``OUT/<name>/<label>/``."""
    from cc_log.core import collector
    from cc_log.offline import fleet
    from cc_log.core.model import AnomalyModel
    many = _fleet_wanted(args, args.bag)
    if not many:
        args.bag = _existing_file(args.bag[0], 'bag file')
    if not args.config and args.topic is None:
        raise CommandError('collect: give --topic, or --config (a configuration with classifiers)')
    single = {}
    if args.topic is not None:
        single = {'topics': [args.topic] + args.input_topic, 'feature_set': args.features or _feature_sets()[0],
                  'window': args.window or collector.DEFAULT_WINDOW}
    cfg = _configuration(args, {'label': args.label, 'stride': args.stride, 'classifier': single})
    label = cfg.label or collector.DEFAULT_LABEL
    stride = cfg.stride  # None: the default, or smaller for a short bag (collector.auto_stride)
    specs = cfg.feature_specs(AnomalyModel.load)
    if not specs:
        raise CommandError('collect: %s has no classifier: nothing to compute' % args.config)
    if many:
        return _collect_many(args, specs, label, stride)
    with _leftovers_removed([args.out]), _bar(args, 'collect') as bar:
        result = _call(fleet.collect_one, bar, args.bag, args.out, specs, label, stride, single=not args.config)
    first = specs[0][1]
    summary = collections.OrderedDict([
        ('bag', args.bag), ('topic', specs[0][2][0]), ('label', label), ('window', first.window),
        ('stride', result['stride']), ('features', first.feature_set), ('vectors', result['vectors']),
        ('directory', result['directory'])])
    if args.config:
        summary['sets'] = collections.OrderedDict(
            (name, collections.OrderedDict([('features', config.feature_set), ('window', config.window),
                                            ('topics', topics), ('vectors', result['sets'][name][0]),
                                            ('directory', result['sets'][name][1])]))
            for name, config, topics in specs)
    if args.json:
        _print_json(summary)
    else:
        for name, config, topics in specs:
            count, directory = result['sets'][name if args.config else '']
            print('%d feature vectors (%s features, window %s, every %s messages) from %s %s -> %s'
                  % (count, config.feature_set, config.window, result['strides'][name if args.config else ''],
                     args.bag, ' '.join(topics), directory))
    for name, config, topics in specs:
        if not result['sets'][name if args.config else ''][0]:
            sys.stderr.write('%s collect: warning: no vector%s: %s never filled a whole feature window of %s\n'
                             % (PROG, ' for ' + name if args.config else '', topics[0],
                                config.window + ('' if config.span.is_duration else ' messages')))
    return EXIT_OK


def _report_dict(report):
    return collections.OrderedDict((field, getattr(report, field)) for field in report._fields)


def _training_text(info):
    """What training alone (no --test) can tell: the model, its threshold, the held-out nominal check."""
    lines = ['%-16s %s, nu=%g, gamma=%.4g, %s nominal vectors (%s held out), %s anomalous' % (
        'Model', info['method'], info['nu'], info['gamma'], info['vectors_nominal'], info['vectors_held_out'],
        info['vectors_anomalous']),
        '%-16s %.4g (%s)' % ('Threshold', info['threshold'], info['threshold_rule']),
        '%-16s %d of %d held-out nominal vectors flagged (no --test directory)' % (
            'Held out', info['held_out_flagged'], info['vectors_held_out']),
        '%-16s %.2f s' % ('Training time', info['train_seconds']),
        '%-16s %.0f MB (process peak RSS)' % ('Peak memory', info['peak_rss_mb'])]
    return '\n'.join(lines)


def _save_model(model, path):
    try:
        model.save(path)
    except OSError as error:
        raise CommandError('model: cannot write %s: %s' % (path, error.strerror or error))


def cmd_learn(args):
    """Train a model (``--train``), validate it (``--test``); or evaluate an existing one (``--test`` only)."""
    from cc_log.offline import learn_main
    from cc_log.core import learning
    if args.train is None and args.test is None:
        raise CommandError('train: give --train DIR (train a model), --test DIR (evaluate --model), or both')
    many = args.train is not None and (args.method == 'stream' or _fleet_wanted(args, args.train, _vector_dir))
    if args.train is not None and not many:
        args.train = args.train[0]
    if args.train is not None:
        _parent_exists(args.model, 'model')
    summary = collections.OrderedDict([('model', args.model), ('train', args.train), ('test', args.test)])
    with _bar(args, 'learn').busy():
        try:
            if many:
                model, info = _learn_many(args)
                _save_model(model, args.model)
                report = learn_main.learn(None, args.test, args.model)[1] if args.test is not None else None
            else:
                model, report, info = learn_main.learn(args.train, args.test, args.model, args.nu, args.gamma,
                                                       args.method)
        except ValueError as error:
            if isinstance(error, CommandError):
                raise
            raise CommandError(str(error).replace('validate:', 'test:', 1))
    summary['trained'] = args.train is not None
    summary['config'] = model.config.to_dict()
    summary['threshold'] = model.threshold
    summary['info'] = {key: value for key, value in info.items() if key != 'grid'}
    summary['report'] = _report_dict(report) if report is not None else None
    if args.json:
        _print_json(summary)
        return EXIT_OK
    if report is not None:
        print(learning.format_report(report, info))
    else:
        print(_training_text(info))
    if args.train is not None:
        print('%-16s %s (%s features, window %s)' % ('Saved', args.model, model.config.feature_set,
                                                     model.config.window))
    return EXIT_OK


def cmd_tune(args):
    """Set a model's threshold, and with several --windows / --classify-every its feature window and classify
    rate, to a false-window budget on nominal bags (``tuning.choose``); write it to --out."""
    from cc_log.storage.bag import bagio
    from cc_log.offline import replay, tuning
    from cc_log.core.model import AnomalyModel
    model = AnomalyModel.load(_existing_file(args.model, 'model file'))
    for bag in args.bag:
        _existing_file(bag, 'bag file')
        replay.check_bag_topics(bag, [args.topic], {args.topic: model.config.feature.inputs[0][1]})
    _parent_exists(args.out, 'out')
    with _bar(args, 'tune').busy():
        runs = [list(bagio.read_messages(bag, [args.topic])) for bag in args.bag]
        try:
            model, record = tuning.choose(model, runs, args.topic, args.max_false_per_hour, args.windows,
                                          args.classify_every, args.pre, args.post, args.retrigger, sources=args.bag)
        except ValueError as error:
            raise CommandError(str(error))
    try:
        model.save(args.out)
    except OSError as error:
        raise CommandError('out: cannot write %s: %s' % (args.out, error.strerror or error))
    if args.json:
        _print_json(dict(record, out=args.out))
        return EXIT_OK
    if len(record['grid']) > 1:
        for g in record['grid']:
            print('window %-6s classify every %-6s threshold %-10.4g %6.1f false/h  %d caught, mean latency %s%s' % (
                g['window'], g['classify_every'], g['threshold'], g['false_per_hour'], len(g['catches']),
                '%.2f s' % g['mean_latency'] if g['mean_latency'] is not None else '-',
                ' (trained on the bags)' if g['trained'] else ''))
        print('chosen: window %s, classify every %s (%s)' % (
            record['window'], record['classify_every'], record['chosen_by']))
    print('%.3f h of nominal driving: %d false window(s) at threshold %.4g (%.1f/h), %d at %.4g (%.1f/h; budget '
          '%g/h, measured on the tuning bags)' % (
              record['hours'], record['false_windows_before'], record['threshold_before'],
              record['false_windows_before'] / record['hours'], record['false_windows'], record['threshold'],
              record['false_per_hour'], record['max_false_per_hour']))
    print('still caught (one injected anomaly each): %s; missed: %s' % (
        ', '.join(record['catches']) or 'none', ', '.join(record['misses']) or 'none'))
    print('%-16s %s' % ('Saved', args.out))
    return EXIT_OK


def _configuration(args, flat):
    """The Config of ``--config`` (if given) with the options of ``flat`` (None: not given) and the single
    classifier of ``--model``/``--topic`` over it."""
    from cc_log.core import config as config_mod
    data = config_mod.load_file(_existing_file(args.config, 'configuration file')) if args.config else {}
    side = flat.pop('side_topics', None)
    classifier = flat.pop('classifier', {})
    data = config_mod.with_flat(data, flat)
    if side:
        topics = data.get('topics') or []
        data['topics'] = (topics.replace(',', ' ').split() if isinstance(topics, str) else list(topics)) + side
    data = config_mod.with_classifier(data, **classifier)
    return config_mod.Config.from_dict(data, args.config or 'options')


def cmd_replay(args):
    """The smart logger (the live node's SmartLogger) fed from a bag as fast as it can be read, with the
    triggers of ``--config`` and/or the classifier of ``--model`` on ``--topic``."""
    from cc_log.offline import replay
    many = _fleet_wanted(args, args.bag)
    if not many:
        args.bag = _existing_file(args.bag[0], 'bag file')
    if not args.config and (args.topic is None or args.model is None):
        raise CommandError('replay: give --topic and --model, or --config (a configuration with triggers)')
    if args.model is not None:
        _existing_file(args.model, 'model file')
    if args.model is not None and args.topic is None:
        raise CommandError('replay: --model needs --topic (the topic the model reads)')
    flat = {'pre': args.pre, 'post': args.post, 'format': args.format, 'max_buffer_mb': args.max_buffer_mb,
            'precision': args.precision, 'driving_topic': args.topic,
            'side_topics': [t for t in args.side_topic if t != args.topic],
            'classifier': {'model': args.model, 'topics': [args.topic] if args.model else None,
                           'classify_every': args.classify_every, 'retrigger': args.retrigger}}
    cfg = _configuration(args, copy.deepcopy(flat))
    if args.sweep:
        return _sweep(args, flat, many)
    if many:
        replay.replay_setup(cfg)  # a bad configuration is one line before any bag
        with _cut_off_reported(args.out):
            return _replay_many(args, cfg)
    with _cut_off_reported(args.out), _bar(args, 'replay') as bar:
        summary = replay.replay_one(args.bag, args.out, cfg, bar.set, lambda path: _writable_dir(path, 'out'))
    result = collections.OrderedDict([
        ('input_messages', summary['input_messages']),
        ('raw_json_bytes', summary['raw_json_bytes']),
        ('stored_bytes', summary['stored_bytes']),
        ('windows', [collections.OrderedDict([('start', w['start']), ('end', w['end']),
                                              ('messages', w['messages']), ('path', w['path'])])
                     for w in summary['windows']]),
        ('drift', [monitor.as_dict() for monitor in summary['drift']]),
    ])
    if args.json:
        _print_json(result)
        return EXIT_OK
    windows = result['windows']
    saved = sum(window['messages'] for window in windows)
    print('%s %s: %d messages in, %d saved in %d window(s) (%s files in %s)'
          % (args.bag, summary['driving_topic'], result['input_messages'], saved, len(windows), cfg.format, args.out))
    ratio = _ratio(result['raw_json_bytes'], result['stored_bytes'])
    print('  raw row-per-message JSON %s, stored %s%s' % (
        human_bytes(result['raw_json_bytes']), human_bytes(result['stored_bytes']),
        ' (%.1fx smaller)' % ratio if ratio else ''))
    for number, window in enumerate(windows, 1):
        print('  %3d  %s .. %s  %7.2f s  %6d msgs  %s' % (
            number, _stamp_text(window['start']), _stamp_text(window['end']), window['end'] - window['start'],
            window['messages'], window['path']))
    for monitor in summary['drift']:
        print('  %s' % monitor.report())
    return EXIT_OK


def cmd_info(args):
    """Windows, time spans, message counts, sizes, codec, trigger and scores of window files."""
    windows = [_window_summary(path, metadata, records)
               for path, metadata, records in _read_windows(args, args.paths, 'info')]
    total = collections.OrderedDict([
        ('windows', len(windows)),
        ('messages', sum(w['messages'] for w in windows)),
        ('bytes', sum(w['bytes'] for w in windows)),
        ('raw_json_bytes', sum(w['raw_json_bytes'] for w in windows)),
        ('start', min(w['start'] for w in windows) if windows else None),
        ('end', max(w['end'] for w in windows) if windows else None),
    ])
    total['ratio'] = _ratio(total['raw_json_bytes'], total['bytes'])
    if args.json:
        _print_json(collections.OrderedDict([('windows', windows), ('total', total)]))
        return EXIT_OK
    for w in windows:
        _say(w['path'])
        _say('  codec      %s' % w['codec'])
        utc = ', from %s' % w['start_utc'] if w['start_utc'] else ''
        _say('  span       %s .. %s  (%.2f s%s)' % (_stamp_text(w['start']), _stamp_text(w['end']),
                                                    w['duration'] or 0.0, utc))
        _say('  messages   %d: %s' % (w['messages'], ', '.join('%s %d' % item for item in w['topics'].items())))
        _say('  topic MB   %s (serialized)' % ', '.join(
            '%s %.2f' % (topic, size / 1e6) for topic, size in sorted(w['topic_bytes'].items(), key=lambda i: -i[1])))
        if w['dropped']:
            _say('  DROPPED    %d messages the writer could not keep up with: %s' % (
                sum(w['dropped'].values()), ', '.join('%s %d' % item for item in sorted(w['dropped'].items()))))
        _say('  size       %s (row JSON %s, %s)' % (
            human_bytes(w['bytes']), human_bytes(w['raw_json_bytes']),
            '%.1fx' % w['ratio'] if w['ratio'] else '-'))
        if w['triggers']:
            scores = [t['score'] for t in w['triggers'] if t['score'] is not None]
            _say('  trigger    %s, %d trigger(s)%s%s' % (
                w['reason'], len(w['triggers']),
                ', scores %.4g .. %.4g' % (min(scores), max(scores)) if scores else '',
                ', threshold %.4g' % w['threshold'] if isinstance(w['threshold'], (int, float)) else ''))
        if w['part']:
            _say('  part       %s of a window split at max_window' % w['part'])
    _say('%d window(s), %d messages, %s on disk, %s as row JSON%s' % (
        total['windows'], total['messages'], human_bytes(total['bytes']), human_bytes(total['raw_json_bytes']),
        ' (%.1fx)' % total['ratio'] if total['ratio'] else ''))
    return EXIT_OK


def _cc_log_json(path):
    """A cc_log JSON file (model, feature vector, simulator truth); CommandError when it is none of them."""
    from cc_log.core import safe_input
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
    from cc_log.core import safe_input
    with safe_input.open_input(path) as stream:
        return formats.by_magic(stream.read(16)) is not None


def cmd_cat(args):
    """Decode cc_log files to JSON lines on stdout (window records; models, vectors, truth as one line)."""
    topics = set(args.topic) if args.topic else None
    out = sys.stdout
    for argument in args.paths:
        if os.path.isfile(argument) and not _is_window_file(argument) and not formats.by_extension(argument):
            out.write(json.dumps(_plain(_cc_log_json(argument)), allow_nan=False) + '\n')
            continue
        for path, metadata, records in _read_windows(args, [argument], 'cat'):
            if args.metadata:
                out.write(json.dumps(_plain({'file': path, 'metadata': metadata}), allow_nan=False) + '\n')
            for record in records:
                if topics is None or record.topic in topics:
                    out.write(json.dumps(_plain(export.record_row(record, path if args.with_file else None)),
                                         allow_nan=False) + '\n')
    return EXIT_OK


def _selected_records(args):
    """All records of the window files named by ``args.paths`` (``--topic`` filter), in stamp order."""
    topics = set(args.topic) if args.topic else None
    records = []
    for _, _, window in _read_windows(args, args.paths, 'read'):
        records.extend(record for record in window if topics is None or record.topic in topics)
    records.sort(key=lambda record: record.stamp)
    if not records:
        raise CommandError('topic: no messages of %s in %s' % (', '.join(sorted(topics)), ', '.join(args.paths))
                           if topics else '%s: no messages' % ', '.join(args.paths))
    return records


def cmd_export(args):
    """Window files to one bag, one CSV per topic, or one JSON-lines file (``export``)."""
    records = _selected_records(args)
    if args.to == 'jsonl':
        _parent_exists(args.out, 'out')
        files = export.to_jsonl(records, args.out)
    elif args.to in ('bag', 'mcap'):
        _parent_exists(args.out, 'out')
        if os.path.exists(args.out) and not args.force:
            raise CommandError('out: %s exists (use --force to overwrite)' % args.out)
        with _bar(args, 'export', len(records)) as bar:
            write = export.to_bag if args.to == 'bag' else export.to_mcap
            files = write(records, args.out, args.compression, bar.update)
    elif args.to == 'png':
        return _export_frames(args, records)
    else:
        _writable_dir(args.out, 'out')
        files = export.to_csv(records, args.out)
    summary = collections.OrderedDict([('to', args.to), ('messages', len(records)),
                                       ('topics', sorted(set(record.topic for record in records))),
                                       ('files', files)])
    if args.json:
        _print_json(summary)
    else:
        print('%d messages of %d topic(s) -> %s' % (len(records), len(summary['topics']), ', '.join(files)))
    return EXIT_OK


def _export_frames(args, records):
    """``export --to png``: every camera frame as a PNG (or its own JPEG) file in the directory ``--out``."""
    from cc_log.core import raw_message
    frames = [record for record in records if raw_message.type_of(record) in export.IMAGE_TYPES]
    if not frames:
        raise CommandError('%s: no sensor_msgs/Image or CompressedImage messages' % ', '.join(args.paths)[:200])
    _writable_dir(args.out, 'out')
    skipped = {}
    with _bar(args, 'export', len(frames)) as bar:
        files = export.to_frames(frames, args.out, skipped, bar.update)
    summary = collections.OrderedDict([('to', args.to), ('frames', len(files)),
                                       ('topics', sorted(set(record.topic for record in frames))),
                                       ('directory', args.out), ('skipped', skipped), ('files', files)])
    if args.json:
        _print_json(summary)
        return EXIT_OK
    print('%d frame(s) of %s -> %s' % (len(files), ', '.join(summary['topics']), args.out))
    for reason, count in sorted(skipped.items()):
        print('  skipped %d frame(s): %s' % (count, reason))
    return EXIT_OK


def cmd_codecs(args):
    """The paper's Table 2 on the row-per-message JSON of a bag topic or of window files."""
    from cc_log.storage import codecs
    from cc_log.core import msg_codec
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
        records = _selected_records(args)
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
        _print_json(result)
        return EXIT_OK
    print('%d messages, %s of row-per-message JSON (%s)' % (
        len(records), human_bytes(len(data)), ', '.join(source['topics'])))
    print(codecs.format_table(rows))
    print('ratio: compressed size in % of the raw JSON; MB/s: raw JSON compressed per second')
    return EXIT_OK


def _is_plain_bag(path):
    """True for a rosbag that is not a cc_log bag-lz4 window file (which ``codecs`` reads as a LOG)."""
    from cc_log.core import safe_input
    from cc_log.storage.formats import bag_lz4
    with safe_input.open_input(path) as stream:
        if not stream.read(16).startswith(bag_lz4.MAGIC):
            return False
    return not os.path.basename(path).startswith('cc_log_')


def cmd_plot(args):
    """A timeline: speed of the driving topic with the saved windows shaded (and the true events of
    ``--truth``), and the scores with the threshold (``plot``)."""
    from cc_log.offline import plot
    windows = []
    driving = args.topic
    for path, metadata, records in _read_windows(args, args.paths, 'plot'):
        driving = driving or metadata.get('driving_topic')
        windows.append((path, metadata, records))
    if not driving:
        raise CommandError('topic: the windows do not name their driving topic; give --topic')
    truth = plot.load_truth(args.truth) if args.truth else []
    if args.bag:
        from cc_log.storage.bag import bagio
        bag = bagio.open_bag(args.bag)
        try:
            bagio.check_topic(bag, driving, plot.ODOMETRY)
            total = bag.get_message_count([driving])
        finally:
            bag.close()
        speed = []
        with _bar(args, 'read', total) as bar:
            for record in bagio.read_messages(args.bag, [driving]):
                speed.append((record.stamp,) + plot.motion_of(record.msg))
                bar.update()
    else:
        speed = plot.window_speeds(windows, driving)
        if not any(speed):
            raise CommandError('topic: no nav_msgs/Odometry messages on %s in the windows' % driving)
    curve, threshold = [], None
    if args.model:
        from cc_log.core.model import AnomalyModel
        if not args.bag:
            raise CommandError('model: --model scores the whole run and needs --bag')
        model = AnomalyModel.load(args.model)
        threshold = model.threshold
        with _bar(args, 'score').busy():
            curve = plot.run_scores(args.bag, driving, model, args.stride)
    _parent_exists(args.out, 'out')
    title = args.title or '%s: %d saved window(s)%s' % (
        args.bag or ', '.join(args.paths), len(windows), '' if args.bag else ' (speed inside the windows only)')
    summary = plot.timeline(args.out, windows, speed, curve, threshold, truth, title, args.width, args.dpi,
                            'speed (%s)' % driving)
    if args.json:
        _print_json(summary)
    else:
        print('%s: %d window(s), %d trigger score(s), %d speed samples%s' % (
            args.out, len(windows), summary['triggers'], summary['speed_samples'],
            ', %d of %d true events inside windows' % (summary['truth_in_windows'], len(truth)) if truth else ''))
    return EXIT_OK


def cmd_simulate(args):
    """A simulated BWIBot bag with labelled anomalies, and ``<bag>.truth.json``."""
    from cc_log import sim
    _parent_exists(args.out, 'out')
    if os.path.exists(args.out) and not args.force:
        raise CommandError('out: %s exists (use --force to overwrite)' % args.out)
    config = sim.SimConfig(rate=args.rate, seed=args.seed, minutes=args.minutes, anomalies=args.anomalies,
                           imu=args.imu, commands=args.commands,
                           **({'anomaly_types': args.types} if args.types else {}))
    with _bar(args, 'simulate') as bar:
        truth = _call(sim.simulate_to_bag, bar, args.out, config)
    truth_path = sim.truth_path(args.out)
    summary = collections.OrderedDict([('bag', args.out), ('truth', truth_path), ('minutes', args.minutes),
                                       ('rate', args.rate), ('seed', args.seed), ('anomalies', len(truth)),
                                       ('bytes', os.path.getsize(args.out)), ('truth_anomalies', truth)])
    if args.json:
        _print_json(summary)
    else:
        print('%s: %.1f min at %g Hz, %d anomalies (%s), %s' % (
            args.out, args.minutes, args.rate, len(truth), truth_path, human_bytes(summary['bytes'])))
    return EXIT_OK


def cmd_stats(args):
    """Distance, time moving/stopped, windows per hour by trigger, bytes vs rosbag record (``stats``)."""
    from cc_log.offline import stats
    result = stats.run_stats(args.directory, stats.parse_time(args.since, 'since') if args.since else None,
                             stats.parse_time(args.until, 'until') if args.until else None, args.odom)
    if args.json:
        _print_json(result)
    else:
        for line in stats.format_text(result):
            _say(line)
    return EXIT_OK


def cmd_recover(args):
    """Leftovers of a crash (``cc_log_*.tmp-<pid>``) turned back into window files, or reported."""
    from cc_log.storage import recovery
    outcomes = []
    for path in args.paths:
        if os.path.isdir(path):
            outcomes.extend(recovery.recover_directory(path))
        elif os.path.exists(path):
            outcomes.append(recovery.recover(path))
        else:
            raise CommandError('%s: no such file or directory' % path)
    if args.json:
        _print_json({'leftovers': [outcome._asdict() for outcome in outcomes]})
    else:
        for outcome in outcomes:
            target = ' -> %s (%d messages)' % (outcome.path, outcome.messages) if outcome.path else ''
            print('%-13s %s%s: %s' % (outcome.status, outcome.leftover, target, outcome.detail))
        if not outcomes:
            print('no leftovers')
        elif len(outcomes) > 1:
            print('%d leftovers: %d messages recovered, %d bytes could not be' % (
                len(outcomes), sum(o.messages for o in outcomes), sum(o.lost_bytes for o in outcomes)))
    return EXIT_BAD_INPUT if recovery.incomplete(outcomes) else EXIT_OK


# -- parser -----------------------------------------------------------------------------------------------

class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``cclog replay: error: ... (see cclog replay --help)``, status 2."""

    def error(self, message):
        self.exit(EXIT_USAGE, '%s: error: %s (see %s --help)\n' % (self.prog, message, self.prog))


def _help(description, examples):
    return dict(description=textwrap.dedent(description).strip(),
                epilog='examples:\n' + textwrap.indent(textwrap.dedent(examples).strip('\n'), '  '),
                formatter_class=argparse.RawDescriptionHelpFormatter)


def _common(parser, json_help=True):
    if json_help:
        parser.add_argument('--json', action='store_true', help='print one JSON object on stdout')
    group = parser.add_mutually_exclusive_group()
    group.add_argument('--progress', dest='progress', action='store_true', default=None,
                       help='progress bar on stderr even when it is not a terminal')
    group.add_argument('--no-progress', dest='progress', action='store_false',
                       help='no progress bar, even on a terminal')


def _fleet_options(parser):
    """--workers and --scheduler of the commands that take many bags."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument('--workers', type=_non_negative_int('workers'), metavar='N',
                       help='many bags: a local Dask cluster of N worker processes (default: the cores); 0: run '
                       'every bag in this process')
    group.add_argument('--scheduler', metavar='ADDRESS',
                       help='many bags: the Dask cluster of this scheduler (tcp://host:8786) instead')


def build_parser():
    """The ``cclog`` argument parser (one sub-parser per command)."""
    parser = _Parser(prog=PROG, **_help(
        """
        cc_log offline tool: tune the anomaly logger on bags you already have. No roscore needed.

        Results go to stdout (--json: one JSON object); progress bars to stderr (on a terminal or with
        --progress). Bad input prints one line "cclog <command>: error: ..." and exits 1 (2 for bad
        command-line syntax).
        """,
        """
          cclog simulate --minutes 10 --anomalies 6 --seed 1 sim.bag
          cclog collect husky.bag --topic /husky_velocity_controller/odom --out vectors
          cclog learn --train vectors --model model.json
          cclog replay husky.bag --topic /husky_velocity_controller/odom --model model.json --out logs --json
          cclog info logs
          cclog plot logs --bag husky.bag --out run.png
        """))
    parser.add_argument('--version', action='version', version='%(prog)s ' + _version())
    commands = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=_Parser)
    commands.required = True

    p = commands.add_parser('collect', help='feature vectors of a bag into DIR/<label>/ (collect mode)', **_help(
        """
        Collect mode from a bag: run the features over the driving topic (nav_msgs/Odometry) and write one
        feature vector file per --stride messages into DIR/<label>/, as the collect node does live. Those
        directories are what `cclog learn --train` reads; label a run "nominal" or after its anomaly. A
        vector that cannot be written (disk full) is retried for a few seconds; then collect exits 1 with one
        line naming DIR/<label> and how many vectors were not written.
        """,
        """
          cclog collect husky.bag --topic /husky_velocity_controller/odom --out train
          cclog collect crash.bag --topic /odom --out test --label crash --window 5s --stride 5
          cclog collect run.bag --topic /odom --out train --window 200 --json
        """))
    p.add_argument('bag', nargs='+', metavar='BAG', help='input bag (indexed, rosbag 2.0); several, a directory '
                   '(its *.bag) or a glob: one Dask task each, vectors into DIR/<bag name>/<label>/')
    p.add_argument('--config', metavar='YAML', help='configuration: vectors of every classifier (its feature set '
                   'and window, else its model\'s) into DIR/<name>/<label>/; collect.label and collect.stride too')
    p.add_argument('--topic', metavar='T', help="driving topic: the feature set's first input "
                   '(nav_msgs/Odometry; imu: sensor_msgs/Imu); needed without --config')
    p.add_argument('--out', required=True, metavar='DIR', help='vectors go to DIR/<label>/')
    p.add_argument('--label', help='label directory (default: nominal; anything but '
                   '"nominal" counts as anomalous)')
    p.add_argument('--window', type=_span('window'), metavar='N|Ns',
                   help='feature window: messages (500) or seconds (5s) (default: 500)')
    p.add_argument('--stride', type=_non_negative_int('stride', 1), metavar='N',
                   help='a vector every N driving messages (default: %d, or smaller so that a short bag '
                   'still gives about 200 vectors)' % _collect_stride())
    p.add_argument('--features', choices=_feature_sets(),
                   help='feature set (default: %s)' % _feature_sets()[0])
    p.add_argument('--input-topic', action='append', default=[], metavar='T',
                   help="a topic of the feature set's other inputs, in its order (command: the cmd_vel topic)")
    _fleet_options(p)
    _common(p)
    p.set_defaults(run=cmd_collect)

    p = commands.add_parser('learn', help='train the model (learn mode), validate or evaluate it', **_help(
        """
        Learn mode. --train DIR holds <label>/<stamp>.json vector files (from `cclog collect` or the
        collect node); DIR/nominal/ alone is enough (the threshold is then set on held-out nominal
        blocks); other labels count as anomalous and tune nu, gamma and the threshold. --test DIR (disjoint
        from --train) is scored with the new model: the paper's table (TP, FP, FN, TN, precision, recall).
        Without --train, --test evaluates the existing --model (the vectors must have its feature
        configuration).
        """,
        """
          cclog learn --train vectors --model model.json
          cclog learn --train train --test test --model model.json --json
          cclog learn --test test --model model.json          # evaluate an existing model
        """))
    p.add_argument('--train', nargs='+', metavar='DIR', help='training vectors (DIR/nominal/ at least); several '
                   'directories, a glob, or the DIR of `cclog collect` over many bags: one Dask task each')
    p.add_argument('--test', metavar='DIR', help='test vectors, disjoint from --train')
    p.add_argument('--model', required=True, metavar='PATH', help='model file to write (or to evaluate)')
    p.add_argument('--nu', type=_positive_float('nu'), help='one-class SVM nu (default: learning default or grid)')
    p.add_argument('--gamma', type=_positive_float('gamma'), help='RBF gamma (default: learning default or grid)')
    p.add_argument('--method', default='auto', choices=('auto', 'exact', 'nystroem', 'stream'),
                   help='exact OneClassSVM, Nystroem + SGD, auto, or stream: Nystroem + SGD partial_fit over the '
                   'directories, never all vectors in one process (default: %(default)s)')
    _fleet_options(p)
    _common(p)
    p.set_defaults(run=cmd_learn)

    p = commands.add_parser('tune', help='set a model\'s threshold to a false-window budget on nominal bags', **_help(
        """
        Replay nominal bags through the classifier trigger the smart logger runs (--classify-every,
        --retrigger), merge its fires into windows (--pre, --post) and lower the model's threshold until
        the bags give at most --max-false-per-hour windows per hour; then inject one anomaly of every
        simulator type into the first bag and report which the tuned model still catches. The model
        written to --out records what it was tuned for (info.tuned). Figures on the tuning bags are
        in-sample: check on other nominal bags with cclog replay.
        """,
        """
          cclog tune --model model.json --bag nominal.bag --topic /odom --max-false-per-hour 1 --out tuned.json
        """))
    p.add_argument('--model', required=True, metavar='PATH', help='the model to tune (not changed)')
    p.add_argument('--bag', required=True, action='append', metavar='BAG', help='a nominal bag (repeatable)')
    p.add_argument('--topic', required=True, metavar='T', help="the model's driving topic in the bags")
    p.add_argument('--max-false-per-hour', required=True, type=_positive_float('max-false-per-hour', zero=True),
                   metavar='N', help='false-window budget')
    p.add_argument('--out', required=True, metavar='PATH', help='the tuned model file to write')
    p.add_argument('--pre', type=_span('pre'), default='2s', metavar='N|Ns', help='(default: %(default)s)')
    p.add_argument('--post', type=_span('post'), default='2s', metavar='N|Ns', help='(default: %(default)s)')
    p.add_argument('--classify-every', type=_spans('classify_every'), default=['50ms'], metavar='N|Ns[,...]',
                   help='classify rate, or several to choose from (default: 50ms)')
    p.add_argument('--windows', type=_spans('windows'), default=None, metavar='W[,...]',
                   help='feature windows to choose from, e.g. 1s,2s,5s (another window than the model\'s is trained '
                        'on the bags; default: the model\'s)')
    p.add_argument('--retrigger', choices=_retrigger_modes(), default='event', help='(default: %(default)s)')
    _common(p)
    p.set_defaults(run=cmd_tune)

    p = commands.add_parser('replay', help='the smart logger over a bag (windows around anomalies)', **_help(
        """
        Smart mode offline: feed the bag, as fast as it can be read, to the same SmartLogger the live node
        runs, with the triggers of --config (the YAML file smart_logger.py reads: classifiers, rules) and/or
        a classifier scoring --topic with --model. Every trigger saves --pre messages before and --post
        after (counts or durations), with the --side-topic messages of that time span, as window files in
        OUT; options given override the configuration. --json prints {input_messages, raw_json_bytes,
        stored_bytes, windows: [{start, end, messages, path}]}; start/end are the header stamps (float
        seconds) of the first and last message saved. A window that cannot be written (disk full) is retried
        for a few seconds; then replay stops and exits 1 with one line naming OUT and how many windows and
        messages were not written.
        """,
        """
          cclog replay husky.bag --topic /husky_velocity_controller/odom --model model.json --out logs
          cclog replay crash.bag --topic /odom --model model.json --out logs --pre 2s --post 2s --json
          cclog replay crash.bag --topic /odom --side-topic /scan --model m.json --out logs --format bag-lz4
          cclog replay run.bag --config robot.yaml --out logs --classify-every 1 --retrigger onset
        """))
    p.add_argument('bag', nargs='+', metavar='BAG', help='input bag; several, a directory (its *.bag) or a glob: '
                   'one Dask task each, windows into OUT/<bag name>/')
    p.add_argument('--config', metavar='YAML', help='configuration (topics, triggers, windows, format, limits): '
                   'the file smart_logger.py reads; the options below override it')
    p.add_argument('--topic', metavar='T', help="driving topic (the model's message type); needed without --config")
    p.add_argument('--model', metavar='PATH', help='model file (cclog learn) of a classifier on --topic; needed '
                   'without --config')
    p.add_argument('--out', required=True, metavar='DIR', help='directory for the window files')
    p.add_argument('--pre', type=_span('pre'), metavar='N|Ns',
                   help='messages (100) or seconds (2s) kept before an anomaly (default: 100)')
    p.add_argument('--post', type=_span('post'), metavar='N|Ns',
                   help='messages or seconds kept after the last anomaly (default: 100)')
    p.add_argument('--format', choices=formats.names(), help='window file format (default: %s)' % formats.DEFAULT)
    p.add_argument('--precision', metavar='FIELD=STEP,...',
                   help="json-xz, lossy (opt-in): round fields to a step, e.g. 'pose.pose.position.*=1e-4,"
                        "twist.twist.*=1e-5' (recorded in each window's metadata; default: lossless)")
    p.add_argument('--side-topic', action='append', default=[], metavar='T',
                   help='another topic to save inside the windows (repeatable)')
    p.add_argument('--classify-every', type=_span('classify-every'), metavar='N|Ns',
                   help='score every N-th message or at most once per duration (default: 50ms)')
    p.add_argument('--retrigger', choices=_retrigger_modes(),
                   help='event: the onset opens a window, extended while the newest rows are anomalous; every: '
                   'every anomalous score extends a window; onset: only the onset (default: event)')
    p.add_argument('--max-buffer-mb', type=_positive_float('max-buffer-mb', zero=True),
                   metavar='MB', help='memory budget of every message buffered (estimated); a window reaching it '
                   'is written in parts; 0: none (default: %g)' % _max_buffer_mb())
    p.add_argument('--sweep', action='append', default=[], metavar='KEY=V1,V2',
                   help='evaluate every combination of these values (keys: threshold, pre, post, classify_every, '
                   'retrigger; repeatable) over one reading of each bag: a table of windows, messages kept, bytes '
                   'stored and, with <bag>.truth.json files, recall and false windows per hour; windows go to '
                   'OUT/<bag name>/<configuration>/')
    _fleet_options(p)
    _common(p)
    p.set_defaults(run=cmd_replay)

    p = commands.add_parser('info', help='windows, spans, counts, sizes, codec, triggers, scores', **_help(
        """
        Describe window files: time span, messages per topic, size on disk and as row-per-message JSON,
        codec, the trigger(s) that opened the window with their scores, and the model threshold. PATH is a
        window file or a directory of them (read in time order).
        """,
        """
          cclog info logs
          cclog info logs/cc_log_20150521T191138.027Z_classifier.json.xz --json
        """))
    p.add_argument('paths', nargs='+', metavar='PATH', help='window file or directory')
    _common(p)
    p.set_defaults(run=cmd_info)

    p = commands.add_parser('cat', help='decode cc_log files to JSON lines', **_help(
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
    _common(p, json_help=False)
    p.set_defaults(run=cmd_cat)

    p = commands.add_parser('export', help='window files to a bag, MCAP, CSV, JSON lines or PNG frames', **_help(
        """
        Export the messages of window files (merged, in stamp order) to one rosbag (messages on their own
        topics, stamp as bag time), to one MCAP file (ROS 1 profile, for Foxglove and PlotJuggler; needs the
        optional Python package mcap: /usr/bin/python3 -m pip install --break-system-packages mcap), to CSV
        (--out is a directory: one <topic>.csv per topic, a "stamp" column then one column per field; arrays
        as JSON), to one JSON-lines file, or the camera frames to
        images (--to png, --out is a directory: each sensor_msgs/Image as <topic>_<stamp>.png, rgb8, bgr8,
        rgba8, bgra8, mono8, 16UC1/mono16 with their values, 32FC1 depth as 16-bit millimetres; each
        CompressedImage as its own .jpg or .png bytes; existing files are never overwritten).
        """,
        """
          cclog export logs --to bag --out anomalies.bag
          cclog export logs --to mcap --out anomalies.mcap --compression lz4
          cclog export logs/cc_log_20150521T191138.027Z_classifier.json.xz --to csv --out csv/
          cclog export logs --to jsonl --out all.jsonl --topic /odom
          cclog export logs --to png --out frames/ --topic /camera/image_raw
        """))
    p.add_argument('paths', nargs='+', metavar='PATH', help='window file or directory')
    p.add_argument('--to', required=True, choices=EXPORT_TARGETS, help='output kind')
    p.add_argument('--out', required=True, metavar='PATH',
                   help='output file (bag, mcap, jsonl) or directory (csv, png)')
    p.add_argument('--topic', action='append', metavar='T', help='only this topic (repeatable)')
    p.add_argument('--compression', default='none', choices=export.BAG_COMPRESSIONS,
                   help='bag compression; MCAP: none or lz4 (default: %(default)s)')
    p.add_argument('--force', action='store_true', help='overwrite an existing bag or MCAP file')
    _common(p)
    p.set_defaults(run=cmd_export)

    p = commands.add_parser('codecs', help="the paper's Table 2 on some data", **_help(
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
    _common(p)
    p.set_defaults(run=cmd_codecs, paths=None)

    p = commands.add_parser('plot', help='timeline of a run with windows and scores (PNG)', **_help(
        """
        Draw a timeline: speed of the driving topic (nav_msgs/Odometry) over time with the saved windows
        shaded, and below it the classifier scores of the triggers and the model threshold. With --bag the
        speed curve covers the whole run, else only the messages inside the windows; with --bag and
        --model the model's score of every feature window of the run is drawn too; with --truth the true
        events, so a window that was or was not kept can be told from the score. Uses matplotlib's Agg
        backend (no display needed).
        """,
        """
          cclog plot logs --bag husky.bag --out run.png
          cclog plot logs --bag husky.bag --model model.json --out run-scores.png
          cclog plot logs/cc_log_20150521T191138.027Z_classifier.json.xz --out window.png
          cclog plot logs --bag sim.bag --model model.json --truth sim.bag.truth.json --out why.png
        """))
    p.add_argument('paths', nargs='+', metavar='PATH', help='window file or directory')
    p.add_argument('--out', required=True, metavar='PNG', help='image to write')
    p.add_argument('--bag', metavar='BAG', help='the full run, for the speed curve')
    p.add_argument('--topic', metavar='T', help='driving topic (default: the windows\' driving_topic)')
    p.add_argument('--model', metavar='PATH', help='with --bag: draw this model\'s score over the whole run')
    p.add_argument('--truth', metavar='JSON', help='true events to draw: cclog simulate\'s <bag>.truth.json, or a '
                   'JSON list of {type, start, end}')
    p.add_argument('--stride', type=_non_negative_int('stride', 1), default=1, metavar='N',
                   help='with --model: score every N-th message (default: %(default)s)')
    p.add_argument('--title', help='figure title')
    p.add_argument('--width', type=_positive_float('width'), default=11.0, help='inches (default: %(default)s)')
    p.add_argument('--dpi', type=_non_negative_int('dpi', 10), default=100, help='(default: %(default)s)')
    _common(p)
    p.set_defaults(run=cmd_plot)

    p = commands.add_parser('simulate', help='a simulated BWIBot bag with labelled anomalies', **_help(
        """
        Simulate the BWIBot driving (nav_msgs/Odometry, optionally IMU) with labelled anomalies and write a
        bag plus OUT.truth.json (the anomalies: time spans and types).
        """,
        """
          cclog simulate --minutes 10 --anomalies 6 --seed 1 out.bag
          cclog simulate --minutes 2 --anomalies 0 --seed 7 nominal.bag --json
        """))
    p.add_argument('out', metavar='OUT.bag', help='bag to write (OUT.bag.truth.json next to it)')
    p.add_argument('--minutes', type=_positive_float('minutes'), default=10.0, help='(default: %(default)s)')
    p.add_argument('--anomalies', type=_non_negative_int('anomalies'), default=6, help='(default: %(default)s)')
    p.add_argument('--seed', type=_non_negative_int('seed'), default=1, help='(default: %(default)s)')
    p.add_argument('--rate', type=_positive_float('rate'), default=_sim_rate(),
                   help='odometry Hz (default: %(default)s)')
    p.add_argument('--types', metavar='A,B', help='anomaly types to draw from (default: all)')
    p.add_argument('--imu', action='store_true', help='also write sensor_msgs/Imu')
    p.add_argument('--commands', action='store_true', help='also write the planner\'s /cmd_vel and a move_base-like '
                   '/move_base/status')
    p.add_argument('--force', action='store_true', help='overwrite an existing bag')
    _common(p)
    p.set_defaults(run=cmd_simulate)

    p = commands.add_parser('recover', help='turn crash leftovers (*.tmp-<pid>) back into window files', **_help(
        """
        A logger killed while writing a window leaves cc_log_*.tmp-<pid>. recover gives a complete leftover
        its final name, rebuilds a cut-off bag-lz4 window from every message it still holds
        (..._recovered.bag; the leftover is kept as *.unrecovered-<pid> when some of its bytes could not be
        decoded), removes empty leftovers and duplicates of final files, and reports the rest, which it
        keeps. The smart node does the same at start. Exit status 1 when anything could not be recovered.
        """,
        """
          cclog recover ~/.ros/cc_log
          cclog recover ~/.ros/cc_log/cc_log_20150521T191138.027Z_classifier.bag.tmp-4242 --json
        """))
    p.add_argument('paths', nargs='+', metavar='DIR|FILE', help='window directories or leftover files')
    _common(p)
    p.set_defaults(run=cmd_recover)

    p = commands.add_parser('stats', help='distance, time moving, windows per hour, bytes vs rosbag record', **_help(
        """
        What the robot did and what cc_log kept, from the context track (DIR/context/*.bag) and the windows
        in DIR: distance driven (odometry of the context track, chords lengthened to arcs), time moving and
        stopped, windows (and per hour) by trigger, bytes stored against an estimate of what rosbag record of
        the same topics would have stored (full rates measured inside windows). --since/--until: seconds or a
        UTC time.
        """,
        """
          cclog stats ~/.ros/cc_log
          cclog stats ~/.ros/cc_log --since 2026-01-01 --until 2026-02-01T00:00:00Z --json
        """))
    p.add_argument('directory', metavar='DIR', help='a cc_log directory (windows, context/)')
    p.add_argument('--since', help='count from this stamp (seconds or UTC time)')
    p.add_argument('--until', help='count up to this stamp (seconds or UTC time)')
    p.add_argument('--odom', help='the odometry topic of the context track (default: the one with most messages)')
    _common(p)
    p.set_defaults(run=cmd_stats)
    return parser


def _version():
    from cc_log import __version__
    return __version__


def _collect_stride():
    try:
        from cc_log.core.collector import DEFAULT_STRIDE
    except ImportError:
        return 25
    return DEFAULT_STRIDE


def _retrigger_modes():
    from cc_log.triggers import RETRIGGER_MODES
    return RETRIGGER_MODES


def _feature_sets():
    from cc_log.features import FEATURE_SETS
    return FEATURE_SETS


def _max_buffer_mb():
    from cc_log.core.window_buffer import DEFAULT_MAX_BUFFER_MB
    return DEFAULT_MAX_BUFFER_MB


def _sim_rate():
    try:
        from cc_log.sim import SimConfig
        return SimConfig().rate
    except ImportError:
        return 100.0


# -- main -------------------------------------------------------------------------------------------------

def _one_line(error):
    text = ' '.join(part.strip() for part in str(error).strip().splitlines() if part.strip())
    return text or type(error).__name__


class Interrupt(object):
    """Ctrl-C (SIGINT) while a command runs: KeyboardInterrupt, as Python's own handler raises it. What the
    command then finishes (the window writer writing the window that was open) may take ``grace`` seconds at
    most: then a second KeyboardInterrupt stops that wait too, so the command ends within about a second.
    Files are written under a temporary name and renamed whole, so a window cut off this way leaves no
    partial file under a final name. ``grace`` None: no second interrupt (set while a Dask cluster runs: its
    workers must end before their leftovers are removed)."""

    def __init__(self, grace=INTERRUPT_GRACE):
        import threading
        self.grace = grace
        self.done = False
        self._timer = None
        self._previous = None
        self._main = threading.current_thread() is threading.main_thread()

    def __enter__(self):
        import signal
        if self._main:  # signal handlers can only be set there
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        import signal
        self.done = True
        if self._timer is not None:
            self._timer.cancel()
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        return False

    def _handle(self, signum, frame):
        import threading
        if self.done:
            return
        if self._timer is None and self.grace is not None:
            self._timer = threading.Timer(self.grace, self._again, (threading.main_thread().ident, signum))
            self._timer.daemon = True
            self._timer.start()
        raise KeyboardInterrupt

    def _again(self, thread, signum):
        import signal
        if self.grace is not None and not self.done:
            signal.pthread_kill(thread, signum)  # wakes the main thread out of a join


def main(argv=None):
    """Run ``cclog``; return the exit status."""
    parser = build_parser()
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    prog = '%s %s' % (PROG, args.command)
    try:
        with Interrupt() as args.interrupt:
            status = _run(args, prog)
    except KeyboardInterrupt:  # the second one, while the first was being reported
        status = EXIT_INTERRUPTED
    if status == EXIT_INTERRUPTED and argv is None and args.interrupt.grace is not None:
        # the program itself (not a call from Python), no Dask cluster (whose processes the teardown ends): skip
        # the interpreter's teardown, which takes seconds to free what an interrupted command held (a replay's
        # open window of 100,000s of messages); nothing is left to write
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(status)
    return status


def _run(args, prog):
    """``args.run(args)`` with its errors as one line and an exit status."""
    try:
        return args.run(args)
    except ValueError as error:  # CommandError, ModelError and every '<what>: <problem>' of the library
        sys.stderr.write('%s: error: %s\n' % (prog, _one_line(error)))
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # `cclog cat ... | head`: the reader is gone, nothing left to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except OSError as error:
        where = ' %s:' % error.filename if getattr(error, 'filename', None) else ''
        sys.stderr.write('%s: error:%s %s\n' % (prog, where, _one_line(error.strerror or error)))
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        sys.stderr.write('%s: interrupted\n' % prog)
        return EXIT_INTERRUPTED
