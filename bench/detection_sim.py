#!/usr/bin/env python3
"""The paper's Table 1 protocol on the simulated BWIBot (cc_log.sim), trained on nominal data only.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/detection_sim.py            # ~1500 events as in the paper (about a minute)
    python3 bench/detection_sim.py --quick    # tiny run (tests)

Events: one event = one feature window = one vector. Windows tile the odometry without overlap (the
paper's "event" count), ``--window`` messages each (default 500, the paper's window, 5 s at 100 Hz).

- training set: a nominal run (seed ``--seed``, no anomalies) long enough for ``--train`` (983) windows;
- test set: a separate run (seed + 1) with ``--anomalies`` (20) anomalies cycling through every type of
  sim.ANOMALY_TYPES, long enough for ``--test`` (512) windows; a window is anomalous when its time span
  overlaps an anomaly [start, end] of the ground truth, nominal otherwise. The two runs share nothing.

Models (same events):
- ``motion``: cc_log's default features (per-channel mean/std/min/max of 18 motion channels) and training
  (learning.train: nu 0.02, gamma 0.5 / n_features, threshold from held-out nominal blocks);
- ``motion + progress``: a motion model and a ``progress`` model (net displacement against path length,
  reversals, rotation in place; same training), an event flagged when either flags it (two classifiers in
  one configuration);
- ``raw``: the paper's features (position, orientation, twist of every message concatenated), same training;
- ``paper``: raw features with the paper's settings as far as it states them (OneClassSVM RBF, nu 0.5,
  gamma 1 / n_features, threshold 0 = OneClassSVM.predict).
Table 1 (window-level counts) is printed for each next to the paper's, plus anomalies caught by type (an
anomaly counts as caught when any window overlapping it is flagged).
"""
import argparse
import collections
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.learning import learning  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.features import FeatureConfig, OdometryFeatures, vector_length, window_vector  # noqa: E402

PAPER = learning.Report(512, 20, 183, 0, 309, 20 / 203.0, 1.0)


def simulate_rows(config, feature_configs):
    """Run the simulator; return (stamps, {feature_set: rows array}) of the odometry, and the truth."""
    simulator = sim.Simulator(config)
    extractors = {fc.feature_set: OdometryFeatures(fc) for fc in feature_configs}
    stamps, rows = [], {name: [] for name in extractors}
    for topic, stamp, msg in simulator.messages():
        if topic != sim.ODOM_TOPIC:
            continue
        s = msg.header.stamp.to_sec()
        stamps.append(s)
        for name, extractor in extractors.items():
            rows[name].append(extractor.row(msg, s))
    return np.array(stamps), {name: np.array(value) for name, value in rows.items()}, simulator.truth


def tile(stamps, rows, config, count):
    """Non-overlapping windows of ``count`` rows: (start stamps, end stamps, vectors). The first window
    starts after one message (derivatives need a predecessor)."""
    starts, ends, vectors = [], [], []
    for first in range(1, len(stamps) - count + 1, count):
        block = rows[first:first + count]
        starts.append(stamps[first])
        ends.append(stamps[first + count - 1])
        vectors.append(window_vector(list(block), config))
    return np.array(starts), np.array(ends), np.array(vectors)


def test_events(stamps, rows, config, count, truth, total):
    """The test events: one anomalous window per anomaly (the ``count`` messages from its onset) and nominal
    windows tiling the run that overlap no anomaly (nor the message after one), ``total`` in all."""
    anomalous = []
    for entry in truth:
        first = int(np.searchsorted(stamps, entry['start']))
        anomalous.append(window_vector(list(rows[first:first + count]), config))
    t0, t1, X = tile(stamps, rows, config, count)
    clean = np.array([not any(a <= e['end'] + 0.05 and b >= e['start'] - 0.05 for e in truth)
                      for a, b in zip(t0, t1)])
    return X[clean][:total - len(anomalous)], np.array(anomalous)


def flags_report(nominal_flags, anomalous_flags):
    """learning.Report of boolean flags of the nominal and the anomalous events."""
    tp, fp = int(np.sum(anomalous_flags)), int(np.sum(nominal_flags))
    fn, tn = len(anomalous_flags) - tp, len(nominal_flags) - fp
    return learning.Report(tp + fp + fn + tn, tp, fp, fn, tn, tp / float(tp + fp) if tp + fp else float('nan'),
                           tp / float(tp + fn) if tp + fn else float('nan'))


def run_minutes(windows, count, rate):
    return (windows * count + 2) / rate / 60.0


