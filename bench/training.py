#!/usr/bin/env python3
"""Training cost: seconds and peak memory to train on 17,512 feature vectors (the paper's real-robot set size).

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/training.py            # 17512 vectors (a few minutes, mostly simulation)
    python3 bench/training.py --quick    # 500 vectors (tests)

Vectors come from a nominal simulated BWIBot run (cc_log.sim, 100 Hz, seed 11), one vector every
``stride`` messages, so they are real sliding-window vectors, not copies. Each training runs in its own
child process (a fresh Python that loads the vectors from a .npy file and calls learning.train), so its
peak RSS is its own: the figure includes the interpreter, numpy and scikit-learn (reported as "baseline",
the child's peak RSS before training) plus the training.

Rows:
- cc_log motion features (72 per vector, 500-message window), learning.train method 'exact'
  (scikit-learn OneClassSVM, RBF) and 'nystroem' (the scalable formulation: Nystroem + SGDOneClassSVM);
- the paper's own case: raw concatenation features of 250 messages (3250 per vector), 983 vectors,
  nu 0.5 (the paper: 35 s, 500 MB).
Wall seconds and process CPU seconds are both printed; other processes share this 2-core machine, so
CPU seconds are the steadier figure.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.learning import learning  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.features import FeatureConfig, OdometryFeatures, vector_length, window_vector  # noqa: E402


def sim_vectors(config, count, stride, seed=11, rate=100.0):
    """``count`` vectors of ``config`` (count window) from a nominal run, one every ``stride`` messages."""
    window = config.span.count
    messages = window + 1 + stride * count
    simulator = sim.Simulator(sim.SimConfig(rate=rate, seed=seed, minutes=messages / rate / 60.0 + 0.01,
                                            anomalies=0))
    features = OdometryFeatures(config)
    rows = []
    for topic, _, msg in simulator.messages():
        if topic == sim.ODOM_TOPIC:
            rows.append(features.row(msg, msg.header.stamp.to_sec()))
    rows = np.array(rows)
    out = []
    for end in range(window + 1, len(rows) + 1, stride):
        out.append(window_vector(list(rows[end - window:end]), config))
        if len(out) == count:
            break
    return np.array(out), len(rows)


def child(args):
    """Train once on the vectors in args.child; print one JSON line."""
    config = FeatureConfig(args.feature_set, args.window)
    X = np.load(args.child)
    baseline = common.peak_rss_mb()
    cpu0, wall0 = common.cpu_seconds(), time.perf_counter()
    kwargs = {'method': args.method}
    if args.paper:
        kwargs.update(nu=0.5, gamma=1.0 / vector_length(config))
    model, info = learning.train(X, config=config, **kwargs)
    wall, cpu = time.perf_counter() - wall0, common.cpu_seconds() - cpu0
    print(json.dumps({'vectors': len(X), 'features': X.shape[1], 'wall': wall, 'cpu': cpu,
                      'peak_rss_mb': common.peak_rss_mb(), 'baseline_mb': baseline,
                      'method': info['method'], 'support': info['support_vectors'], 'nu': info['nu'],
                      'vectors_train': info['vectors_train'], 'held_out_flagged': info['held_out_flagged'],
                      'held_out': info['vectors_held_out']}))
    return 0


def run_child(path, feature_set, window, method, paper=False):
    command = [sys.executable, os.path.abspath(__file__), '--child', path, '--feature-set', feature_set,
               '--window', window, '--method', method] + (['--paper'] if paper else [])
    output = subprocess.check_output(command, universal_newlines=True)
    return json.loads(output.strip().splitlines()[-1])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--vectors', type=int, default=17512)
    parser.add_argument('--stride', type=int, default=10, help='messages between vectors')
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--child', help=argparse.SUPPRESS)
    parser.add_argument('--feature-set', default='motion', help=argparse.SUPPRESS)
    parser.add_argument('--window', default='500', help=argparse.SUPPRESS)
    parser.add_argument('--method', default='exact', help=argparse.SUPPRESS)
    parser.add_argument('--paper', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        return child(args)
    paper_count = 983
    if args.quick:
        args.vectors, paper_count = 500, 100
    started = time.time()
    common.header('Training cost', ['data: cc_log.sim BWIBot nominal run, 100 Hz, seed 11; motion vectors: '
                                    '500-message window every %d messages; raw vectors: 250-message window '
                                    'every 50 messages' % args.stride])
    motion = FeatureConfig('motion', '500')
    raw = FeatureConfig('raw', '250')
    X_motion, n_motion = sim_vectors(motion, args.vectors, args.stride)
    X_raw, n_raw = sim_vectors(raw, paper_count, 50)
    print('vectors: %d motion (%d features) from %d messages; %d raw (%d features) from %d messages  [%.1f s]\n'
          % (len(X_motion), X_motion.shape[1], n_motion, len(X_raw), X_raw.shape[1], n_raw, time.time() - started))
    rows = []
    with tempfile.TemporaryDirectory(prefix='cc_log_bench_') as tmp:
        motion_path, raw_path = os.path.join(tmp, 'motion.npy'), os.path.join(tmp, 'raw.npy')
        np.save(motion_path, X_motion)
        np.save(raw_path, X_raw)
        runs = [('cc_log motion, exact OCSVM', motion_path, 'motion', '500', 'exact', False),
                ('cc_log motion, nystroem-sgd', motion_path, 'motion', '500', 'nystroem', False),
                ('paper case: raw 250 msgs, nu 0.5, exact', raw_path, 'raw', '250', 'exact', True)]
        results = {}
        for label, path, feature_set, window, method, paper in runs:
            r = run_child(path, feature_set, window, method, paper)
            results[label] = r
            rows.append([label, r['vectors'], r['features'], '%.2f' % r['wall'], '%.2f' % r['cpu'],
                         '%.0f' % r['peak_rss_mb'], '%.0f' % r['baseline_mb'], r['support'],
                         '%d/%d' % (r['held_out_flagged'], r['held_out'])])
    rows.append(['paper (CC-Log, their machine)', 983, 3250, '35', '-', '500', '-', '-', '-'])
    common.table(['training', 'vectors', 'features', 'wall s', 'CPU s', 'peak RSS MB', 'baseline MB',
                  'SVs/components', 'held-out flagged'], rows,
                 'Training (each row a separate child process; peak RSS includes Python + numpy + scikit-learn):')
    for label in ('cc_log motion, exact OCSVM', 'cc_log motion, nystroem-sgd'):
        r = results[label]
        print('target <= 10 s and <= 300 MB on %d vectors, %s: %.2f s wall, %.0f MB -> %s' % (
            r['vectors'], label, r['wall'], r['peak_rss_mb'],
            'met' if r['wall'] <= 10 and r['peak_rss_mb'] <= 300 else 'NOT met'))
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
