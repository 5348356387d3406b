"""``cclog replay``: the smart logger over bags; ``--sweep`` over several configurations."""
import collections
import contextlib
import copy
import math
import os
import sys

from cc_log.base.safe_input import printable
from cc_log.logger import options
from cc_log.logger.health import per_topic
from cc_log.offline.progress import bar as _bar
from cc_log.offline.cli.common import (
    PROG, EXIT_OK, CommandError, command_help, configuration, driving_topic, existing_file, fleet_end, fleet_flags,
    fleet_rows, fleet_wanted, human_bytes, output_flags, print_json, retrigger_modes, run_fleet, size_ratio, span,
    stamp_text, writable_dir)


def add_parser(subparsers):
    """The ``cclog replay`` sub-parser."""
    p = subparsers.add_parser('replay', **command_help(
        'the smart logger over a bag (windows around anomalies)',
        """
        Smart mode offline: feed the bag, as fast as it can be read, to the same SmartLogger the live node
        runs, with the triggers of --config (the YAML file smart_logger.py reads: classifiers, rules) and/or
        the trigger of --model: an envelope file (cclog learn-envelope) watches the odometry of --topic
        (default: the file's), a model (cclog learn) is a classifier scoring --topic. Every trigger saves
        --pre messages before and --post after (counts or durations), with the --side-topic messages of
        that time span, as window files in OUT; options given override the configuration. --json prints
        {input_messages, raw_json_bytes, stored_bytes, windows: [{name, start, end, messages, files, path}],
        messages_restamped, restamped_by_topic (messages placed at the clock, their header stamps off it),
        messages_trimmed_silent (side messages after a window let go at the memory budget, the driving topic
        silent while the window was open)},
        one entry per window whatever
        its files (routes, parts, splits: messages of them all; path: its first); start/end are the header
        stamps (float seconds) of the first and last message saved. A window that cannot be written (disk
        full) is retried for a few seconds; then replay stops and exits 1 with one line naming OUT and how
        many windows and messages were not written. --max-windows-per-hour N: the keep budget (past N windows
        in the last hour, only a more anomalous one opens); the summary counts what it skipped (--json:
        keep_budget).
        """,
        """
          cclog replay husky.bag --model envelope.json --out logs
          cclog replay husky.bag --topic /husky_velocity_controller/odom --model model.json --out logs
          cclog replay crash.bag --topic /odom --model model.json --out logs --pre 2s --post 2s --json
          cclog replay crash.bag --topic /odom --side-topic /scan --model m.json --out logs --format bag-lz4
          cclog replay run.bag --config robot.yaml --out logs --classify-every 1 --retrigger onset
          cclog replay long_run.bag --config robot.yaml --out logs --max-windows-per-hour 6
        """))
    p.add_argument('bag', nargs='+', metavar='BAG', help='input bag; several, a directory (its *.bag) or a glob: '
                   'one Dask task each, windows into OUT/<bag name>/')
    p.add_argument('--config', metavar='YAML', help='configuration (topics, triggers, windows, format, limits): '
                   'the file smart_logger.py reads; the options below override it')
    p.add_argument('--topic', metavar='T', help="driving topic (the model's message type; default: "
                   "the bag's only topic of that type; an envelope's: the one it was learned on)")
    p.add_argument('--model', metavar='PATH', help='envelope file (cclog learn-envelope) or model file (cclog '
                   'learn) of a classifier on --topic; needed without --config')
    p.add_argument('--out', required=True, metavar='DIR', help='directory for the window files')
    options.add_flags(p, 'replay')  # --format, --precision, --pre, --post, --max-buffer-mb: logger.options
    p.add_argument('--side-topic', action='append', default=[], metavar='T',
                   help='another topic to save inside the windows (repeatable)')
    p.add_argument('--classify-every', type=span('classify-every'), metavar='N|Ns',
                   help='score every N-th message or at most once per duration (default: 50ms)')
    p.add_argument('--retrigger', choices=retrigger_modes(),
                   help='event: the onset opens a window, extended while the newest rows are anomalous; every: '
                   'every anomalous score extends a window; onset: only the onset (default: event)')
    p.add_argument('--sweep', action='append', default=[], metavar='KEY=V1,V2',
                   help='evaluate every combination of these values (keys: threshold, pre, post, classify_every, '
                   'retrigger; repeatable) over one reading of each bag: a table of windows, messages kept, bytes '
                   'stored and, with <bag>.truth.json files, recall and false windows per hour; windows go to '
                   'OUT/<bag name>/<configuration>/')
    fleet_flags(p)
    output_flags(p)
    return p


