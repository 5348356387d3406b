#!/usr/bin/env python3
"""Simulator anomalies injected into real Husky odometry: events caught by type, false windows per hour.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/injected_husky.py            # seeds 0 1 2 (18 anomalies)
    python3 bench/injected_husky.py --quick    # seed 0, three types (tests)
    python3 bench/injected_husky.py --retrigger every,onset,event --pre 2s --post 2s

Data: ../shared/data/real/husky_outdoor_2015.bag, /husky_velocity_controller/odom (10 Hz) driving and
/imu/data (30 Hz) side topic. The model (motion features, 2 s window, learning.train defaults) is trained
on the first half of the odometry (time), nominal only. Into the second half, sim.inject_anomalies puts one
anomaly of every simulator type (the real recording's noise around the synthetic event; every message
outside the anomalies is the recorded one), once per seed. The injected stream goes through SmartLogger
(json-xz, pre/post 100 messages unless given) exactly as in `cclog replay`, once per retrigger rule.

An anomaly is caught when a classifier trigger falls between its onset and its end + the 2 s feature window;
a saved window is false when none of its triggers does. The same second half without injection gives the
baseline false windows per hour (bench/detection_real.py reports it for the raw and paper settings too).
Kept: odometry messages inside saved windows against those within [start - pre, end + post] of an anomaly
(the target is at most 1.5x).
"""
import argparse
import collections
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.learning import learning  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.features import FeatureConfig  # noqa: E402

WINDOW = '2s'
REACH = 2.0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', default='0,1,2')
    parser.add_argument('--window', default=WINDOW, help='motion feature window (default 2s)')
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--retrigger', default='event', help='retrigger rules, comma-separated (default event)')
    parser.add_argument('--pre', default='100', help='pre of the smart logger (default 100 messages)')
    parser.add_argument('--post', default='100', help='post of the smart logger (default 100 messages)')
    args = parser.parse_args(argv)
    for rule in args.retrigger.split(','):
        run(args, rule)
    return 0


def _seconds(span, rate):
    from cc_log.base.spans import Span
    span = Span.parse(span)
    return span.seconds if span.is_duration else span.count / rate


def run(args, rule):
    """The bench for one retrigger rule."""
    seeds = [0] if args.quick else [int(s) for s in args.seeds.split(',')]
    types = sim.ANOMALY_TYPES[:3] if args.quick else sim.ANOMALY_TYPES
    started = time.time()
    common.header('Simulator anomalies injected into the real Husky run',
                  [common.describe_data(common.HUSKY_BAG,
                                        '(odometry %s, IMU %s)' % (common.HUSKY_ODOM, common.HUSKY_IMU)),
                   'injection: sim.inject_anomalies, types %s, seeds %s' % (', '.join(types), seeds),
                   'smart logger: retrigger %s, pre %s, post %s' % (rule, args.pre, args.post)])
    records = common.husky_records((common.HUSKY_ODOM, common.HUSKY_IMU))
    first, second = common.split_half(records, common.HUSKY_ODOM)
    config = FeatureConfig('motion', args.window)
    _, X = common.window_vectors(first, common.HUSKY_ODOM, config)
    model, info = learning.train(X, config=config)
    print('model: motion %s window, %d training vectors (first half), %s, nu=%g, gamma=%.3g, threshold %.4g\n'
          % (args.window, len(X), info['method'], info['nu'], info['gamma'], info['threshold']))
    odom = [r for r in second if r.topic == common.HUSKY_ODOM]
    hours = (odom[-1].stamp - odom[0].stamp) / 3600.0
    rate = (len(odom) - 1) / (hours * 3600.0)
    pre, post = _seconds(args.pre, rate), _seconds(args.post, rate)
    kept_total = need_total = 0
    caught, total, delays = collections.Counter(), collections.Counter(), collections.defaultdict(list)
    run_rows = []
    with tempfile.TemporaryDirectory(prefix='cc_log_bench_') as tmp:
        base = common.smart_replay(model, second, common.HUSKY_ODOM, os.path.join(tmp, 'nominal'),
                                   (common.HUSKY_IMU,), pre=args.pre, post=args.post, retrigger=rule)
        run_rows.append(['second half, no injection', 0, '-', len(base['windows']), len(base['windows']),
                         '%.1f' % (len(base['windows']) / hours), '-'])
        false_total = 0
        for seed in seeds:
            injected, truth = sim.inject_anomalies(second, types, seed=seed, topic=common.HUSKY_ODOM)
            result = common.smart_replay(model, injected, common.HUSKY_ODOM,
                                         os.path.join(tmp, '%s-seed%d' % (rule, seed)), (common.HUSKY_IMU,),
                                         pre=args.pre, post=args.post, retrigger=rule)
            matches, false = common.match_anomalies(truth, result['windows'], REACH)
            false_total += false
            kept, need = common.kept_messages(injected, common.HUSKY_ODOM, result['windows'], truth, pre, post)
            kept_total += kept
            need_total += need
            for m in matches:
                total[m['type']] += 1
                if m['caught']:
                    caught[m['type']] += 1
                    delays[m['type']].append(m['delay'])
            run_rows.append(['injected, seed %d' % seed, len(truth),
                             '%d/%d' % (sum(m['caught'] for m in matches), len(truth)),
                             len(result['windows']), false, '%.1f' % (false / hours),
                             '%d/%d = %.2fx' % (kept, need, kept / float(need))])
    common.table(['run (second half, %.0f s)' % (hours * 3600), 'anomalies', 'caught', 'windows', 'false windows',
                  'false windows/h', 'kept/needed'], run_rows, 'Per run:')
    rows = [[kind, '%d/%d' % (caught[kind], total[kind]),
             '%.2f' % max(delays[kind]) if delays[kind] else '-'] for kind in types]
    rows.append(['all', '%d/%d' % (sum(caught.values()), sum(total.values())), '-'])
    common.table(['anomaly type', 'caught', 'worst first-trigger delay s'], rows, 'Caught by type (all seeds):')
    all_caught = sum(caught.values()) == sum(total.values())
    false_rate = false_total / (hours * len(seeds))
    print('target all caught: %d/%d -> %s' % (sum(caught.values()), sum(total.values()),
                                              'met' if all_caught else 'NOT met'))
    print('target <= 1 false window per hour: %.1f /h over %d injected runs (%.1f /h without injection) -> %s' % (
        false_rate, len(seeds), len(base['windows']) / hours, 'met' if false_rate <= 1 else 'NOT met'))
    ratio = kept_total / float(need_total)
    print('target kept <= 1.5x needed: %.2fx (%d of %d odometry messages needed) -> %s' % (
        ratio, kept_total, need_total, 'met' if ratio <= 1.5 else 'NOT met'))
    print('total %.1f s\n' % (time.time() - started))


if __name__ == '__main__':
    sys.exit(main())
