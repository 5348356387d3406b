#!/usr/bin/env python3
"""``cclog tune`` choosing the feature window and classify rate (``tuning.choose``) on simulated bags.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/tune_choice.py                 # a few minutes
    python3 bench/tune_choice.py --quick         # tiny run

A motion model (window 2s) is trained on a nominal simulated run (seed 41); ``tuning.choose`` then tunes every
window of ``--windows`` with every classify rate of ``--rates`` on another nominal run (seed 42) for ``--budget``
false windows per hour, injecting one anomaly of every simulator type (the other windows' models are trained
on the first half of that run, and every setting is tuned on its second half), and the chosen setting is
checked on a third nominal run (seed 43, held out: false windows per hour that the tuning did not see).
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.learning import learning  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.offline import tuning  # noqa: E402
from cc_log.features import FeatureConfig, FeatureStream  # noqa: E402


def records(seed, minutes, rate):
    return [r for r in common.sim_records(sim.SimConfig(rate=rate, seed=seed, minutes=minutes, anomalies=0))[0]
            if r.topic == sim.ODOM_TOPIC]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--windows', default='1s,2s,5s')
    parser.add_argument('--rates', default='50ms,100ms,200ms')
    parser.add_argument('--budget', type=float, default=10.0, help='false windows per hour')
    parser.add_argument('--minutes', type=float, default=10.0, help='minutes of each simulated run')
    parser.add_argument('--rate', type=float, default=50.0, help='odometry Hz')
    parser.add_argument('--quick', action='store_true', help='tiny run: 2 minutes, windows 1s,2s, rates 100ms,200ms')
    args = parser.parse_args(argv)
    if args.quick:
        args.minutes, args.windows, args.rates, args.rate = 2.0, '1s,2s', '100ms,200ms', 20.0
    started = time.time()
    common.header('cclog tune: feature window and classify rate chosen for a false-window budget',
                  ['data: cc_log.sim BWIBot, %g Hz odometry, nominal runs of %g min: seed 41 trains motion 2s, seed 42 '
                   'tunes, seed 43 is held out; budget %g/h; windows %s; classify every %s'
                   % (args.rate, args.minutes, args.budget, args.windows, args.rates)])
    train, tune_run, held = (records(seed, args.minutes, args.rate) for seed in (41, 42, 43))
    config = FeatureConfig('motion', '2s')
    stream = FeatureStream(config, every='100ms')
    model, _ = learning.train(np.array([v for v in (stream.add(r.msg, r.stamp) for r in train) if v is not None]),
                              config=config)
    with common.Timer() as timer:
        chosen, record = tuning.choose(model, [tune_run], sim.ODOM_TOPIC, args.budget, args.windows.split(','),
                                       args.rates.split(','))
    rows = []
    for g in record['grid']:
        rows.append([g['window'] + (' (trained)' if g['trained'] else ''), g['classify_every'], '%.4g' % g['threshold'],
                     '%.1f' % g['false_per_hour'], 'yes' if g['meets_budget'] else 'no', len(g['catches']),
                     '%.2f' % g['mean_latency'] if g['mean_latency'] is not None else '-'])
    common.table(['window', 'classify every', 'threshold', 'false/h (tuned on)', 'within budget', 'types caught',
                  'mean latency s'], rows, 'Every setting tried (tuned on the %s):' % record['tuned_on'])
    hours = (held[-1].stamp - held[0].stamp) / 3600.0
    held_windows = tuning.windows_of(tuning.fires(chosen, held, sim.ODOM_TOPIC, chosen.threshold,
                                                  record['classify_every'], record['retrigger']), 2.0, 2.0)
    print('chosen: window %s, classify every %s: %.1f false/h where tuned, %.1f/h on the held-out run '
          '(%d windows in %.2f h); caught %s (latency %s); missed %s' % (
              record['window'], record['classify_every'], record['false_per_hour'], len(held_windows) / hours,
              len(held_windows), hours, ', '.join(record['catches']),
              ', '.join('%s %.2f s' % item for item in record['latencies'].items()), ', '.join(record['misses']) or
              'none'))
    print('choose: %.1f s wall' % timer.wall)
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