def run(args):
    """The smart logger (the live node's SmartLogger) fed from a bag as fast as it can be read, with the
    triggers of ``--config`` and/or the classifier of ``--model`` on ``--topic``."""
    from cc_log.offline import replay
    from cc_log.logger.config import model_kind
    many = fleet_wanted(args, args.bag)
    if not many:
        args.bag = existing_file(args.bag[0], 'bag file')
    if not args.config and args.model is None:
        raise CommandError('replay: give --model (and --topic), or --config (a configuration with triggers)')
    if args.model is not None:
        existing_file(args.model, 'model file')
    if args.model is not None and args.topic is None and model_kind(args.model) == 'classifier':
        if many:
            raise CommandError('replay: --model needs --topic (the topic the model reads)')
        from cc_log.learning.model import AnomalyModel
        args.topic = driving_topic(args, AnomalyModel.load(args.model).config.topic_type)
    flat = dict((option.name, getattr(args, option.name)) for option in options.for_command('replay'))
    flat.update({'driving_topic': args.topic, 'side_topics': [t for t in args.side_topic if t != args.topic],
                 'classifier': {'model': args.model, 'topics': [args.topic] if args.model and args.topic else None,
                                'classify_every': args.classify_every, 'retrigger': args.retrigger,
                                'on_drift': flat.pop('on_drift')}})
    cfg = configuration(args, copy.deepcopy(flat))
    if args.sweep:
        return _sweep(args, flat, many)
    if many:
        replay.replay_setup(cfg)  # a bad configuration is one line before any bag
        with _cut_off_reported(args.out):
            return _replay_many(args, cfg)
    with _cut_off_reported(args.out), _bar(args, 'replay') as bar:
        summary = replay.replay_one(args.bag, args.out, cfg, bar.set, lambda path: writable_dir(path, 'out'))
    result = collections.OrderedDict([
        ('input_messages', summary['input_messages']),
        ('raw_json_bytes', summary['raw_json_bytes']),
        ('stored_bytes', summary['stored_bytes']),
        ('windows', [_window_entry(w) for w in summary['windows']]),
        ('drift', [monitor.as_dict() for monitor in summary['drift']]),
        ('online', summary['online']),
        ('keep_budget', summary['keep_budget']),
        ('absent_route_topics', summary['absent_route_topics']),
        ('messages_restamped', summary['messages_restamped']),
        ('restamped_by_topic', summary['restamped_by_topic']),
        ('messages_trimmed_silent', summary['messages_trimmed_silent']),
    ])
    if args.json:
        print_json(result)
        return EXIT_OK
    windows = result['windows']
    saved = sum(window['messages'] for window in windows)
    print('%s %s: %d messages in, %d saved in %d window(s) (%s files in %s)'
          % (args.bag, summary['driving_topic'], result['input_messages'], saved, len(windows), cfg.format, args.out))
    ratio = size_ratio(result['raw_json_bytes'], result['stored_bytes'])
    print('  raw row-per-message JSON %s, stored %s%s' % (
        human_bytes(result['raw_json_bytes']), human_bytes(result['stored_bytes']),
        ' (%.1fx smaller)' % ratio if ratio else ''))
    for number, window in enumerate(windows, 1):
        print('  %3d  %s .. %s  %7.2f s  %6d msgs  %s%s' % (
            number, stamp_text(window['start']), stamp_text(window['end']), window['end'] - window['start'],
            window['messages'], os.path.join(args.out, window['name']),
            ' (%s)' % _files_text(window['files'])))
    if result['messages_restamped']:
        print('  %d messages placed at the clock, their header stamps off it (%s)' % (
            result['messages_restamped'], per_topic(result['restamped_by_topic'])))
    if result['messages_trimmed_silent']:
        print('  %d side messages after a window trimmed to stay within the memory budget: the driving topic fell '
              'silent while the window was open' % result['messages_trimmed_silent'])
    for topic in result['absent_route_topics']:
        print('  routes: %s is not in the bag; nothing was routed there' % printable(topic))
    for monitor in summary['drift']:
        print('  %s' % monitor.report())
    for learner in summary['online']:
        print('  %s: online learning %s' % (learner['classifier'], learner['resumed'] or 'started afresh'))
    print(''.join(_skipped_lines(summary['keep_budget'])), end='')
    return EXIT_OK


