#!/usr/bin/env python3
"""Online learning of nominal on the simulator: false windows before and after refits, anomalies still caught.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/learn_online.py            # about a minute
    python3 bench/learn_online.py --quick    # tiny run (tests)

A motion model (window 1s) is trained on a slow simulated BWIBot (0.5 m/s, 0.5 rad/s: the manoeuvres of the
full-speed robot are new to it). The full-speed robot's nominal driving (seed 22) is then fed message by
message through a ClassifierTrigger with online learning on and its drift monitor (as smart mode and ``cclog
replay`` run it: in drift the classifier's own flags are learned too; classify every 100 ms, ``--every`` vectors per
refit, guard 3 s, refits in the caller's thread so the run is repeatable). After each simulated ``--report``
minutes the model in use is scored on another nominal full-speed run (seed 23, 4 min: false windows = runs of
anomalous scores, 2 s apart) and on a run with one anomaly of every type but planning_failure (seed 24:
caught = an anomalous score within [onset, end + 1 s]).
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log.learning import drift, learning  # noqa: E402
from cc_log import sim  # noqa: E402
from cc_log.features import FeatureConfig, FeatureStream  # noqa: E402
from cc_log.learning.online_learning import OnlineLearner  # noqa: E402
from cc_log.triggers import ClassifierTrigger  # noqa: E402
from cc_log.base.records import Record  # noqa: E402

FEATURE = FeatureConfig('motion', '1s')
SLOW = sim.Limits(max_speed=0.5, max_accel=0.8, max_decel=1.0, max_yaw_rate=0.5, max_yaw_accel=2.0)
TYPES = ('collision', 'sudden_acceleration', 'excessive_twisting', 'localization_jump', 'wheels_slipping')


def odometry(run, limits=sim.BWIBOT_LIMITS):
    simulator = sim.Simulator(run, limits=limits)
    return [(stamp, msg) for topic, stamp, msg in simulator.messages() if topic == sim.ODOM_TOPIC], simulator.truth


def flag_starts(model, messages, merge=2.0):
    """Stamps where runs of anomalous scores (10 per second) start; runs closer than ``merge`` s merge."""
    stream, starts, last = FeatureStream(FEATURE, every='100ms'), [], None
    for stamp, msg in messages:
        vector = stream.add(msg, stamp)
        if vector is not None and model.is_anomalous(vector)[0]:
            if last is None or stamp - last > merge:
                starts.append(stamp)
            last = stamp
    return starts


def slow_model(rate):
    """The motion model of 6 minutes of the slow BWIBot (seed 21) at ``rate`` Hz."""
    slow, _ = odometry(sim.SimConfig(rate=rate, seed=21, minutes=6, anomalies=0), SLOW)
    stream = FeatureStream(FEATURE, every='100ms')
    vectors = [v for v in (stream.add(msg, stamp) for stamp, msg in slow) if v is not None]
    return learning.train(np.array(vectors), config=FEATURE)[0]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    for flag, kind, default, text in (('--minutes', float, 15.0, 'minutes of nominal driving to learn from'),
                                      ('--every', int, 1000, 'new vectors per refit'),
                                      ('--report', float, 2.5, 'minutes between reports'),
                                      ('--rate', float, 20.0, 'odometry Hz')):
        parser.add_argument(flag, type=kind, default=default, help=text)
    parser.add_argument('--quick', action='store_true', help='tiny run: 3 minutes, a refit every 500 vectors')
    args = parser.parse_args(argv)
    if args.quick:
        args.minutes, args.every, args.report = 3.0, 500, 1.5
    begun = time.time()
    common.header('Online learning of nominal on the simulator',
                  ['data: cc_log.sim; trained on a slow BWIBot (seed 21, 6 min, 0.5 m/s, 0.5 rad/s), learning from '
                   'the full-speed robot (seed 22, %g min), scored on seed 23 (4 min nominal) and seed 24 (one '
                   'anomaly of each of %d types); %g Hz odometry, motion 1s, every %d vectors'
                   % (args.minutes, len(TYPES), args.rate, args.every)])
    model = slow_model(args.rate)
    held_back, _ = odometry(sim.SimConfig(rate=args.rate, seed=23, minutes=4, anomalies=0))
    anomalies, truth = odometry(sim.SimConfig(rate=args.rate, seed=24, minutes=3, anomalies=len(TYPES), gap=15.0,
                                              anomaly_types=TYPES))
    learner = OnlineLearner(model, None, every=args.every, keep=5000, guard='3s', background=False)
    trigger = ClassifierTrigger('classifier', model, '/odom', classify_every='100ms', learner=learner)
    monitor, = drift.monitor_classifiers([trigger])   # as smart mode and cclog replay run it
    learning_run, _ = odometry(sim.SimConfig(rate=args.rate, seed=22, minutes=args.minutes, anomalies=0))
    rows, step, refit_seconds = [], int(args.report * 60 * args.rate), []

    def report(minutes):
        stats = learner.stats()
        starts = flag_starts(trigger.model, anomalies)
        caught = [e['type'] for e in truth if any(e['start'] <= s <= e['end'] + 1.0 for s in starts)]
        false = len(flag_starts(trigger.model, held_back))
        rows.append(['%.1f' % minutes, stats['vectors_seen'], stats['vectors_learned'], stats['vectors_refused'],
                     stats['vectors_adapted'], 'no' if monitor.first_drift is None else 'yes', stats['refits'],
                     '%d (%.0f/h)' % (false, false * 15.0), '%d/%d' % (len(caught), len(truth)),
                     ', '.join(sorted(set(e['type'] for e in truth) - set(caught))) or '-'])
    report(0.0)
    for index, (stamp, msg) in enumerate(learning_run):
        refits = learner.refits
        started = time.time()
        trigger.on_record(Record(stamp, '/odom', msg))
        if learner.refits != refits:
            refit_seconds.append(time.time() - started)
        if (index + 1) % step == 0:
            report((index + 1) / args.rate / 60.0)
    common.table(['minutes learned', 'vectors seen', 'learned', 'refused (near a flag)', 'adapted (in drift)',
                  'drift reported', 'refits',
                  'false windows (4 min)', 'caught', 'missed'], rows,
                 'False windows on another nominal run, anomalies caught, as learning goes on:')
    if refit_seconds:
        print('refit: %.2f s mean, %.2f s max (learning.train on the support vectors + up to 5000 learned vectors)'
              % (np.mean(refit_seconds), np.max(refit_seconds)))
    print('total %.1f s' % (time.time() - begun))
    return 0


if __name__ == '__main__':
    sys.exit(main())
