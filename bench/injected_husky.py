#!/usr/bin/env python3
"""Simulator anomalies injected into real Husky odometry: events caught by type, false windows per hour.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/injected_husky.py            # seeds 0 1 2 (18 anomalies)
    python3 bench/injected_husky.py --quick    # seed 0, three types (tests)

Data: ../shared/data/real/husky_outdoor_2015.bag, /husky_velocity_controller/odom (10 Hz) driving and
/imu/data (30 Hz) side topic. The model (motion features, 2 s window, learning.train defaults) is trained
on the first half of the odometry (time), nominal only. Into the second half, sim.inject_anomalies puts one
anomaly of every simulator type (the real recording's noise around the synthetic event; every message
outside the anomalies is the recorded one), once per seed. The injected stream goes through SmartLogger
(json-xz, pre/post 100 messages) exactly as in `cclog replay`.

An anomaly is caught when a classifier trigger falls between its onset and its end + the 2 s feature window;
a saved window is false when none of its triggers does. The same second half without injection gives the
baseline false windows per hour (bench/detection_real.py reports it for the raw and paper settings too).
"""
import argparse
import collections
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log import learning, sim  # noqa: E402
from cc_log.features import FeatureConfig  # noqa: E402

WINDOW = '2s'
REACH = 2.0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', default='0,1,2')
    parser.add_argument('--window', default=WINDOW, help='motion feature window (default 2s)')
    parser.add_argument('--quick', action='store_true')
    args = parser.parse_args(argv)
    seeds = [0] if args.quick else [int(s) for s in args.seeds.split(',')]
    types = sim.ANOMALY_TYPES[:3] if args.quick else sim.ANOMALY_TYPES
    started = time.time()
    common.header('Simulator anomalies injected into the real Husky run',
                  [common.describe_data(common.HUSKY_BAG,
                                        '(odometry %s, IMU %s)' % (common.HUSKY_ODOM, common.HUSKY_IMU)),
                   'injection: sim.inject_anomalies, types %s, seeds %s' % (', '.join(types), seeds)])
    records = common.husky_records((common.HUSKY_ODOM, common.HUSKY_IMU))
    first, second = common.split_half(records, common.HUSKY_ODOM)
    config = FeatureConfig('motion', args.window)
    _, X = common.window_vectors(first, common.HUSKY_ODOM, config)
    model, info = learning.train(X, config=config)
    print('model: motion %s window, %d training vectors (first half), %s, nu=%g, gamma=%.3g, threshold %.4g\n'
          % (args.window, len(X), info['method'], info['nu'], info['gamma'], info['threshold']))
    odom = [r for r in second if r.topic == common.HUSKY_ODOM]
    hours = (odom[-1].stamp - odom[0].stamp) / 3600.0
    caught, total, delays = collections.Counter(), collections.Counter(), collections.defaultdict(list)
    run_rows = []
    with tempfile.TemporaryDirectory(prefix='cc_log_bench_') as tmp:
        base = common.smart_replay(model, second, common.HUSKY_ODOM, os.path.join(tmp, 'nominal'),
                                   (common.HUSKY_IMU,))
        run_rows.append(['second half, no injection', 0, '-', len(base['windows']), len(base['windows']),
                         '%.1f' % (len(base['windows']) / hours)])
        false_total = 0
        for seed in seeds:
            injected, truth = sim.inject_anomalies(second, types, seed=seed, topic=common.HUSKY_ODOM)
            result = common.smart_replay(model, injected, common.HUSKY_ODOM, os.path.join(tmp, 'seed%d' % seed),
                                         (common.HUSKY_IMU,))
            matches, false = common.match_anomalies(truth, result['windows'], REACH)
            false_total += false
            for m in matches:
                total[m['type']] += 1
                if m['caught']:
                    caught[m['type']] += 1
                    delays[m['type']].append(m['delay'])
            run_rows.append(['injected, seed %d' % seed, len(truth),
                             '%d/%d' % (sum(m['caught'] for m in matches), len(truth)),
                             len(result['windows']), false, '%.1f' % (false / hours)])
    common.table(['run (second half, %.0f s)' % (hours * 3600), 'anomalies', 'caught', 'windows', 'false windows',
                  'false windows/h'], run_rows, 'Per run:')
    rows = [[kind, '%d/%d' % (caught[kind], total[kind]),
             '%.2f' % max(delays[kind]) if delays[kind] else '-'] for kind in types]
    rows.append(['all', '%d/%d' % (sum(caught.values()), sum(total.values())), '-'])
    common.table(['anomaly type', 'caught', 'worst first-trigger delay s'], rows, 'Caught by type (all seeds):')
    all_caught = sum(caught.values()) == sum(total.values())
    rate = false_total / (hours * len(seeds))
    print('target all caught: %d/%d -> %s' % (sum(caught.values()), sum(total.values()),
                                              'met' if all_caught else 'NOT met'))
    print('target <= 1 false window per hour: %.1f /h over %d injected runs (%.1f /h without injection) -> %s' % (
        rate, len(seeds), len(base['windows']) / hours, 'met' if rate <= 1 else 'NOT met'))
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