def _files_text(files, shown=3):
    """A window's files as the summary names them: every one up to ``shown``, else the first and the last."""
    names = [os.path.basename(path) for path in files]
    if len(names) <= shown:
        return ('%d files: ' % len(names) if len(names) > 1 else '') + ', '.join(names)
    return '%d files: %s .. %s' % (len(names), names[0], names[-1])


def _window_entry(window):
    """A window of the summary as printed: its name, start, end, messages (in all its files), files, path."""
    return collections.OrderedDict((key, window[key]) for key in ('name', 'start', 'end', 'messages', 'files', 'path'))


def _skipped_lines(budget):
    """The lines saying what the keep budget skipped (``KeepBudget.stats()``; none when nothing): its report and
    the last skipped windows, each with its stamp, trigger and score."""
    from cc_log.logger import keep_budget
    report = keep_budget.report(budget)
    if not report:
        return []
    return ['  %s\n' % report] + ['    skipped  %s  %s  score %.4g\n' % (
        stamp_text(skip['stamp']), skip['trigger'], skip['score']) for skip in budget['skipped']]


def _replay_many(args, cfg):
    from cc_log.offline import fleet
    bags = fleet.expand_bags(args.bag)
    writable_dir(args.out, 'out')
    outcomes, summary = run_fleet(args, 'replay', lambda engine, progress: fleet.replay_many(
        engine, bags, args.out, cfg, progress=progress))
    rows = fleet_rows(outcomes, ('input_messages', 'raw_json_bytes', 'stored_bytes', 'windows', 'drift', 'online',
                                 'keep_budget', 'messages_restamped', 'restamped_by_topic',
                                 'messages_trimmed_silent'))
    reports = {}
    for row in rows:
        row['windows'] = [_window_entry(w) for w in row.get('windows', ())]
        reports[row['bag']] = ''.join('\n  %s' % monitor.report() for monitor in row.get('drift', ())) + ''.join(
            '\n' + line.rstrip('\n') for line in _skipped_lines(row.get('keep_budget') or {}))
        row['drift'] = [monitor.as_dict() for monitor in row.get('drift', ())]
    good = [row for row in rows if 'error' not in row]
    summary['windows'] = sum(len(row['windows']) for row in good)
    summary['saved_messages'] = sum(w['messages'] for row in good for w in row['windows'])
    summary['stored_bytes'] = sum(row['stored_bytes'] for row in good)
    return fleet_end(args, summary, rows, ['%s: %d messages in, %d saved in %d window(s) (%s) -> %s%s' % (
        row['bag'], row['input_messages'], sum(w['messages'] for w in row['windows']), len(row['windows']),
        human_bytes(row['stored_bytes']), row['directory'], reports[row['bag']]) for row in good])


def _sweep(args, flat, many):
    """``replay --sweep``: every combination of the --sweep values over one reading of each bag; a table."""
    from cc_log.offline import fleet, replay, sweep
    from cc_log.base.spans import Span
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
        cfg = configuration(args, options)
        replay.replay_setup(cfg)  # a bad configuration is one line before any bag
        sweeps.append(sweep.Sweep(sweep.sweep_label(combination), cfg, threshold))
    bags = fleet.expand_bags(args.bag) if many else [args.bag]
    writable_dir(args.out, 'out')
    if not many:
        args.workers = 0
    outcomes, summary = run_fleet(args, 'replay', lambda engine, progress: sweep.sweep_many(
        engine, bags, args.out, sweeps, progress=progress))
    rows = fleet_rows(outcomes, ('seconds', 'anomalies', 'rows'))
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
    return fleet_end(args, summary, rows, text)


def _number(name, value):
    try:
        number = float(value)
    except ValueError:
        number = float('nan')
    if not math.isfinite(number):
        raise CommandError('%s: %r is not a number' % (name, value))
    return number


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
