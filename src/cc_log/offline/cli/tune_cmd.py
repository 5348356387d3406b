"""``cclog tune``: a model's threshold (and window, classify rate) for a false-window budget."""
import sys

from cc_log.offline.progress import bar as _bar
from cc_log.offline.cli.common import (
    EXIT_OK, CommandError, command_help, existing_file, output_flags, parent_exists, positive_float, print_json,
    retrigger_modes, span, spans)


def add_parser(subparsers):
    """The ``cclog tune`` sub-parser."""
    from cc_log.offline.tuning import DEFAULT_INJECTION_SCALE, INJECTION_SCALES
    p = subparsers.add_parser('tune', **command_help(
        'set a model\'s threshold to a false-window budget on nominal bags',
        """
        Replay nominal bags through the classifier trigger the smart logger runs (--classify-every,
        --retrigger), merge its fires into windows (--pre, --post) and lower the model's threshold until
        the bags give at most --max-false-per-hour windows per hour; then inject one anomaly of every
        simulator type into the first bag, at the robot's own scale (--injection-scale robot: magnitudes in
        the ratio of the bags' nominal driving to the simulated BWIBot's), and report which the tuned
        model still catches. It prints the false windows per hour against the injected events caught over
        a range of thresholds, and says on the chosen line when that threshold loses an event the model's
        own threshold catches, and what the best threshold keeping every event gives; --keep-recall
        chooses that threshold instead (the fewest false windows that keep every event, budget or not).
        The model written to --out records what it was tuned for (info.tuned). Figures on the tuning bags
        are in-sample: check on other nominal bags with cclog replay.
        """,
        """
          cclog tune --model model.json --bag nominal.bag --topic /odom --max-false-per-hour 1 --out tuned.json
          cclog tune --model model.json --bag nominal.bag --topic /odom --max-false-per-hour 1 --keep-recall \
              --out tuned.json
        """))
    p.add_argument('--model', required=True, metavar='PATH', help='the model to tune (not changed)')
    p.add_argument('--bag', required=True, action='append', metavar='BAG', help='a nominal bag (repeatable)')
    p.add_argument('--topic', required=True, metavar='T', help="the model's driving topic in the bags")
    p.add_argument('--max-false-per-hour', required=True, type=positive_float('max-false-per-hour', zero=True),
                   metavar='N', help='false-window budget')
    p.add_argument('--out', required=True, metavar='PATH', help='the tuned model file to write')
    p.add_argument('--pre', type=span('pre'), default='2s', metavar='N|Ns', help='(default: %(default)s)')
    p.add_argument('--post', type=span('post'), default='2s', metavar='N|Ns', help='(default: %(default)s)')
    p.add_argument('--classify-every', type=spans('classify_every'), default=['50ms'], metavar='N|Ns[,...]',
                   help='classify rate, or several to choose from (default: 50ms)')
    p.add_argument('--windows', type=spans('windows'), default=None, metavar='W[,...]',
                   help='feature windows to choose from, e.g. 1s,2s,5s (another window than the model\'s is trained '
                        'on the bags; default: the model\'s)')
    p.add_argument('--retrigger', choices=retrigger_modes(), default='event', help='(default: %(default)s)')
    p.add_argument('--keep-recall', action='store_true',
                   help='choose the threshold with the fewest false windows that still catches every injected event '
                   'the model\'s own threshold catches, even above the budget (default: the budget decides, and '
                   'the events it loses are named)')
    p.add_argument('--injection-scale', choices=INJECTION_SCALES, default=DEFAULT_INJECTION_SCALE,
                   help='the size of the injected anomalies: robot, the bags\' own driving (its speed, acceleration '
                   'and turn rates against the BWIBot\'s); bwibot, the simulator\'s m/s and rad/s whatever the robot '
                   '(default: %(default)s)')
    output_flags(p)
    return p


