"""``cclog collect``: feature vectors of bags, as collect mode writes them."""
import collections
import contextlib
import sys

from cc_log.base import safe_files
from cc_log.offline.progress import bar as _bar, call as _call
from cc_log.offline.cli.common import (
    PROG, EXIT_OK, CommandError, command_help, configuration, driving_topic, existing_file, fleet_end, fleet_flags,
    fleet_rows, fleet_wanted, non_negative_int, output_flags, print_json, run_fleet, span)


def add_parser(subparsers):
    """The ``cclog collect`` sub-parser."""
    p = subparsers.add_parser('collect', **command_help(
        'feature vectors of a bag into DIR/<label>/ (collect mode)',
        """
        Collect mode from a bag: run the features over the driving topic (nav_msgs/Odometry) and write one
        feature vector file per --stride messages into DIR/<label>/, as the collect node does live. Those
        directories are what `cclog learn --train` reads; label a run "nominal" or after its anomaly. With
        --config, the configuration's rules (aborts, collisions, bumper, diagnostics errors; not its
        classifiers or periodic triggers) are run over the bag too, and a vector whose feature window
        overlaps a span a rule fired on (widened by the rule's pre/post) is not kept: it is not nominal. The
        count and the spans are reported (one bag; not over several). A vector that cannot be written (disk
        full) is retried for a few seconds; then collect exits 1 with one line naming DIR/<label> and how
        many vectors were not written.
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
                   '(nav_msgs/Odometry; imu: sensor_msgs/Imu; default: the bag\'s only topic of that type)')
    p.add_argument('--out', required=True, metavar='DIR', help='vectors go to DIR/<label>/')
    p.add_argument('--label', help='label directory (default: nominal; anything but '
                   '"nominal" counts as anomalous)')
    p.add_argument('--window', type=span('window'), metavar='N|Ns',
                   help='feature window: seconds (2s) or messages (500) (default: %s)' % _feature_window())
    p.add_argument('--stride', type=non_negative_int('stride', 1), metavar='N',
                   help='a vector every N driving messages (default: %d, or smaller so that a short bag '
                   'still gives about 200 vectors)' % _collect_stride())
    p.add_argument('--features', choices=_feature_sets(),
                   help='feature set (default: %s)' % _feature_sets()[0])
    p.add_argument('--input-topic', action='append', default=[], metavar='T',
                   help="a topic of the feature set's other inputs, in its order (command: the cmd_vel topic)")
    fleet_flags(p)
    output_flags(p)
    return p


def run(args):
    """Feature vectors of a bag's driving topic into ``OUT/<label>/``, as collect mode writes them; with
    ``--config``, of every classifier's feature set into ``OUT/<name>/<label>/``."""
    from cc_log.logger import collector
    from cc_log.offline import fleet
    from cc_log.learning.model import AnomalyModel
    many = fleet_wanted(args, args.bag)
    if not many:
        args.bag = existing_file(args.bag[0], 'bag file')
    if not args.config and args.topic is None:
        if many:
            raise CommandError('collect: give --topic, or --config (a configuration with classifiers)')
        from cc_log import features
        args.topic = driving_topic(args, features.get(args.features or _feature_sets()[0]).inputs[0][1])
    single = {}
    if args.topic is not None:
        single = {'topics': [args.topic] + args.input_topic, 'feature_set': args.features or _feature_sets()[0],
                  'window': args.window or collector.DEFAULT_WINDOW}
    cfg = configuration(args, {'label': args.label, 'stride': args.stride, 'classifier': single})
    label = cfg.label or collector.DEFAULT_LABEL
    stride = cfg.stride  # None: the default, or smaller for a short bag (collector.auto_stride)
    specs = cfg.feature_specs(AnomalyModel.load)
    if not specs:
        raise CommandError('collect: %s has no classifier: nothing to compute' % args.config)
    if many:
        return _collect_many(args, specs, label, stride)
    with _leftovers_removed([args.out]), _bar(args, 'collect') as bar:
        result = _call(fleet.collect_one, bar, args.bag, args.out, specs, label, stride, single=not args.config)
        flagged = _drop_rule_flagged(args.bag, args.out, cfg, specs, label) if args.config else None
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
        summary['flagged'] = flagged
    if args.json:
        print_json(summary)
    else:
        for name, config, topics in specs:
            count, directory = result['sets'][name if args.config else '']
            print('%d feature vectors (%s features, window %s, every %s messages) from %s %s -> %s'
                  % (count, config.feature_set, config.window, result['strides'][name if args.config else ''],
                     args.bag, ' '.join(topics), directory))
        if flagged is not None:
            print(_flagged_text(flagged))
    for name, config, topics in specs:
        if not result['sets'][name if args.config else ''][0]:
            sys.stderr.write('%s collect: warning: no vector%s: %s never filled a whole feature window of %s\n'
                             % (PROG, ' for ' + name if args.config else '', topics[0],
                                config.window + ('' if config.span.is_duration else ' messages')))
    return EXIT_OK


def _drop_rule_flagged(bag, out, cfg, specs, label):
    """Run the rules of ``cfg`` over ``bag`` and remove the vectors of every set whose window overlaps a span
    they fired on; ``{'rules': names, 'spans': [[start, end, names]], 'removed': {set: count}}``, or None when
    the configuration has no rule."""
    import copy
    from cc_log.logger import collector
    from cc_log.base import raw_message
    from cc_log.learning.model import AnomalyModel
    from cc_log.storage.bag import bagio
    rules_only = copy.copy(cfg)
    rules_only.triggers = [entry for entry in cfg.triggers if entry['kind'] not in collector.RULE_EXCLUDED_KINDS]
    if not rules_only.triggers:
        return None
    try:
        triggers = rules_only.build_triggers(AnomalyModel.load, raw_message.installed_class)
        handle = bagio.open_bag(bag)
        try:
            driving = specs[0][2][0]
            count = handle.get_message_count([driving])
            seconds = max(handle.get_end_time() - handle.get_start_time(), 1e-9)
        finally:
            handle.close()
        rate = max(count, 1) / seconds
        spans = collector.rule_spans(bag, triggers, cfg.pre, cfg.post, rate)
    except ValueError as error:
        raise CommandError(str(error))
    removed = collections.OrderedDict()
    for name, config, _ in specs:
        span = config.span
        window = span.seconds if span.is_duration else span.count / rate
        folder = safe_files.inside(out, name, 'classifier', directory=True)
        removed[name] = collector.drop_flagged(folder, label, spans, window)
    return collections.OrderedDict([('rules', [t.name for t in triggers]),
                                    ('spans', [[start, end, names] for start, end, names in spans]),
                                    ('removed', removed)])


def _flagged_text(flagged):
    """One line: how many vectors the rules' spans removed, and the first spans."""
    spans = flagged['spans']
    shown = ', '.join('%.1f-%.1f s (%s)' % (start, end, ' '.join(names)) for start, end, names in spans[:5])
    return '%d vector(s) not kept as nominal: their window overlaps %d span(s) where rules (%s) fired%s%s' % (
        sum(flagged['removed'].values()), len(spans), ', '.join(flagged['rules']), ': ' + shown if shown else '',
        ' and %d more' % (len(spans) - 5) if len(spans) > 5 else '')


def _collect_many(args, specs, label, stride):
    from cc_log.offline import fleet
    bags = fleet.expand_bags(args.bag)
    with _leftovers_removed(fleet.output_dirs(args.out, bags)):
        outcomes, summary = run_fleet(args, 'collect', lambda engine, progress: fleet.collect_many(
            engine, bags, args.out, specs, label, stride, single=not args.config, progress=progress))
    rows = fleet_rows(outcomes, ('vectors', 'messages'))
    summary['vectors'] = sum(row.get('vectors', 0) for row in rows)
    lines = ['%s: %d feature vectors -> %s' % (row['bag'], row['vectors'], row['directory'])
             for row in rows if 'error' not in row]
    return fleet_end(args, summary, rows, lines)


@contextlib.contextmanager
def _leftovers_removed(directories):
    """On the way out (Ctrl-C, a worker lost), remove the half-written vector files of ended processes."""
    from cc_log.logger import collector
    try:
        yield
    finally:
        for directory in directories:
            collector.remove_vector_leftovers(directory)


def _collect_stride():
    try:
        from cc_log.logger.collector import DEFAULT_STRIDE
    except ImportError:
        return 25
    return DEFAULT_STRIDE


def _feature_window():
    from cc_log.features import DEFAULT_WINDOW
    return DEFAULT_WINDOW


def _feature_sets():
    from cc_log.features import FEATURE_SETS
    return FEATURE_SETS
