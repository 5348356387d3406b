"""``cclog learn``: train a model, validate it, or evaluate an existing one."""
import collections

from cc_log.offline.progress import bar as _bar
from cc_log.offline.cli.common import (
    EXIT_OK, CommandError, command_help, fleet_engine, fleet_flags, fleet_wanted, output_flags, parent_exists,
    positive_float, print_json)


def add_parser(subparsers):
    """The ``cclog learn`` sub-parser."""
    p = subparsers.add_parser('learn', **command_help(
        'train the model (learn mode), validate or evaluate it',
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
    p.add_argument('--nu', type=positive_float('nu'), help='one-class SVM nu (default: learning default or grid)')
    p.add_argument('--gamma', type=positive_float('gamma'), help='RBF gamma (default: learning default or grid)')
    p.add_argument('--method', default='auto', choices=('auto', 'exact', 'nystroem', 'stream'),
                   help='exact OneClassSVM, Nystroem + SGD, auto, or stream: Nystroem + SGD partial_fit over the '
                   'directories, never all vectors in one process (default: %(default)s)')
    p.add_argument('--trim', type=_trim, default=None, metavar='SHARE',
                   help='drop this share of the most outlying nominal vectors before training, for a day of '
                   '"nominal" driving that held anomalies; 0 keeps all (default: %g)' % _default_trim())
    fleet_flags(p)
    output_flags(p)
    return p


def _default_trim():
    from cc_log.learning.learning import DEFAULT_TRIM
    return DEFAULT_TRIM


def _trim(text):
    from cc_log.learning.learning import MAX_TRIM
    try:
        value = float(text)
    except ValueError:
        value = float('nan')
    if not 0 <= value < MAX_TRIM:
        import argparse
        raise argparse.ArgumentTypeError('trim: %s is not a share from 0 to below %g' % (text, MAX_TRIM))
    return value


def run(args):
    """Train a model (``--train``), validate it (``--test``); or evaluate an existing one (``--test`` only)."""
    from cc_log.offline import learn_main
    from cc_log.learning import learning
    if args.train is None and args.test is None:
        raise CommandError('train: give --train DIR (train a model), --test DIR (evaluate --model), or both')
    many = args.train is not None and (args.method == 'stream' or fleet_wanted(args, args.train, _vector_dir))
    if args.train is not None and not many:
        args.train = args.train[0]
    if args.train is not None:
        parent_exists(args.model, 'model')
    summary = collections.OrderedDict([('model', args.model), ('train', args.train), ('test', args.test)])
    with _bar(args, 'learn').busy():
        try:
            if many:
                model, info = _learn_many(args)
                _save_model(model, args.model)
                report = learn_main.learn(None, args.test, args.model)[1] if args.test is not None else None
            else:
                model, report, info = learn_main.learn(args.train, args.test, args.model, args.nu, args.gamma,
                                                       args.method, trim=_chosen_trim(args))
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
        print_json(summary)
        return EXIT_OK
    if report is not None:
        print(learning.format_report(report, info))
    else:
        print(_training_text(info))
    if args.train is not None:
        print('%-16s %s (%s features, window %s)' % ('Saved', args.model, model.config.feature_set,
                                                     model.config.window))
    return EXIT_OK


def _learn_many(args):
    """Train over every vector directory of --train (partitions) on the engine: ``(model, info)``."""
    from cc_log.offline import fleet, learn_main, partition_learning
    from cc_log.learning import learning
    directories = fleet.expand_vector_dirs(args.train)
    with fleet_engine(args) as engine:
        if args.method == partition_learning.STREAM_METHOD:
            model, info = partition_learning.train_streamed(engine, partition_learning.load_partition, directories,
                                                            nu=args.nu, gamma=args.gamma)
        else:
            vectors, config, worker_rss = partition_learning.gather_vectors(engine, directories)
            nominal, anomalous = learn_main.split_labels(vectors)
            if nominal is None:
                raise CommandError('train: %s have no %s/ vectors' % (' '.join(args.train), learn_main.NOMINAL))
            model, info = learning.train(nominal, anomalous, config, nu=args.nu, gamma=args.gamma,
                                         method=args.method, trim=_chosen_trim(args))
            info['worker_peak_rss_mb'] = worker_rss
        info['partitions'] = len(directories)
        info['engine'] = engine.describe()
    return model, info


def _chosen_trim(args):
    return _default_trim() if args.trim is None else args.trim


def _vector_dir(path):
    from cc_log.offline import fleet
    return fleet.holds_vectors(path)


def _report_dict(report):
    return collections.OrderedDict((field, getattr(report, field)) for field in report._fields)


def _training_text(info):
    """What training alone (no --test) can tell: the model, its threshold, the held-out nominal check, what was
    trimmed."""
    from cc_log.learning import learning
    lines = ['%-16s %s, nu=%g, gamma=%.4g, %s nominal vectors (%s held out), %s anomalous' % (
        'Model', info['method'], info['nu'], info['gamma'], info['vectors_nominal'], info['vectors_held_out'],
        info['vectors_anomalous']),
        '%-16s %.4g (%s)' % ('Threshold', info['threshold'], info['threshold_rule']),
        '%-16s %d of %d held-out nominal vectors flagged (no --test directory)' % (
            'Held out', info['held_out_flagged'], info['vectors_held_out']),
        '%-16s %.2f s' % ('Training time', info['train_seconds']),
        '%-16s %.0f MB (process peak RSS)' % ('Peak memory', info['peak_rss_mb'])]
    if 'trimmed' in info:  # not with --method stream
        lines.insert(3, learning.trim_text(info))
    return '\n'.join(lines)


def _save_model(model, path):
    try:
        model.save(path)
    except OSError as error:
        raise CommandError('model: cannot write %s: %s' % (path, error.strerror or error))