def run(args):
    """Set a model's threshold, and with several --windows / --classify-every its feature window and classify
    rate, to a false-window budget on nominal bags (``tuning.choose``); write it to --out."""
    from cc_log.storage.bag import bagio
    from cc_log.offline import replay, tuning
    from cc_log.learning.model import AnomalyModel
    model = AnomalyModel.load(existing_file(args.model, 'model file'))
    types = {args.topic: model.config.feature.inputs[0][1]}
    for bag in args.bag:
        existing_file(bag, 'bag file')
        replay.check_bag_topics(bag, [args.topic], types)
    parent_exists(args.out, 'out')
    with _bar(args, 'tune').busy():
        runs = [list(bagio.read_messages(bag, [args.topic], types)) for bag in args.bag]
        try:
            model, record = tuning.choose(model, runs, args.topic, args.max_false_per_hour, args.windows,
                                          args.classify_every, args.pre, args.post, args.retrigger, sources=args.bag,
                                          keep_recall=args.keep_recall, injection_scale=args.injection_scale)
        except ValueError as error:
            raise CommandError(str(error))
    for line in tuning.rejected_lines(record):
        sys.stderr.write(line + '\n')
    try:
        model.save(args.out)
    except OSError as error:
        raise CommandError('out: cannot write %s: %s' % (args.out, error.strerror or error))
    if args.json:
        print_json(dict(record, out=args.out))
        return EXIT_OK
    if len(record['grid']) > 1:
        for g in record['grid']:
            print('window %-6s classify every %-6s threshold %-10.4g %6.1f false/h  %d caught%s, mean latency %s%s' % (
                g['window'], g['classify_every'], g['threshold'], g['false_per_hour'], len(g['catches']),
                ' (%d lost)' % len(g['lost']) if g['lost'] else '',
                '%.2f s' % g['mean_latency'] if g['mean_latency'] is not None else '-',
                ' (trained on the bags)' if g['trained'] else ''))
        print('chosen: window %s, classify every %s (%s)' % (
            record['window'], record['classify_every'], record['chosen_by']))
    print('%.3f h of nominal driving: %d false window(s) at threshold %.4g (%.1f/h), %d at %.4g (%.1f/h; budget '
          '%g/h, measured on the tuning bags)' % (
              record['hours'], record['false_windows_before'], record['threshold_before'],
              record['false_windows_before'] / record['hours'], record['false_windows'], record['threshold'],
              record['false_per_hour'], record['max_false_per_hour']))
    print('still caught (one injected anomaly each, %s): %s; missed: %s' % (
        scale_text(record), ', '.join(record['catches']) or 'none', ', '.join(record['misses']) or 'none'))
    for line in tune_lines(record):
        print(line)
    print('%-16s %s' % ('Saved', args.out))
    return EXIT_OK


def scale_text(record):
    """The scale the anomalies of ``tuning.tune``'s record were injected at, in words."""
    envelope = record.get('envelope')
    if record.get('injection_scale') == 'bwibot':
        return 'at the simulated BWIBot\'s scale'
    if not envelope:
        return 'at the robot\'s own scale'
    return ('at the robot\'s own scale: its nominal driving reaches %.2f m/s, %.2f m/s^2 up, %.2f m/s^2 braking, '
            '%.2f rad/s' % (envelope['max_speed'], envelope['max_accel'], envelope['max_decel'],
                            envelope['max_yaw_rate']))


def tune_lines(record):
    """The false-windows-per-hour against recall curve of ``tuning.tune``'s record, then the chosen line: its
    recall, the events it loses and what the best threshold keeping every event gives."""
    reference = record['caught_before']
    total = len(reference)
    lines = ['false windows per hour against injected events caught (of the %d the model\'s own threshold '
             'catches; %d injected):' % (total, record['injected'])]
    for point in record['curve']:
        kept = sum(1 for kind in reference if kind in point['caught'])
        marks = [name for name, value in (('model', record['threshold_before']), ('chosen', record['threshold']),
                                          ('keeps every event', record['keep_recall_threshold']))
                 if value == point['threshold']]
        lines.append('  threshold %-12.6g %7.1f false/h  recall %d/%d%s' % (
            point['threshold'], point['false_per_hour'], kept, total, '  <- ' + ', '.join(marks) if marks else ''))
    kept = total - len(record['lost'])
    chosen = 'chosen: threshold %.6g, %.1f false/h, recall %d/%d' % (
        record['threshold'], record['false_per_hour'], kept, total)
    if record['lost']:
        chosen += (': %d event(s) lost at this threshold (%s); the best threshold keeping every event (%.6g) gives '
                   '%.1f/h (--keep-recall)' % (len(record['lost']), ', '.join(record['lost']),
                                               record['keep_recall_threshold'], record['keep_recall_false_per_hour']))
    elif record['false_per_hour'] > record['max_false_per_hour'] + 1e-9:
        chosen += ': every event kept, above the budget of %g/h' % record['max_false_per_hour']
        if record['keep_recall'] and record['budget_threshold'] != record['threshold']:
            chosen += ' (the budget alone: threshold %.6g, %d false window(s), fewer events)' % (
                record['budget_threshold'], record['budget_false_windows'])
    else:
        chosen += ': every event kept'
    lines.append(chosen)
    return lines