def fit(X, config, setting):
    if setting == 'paper':
        model, info = learning.train(X, config=config, nu=0.5, gamma=1.0 / vector_length(config))
        model.threshold = 0.0
        info['threshold'] = 0.0
        info['threshold_rule'] = '0 (OneClassSVM.predict)'
        return model, info
    return learning.train(X, config=config)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--train', type=int, default=983, help='training windows (nominal run)')
    parser.add_argument('--test', type=int, default=512, help='test windows')
    parser.add_argument('--anomalies', type=int, default=20, help='anomalies in the test run')
    parser.add_argument('--window', type=int, default=500, help='messages per window')
    parser.add_argument('--motion-windows', default='500,200',
                        help='comma-separated message counts of the motion windows to compare')
    parser.add_argument('--rate', type=float, default=100.0, help='odometry Hz')
    parser.add_argument('--seed', type=int, default=7)
    parser.add_argument('--quick', action='store_true', help='tiny run: 60 train, 48 test windows of 100')
    args = parser.parse_args(argv)
    args.motion_windows = [int(w) for w in args.motion_windows.split(',')]
    if args.quick:
        args.motion_windows = [100, 50]
        args.train, args.test, args.anomalies, args.window = 60, 48, 2, 100
    started = time.time()
    args.test_minutes = run_minutes(args.test + args.anomalies * 3, args.window, args.rate)
    common.header('Detection on the simulator: the paper\'s Table 1 protocol',
                  ['data: cc_log.sim BWIBot, %g Hz odometry; train run seed %d (nominal, %.1f min), test run '
                   'seed %d (%d anomalies of every type, %.1f min); windows of %d messages, no overlap'
                   % (args.rate, args.seed, run_minutes(args.train, args.window, args.rate), args.seed + 1,
                      args.anomalies, args.test_minutes, args.window)])
    configs = {'motion': FeatureConfig('motion', str(args.window)), 'raw': FeatureConfig('raw', str(args.window)),
               'progress': FeatureConfig('progress', str(args.window))}
    train_cfg = sim.SimConfig(rate=args.rate, seed=args.seed, minutes=run_minutes(args.train, args.window, args.rate),
                              anomalies=0)
    test_cfg = sim.SimConfig(rate=args.rate, seed=args.seed + 1,
                             minutes=args.test_minutes, anomalies=args.anomalies,
                             gap=min(20.0, 0.3 * args.test_minutes * 60 / max(1, args.anomalies)),
                             warmup=10.0 if args.quick else 20.0)
    train_stamps, train_rows, _ = simulate_rows(train_cfg, configs.values())
    test_stamps, test_rows, truth = simulate_rows(test_cfg, configs.values())
    print('simulated %d + %d odometry messages, %d anomalies in the test run (%s)  [%.1f s]\n' % (
        len(train_stamps), len(test_stamps), len(truth),
        ', '.join('%s %d' % (k, v) for k, v in sorted(collections.Counter(e['type'] for e in truth).items())),
        time.time() - started))

    results = collections.OrderedDict()
    columns = [('cc_log motion %d' % w, ('motion',), None, w) for w in args.motion_windows] + [
        ('motion + progress %d' % args.window, ('motion', 'progress'), None, args.window),
        ('paper features', ('raw',), None, args.window), ('paper settings', ('raw',), 'paper', args.window)]
    for column, feature_sets, setting, count in columns:
        # several feature sets: one model each, as a configuration runs several classifiers; an event is
        # flagged when any of them flags it
        nominal_flags, anomalous_flags, infos = 0, 0, []
        with common.Timer() as timer:
            for feature_set in feature_sets:
                config = FeatureConfig(feature_set, str(count))
                _, _, X_train = tile(train_stamps, train_rows[feature_set], config, count)
                X_train = X_train[:args.train]
                X_nominal, X_anomalous = test_events(test_stamps, test_rows[feature_set], config, count, truth,
                                                     args.test)
                model, info = fit(X_train, config, setting)
                nominal_flags = nominal_flags | (model.scores(X_nominal) < model.threshold)
                anomalous_flags = anomalous_flags | (model.scores(X_anomalous) < model.threshold)
                infos.append(info)
        report = flags_report(nominal_flags, anomalous_flags)
        caught = collections.Counter(e['type'] for e, f in zip(truth, anomalous_flags) if f)
        total = collections.Counter(e['type'] for e in truth)
        info = dict(infos[0], features=sum(i['features'] for i in infos))
        results[column] = (report, info, caught, total, timer, len(X_train))
        results[column][1]['models'] = infos

    rows = []
    fields = [('Total', 'total'), ('TP', 'tp'), ('FP', 'fp'), ('FN', 'fn'), ('TN', 'tn')]
    for label, key in fields:
        rows.append([label, getattr(PAPER, key)] + [getattr(r[0], key) for r in results.values()])
    rows.append(['Precision', '9.8%']
                + ['%.1f%%' % (100 * r[0].precision) if r[0].precision == r[0].precision else 'n/a'
                   for r in results.values()])
    rows.append(['Recall', '%.1f%%' % (100 * PAPER.recall)]
                + ['%.1f%%' % (100 * r[0].recall) if r[0].recall == r[0].recall else 'n/a' for r in results.values()])
    rows.append(['Training vectors', 983] + [r[5] for r in results.values()])
    rows.append(['Features', 3250] + [r[1]['features'] for r in results.values()])
    rows.append(['Training s (wall)', 35] + ['%.2f' % r[4].wall for r in results.values()])
    common.table(['Table 1', 'paper'] + list(results), rows,
                 'Table 1 (window level; positive = anomalous window):')

    type_rows = []
    for kind in sim.ANOMALY_TYPES:
        type_rows.append([kind] + ['%d/%d' % (r[2][kind], r[3][kind]) for r in results.values()])
    type_rows.append(['all'] + ['%d/%d' % (sum(r[2].values()), sum(r[3].values())) for r in results.values()])
    common.table(['anomalies caught'] + list(results), type_rows, 'Anomalies caught by type (its window flagged):')

    for column, (report, info, _, _, _, _) in results.items():
        for one in info['models']:
            print('%s: %s %s window, %s, nu=%g, gamma=%.3g, threshold %.4g (%s), %d support vectors' % (
                column, one['config']['feature_set'], one['config']['window'], one['method'], one['nu'],
                one['gamma'], one['threshold'], one.get('threshold_rule', ''), one['support_vectors']))
    for column in (columns[0][0], columns[len(args.motion_windows)][0]):
        report = results[column][0]
        print('target (%s) recall 100%% and precision >= 90%%: recall %.1f%%, precision %.1f%% -> %s' % (
            column, 100 * report.recall, 100 * report.precision,
            'met' if report.recall == 1.0 and report.precision >= 0.9 else 'NOT met'))
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
