#!/usr/bin/env python3
"""Which signal each anomaly needs: odometry, IMU, command and goal-status detectors side by side.

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/imu_collision.py            # about four minutes
    python3 bench/imu_collision.py --quick    # tiny run (tests)
    python3 bench/imu_collision.py --soft-decel 1.0,1.8   # braking at 0.5-0.9 x max_decel

The question: a collision inside the robot's own stopping envelope (``soft_collision`` of the simulator: the base
stops no harder than its own nominal stops, the IMU rings, the planner keeps commanding speed) is invisible to
odometry features; which signal catches it, how fast, at what false-window cost? And which signal does each of
the simulator's anomaly types need?

Detectors, each trained or set from nominal driving alone and replayed alone through SmartLogger (the replay of
``cclog replay``; bag-lz4, pre and post 2 s, classify every 50 ms, retrigger ``event``):

- ``odometry``: cc_log's default classifier (``motion`` features, 2 s window, ``cclog learn``'s training);
- ``imu``: the same classifier on the ``imu`` feature set (``/imu/data``);
- ``command``: the same classifier on the ``command`` feature set (``/odom`` against ``/cmd_vel``);
- ``imu rule``: a rule ``abs(linear_acceleration.x) > K``, K = 2 x the largest |forward acceleration| of the
  training run (the issue's envelope factor; no learning beyond that maximum);
- ``goal rule``: a rule on move_base's status, ``status_list[0].status == 4`` (ABORTED).

Data: the simulated BWIBot (cc_log.sim, 100 Hz odometry and IMU, 20 Hz cmd_vel, 2 Hz goal status). Training: a
nominal run (seed 21; ``--train-minutes``). Test: a run (seed 22) with every anomaly type of sim.ANOMALY_TYPES
and ``soft_collision`` (``--per-type`` of each, SLOT seconds apiece), and a nominal run (seed 23) for false
windows. Real IMU: the Husky (../shared/data/real/husky_outdoor_2015.bag, 30 Hz /imu/data, 10 Hz odometry,
rough terrain, nominal only): trained on its first half, replayed on the second; every window there is false.
Sequor (real wall crashes, ../shared/data/real/sequor_*.bag): its /lin_acc peaks in the
crashes against its normal runs', the IMU rule's test.

Caught: a Fire of the detector within [onset, end + 2 s]; latency: the first such Fire minus the onset. A window
is false when none of its Fires is within [onset, end + 2 s] of an anomaly.
"""
import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

from cc_log import sim  # noqa: E402
from cc_log.learning import learning  # noqa: E402
from cc_log.features import FeatureConfig, FeatureStream  # noqa: E402
from cc_log.triggers.classifier import ClassifierTrigger  # noqa: E402
from cc_log.triggers.rule import RuleTrigger  # noqa: E402

REACH = 2.0           # s after an anomaly's end a Fire still counts as catching it
RULE_FACTOR = 2.0     # the IMU rule's threshold: this many times the training run's largest |a_x|
STRIDE = 10           # training vectors: one every this many messages of the first input
SLOT = 45.0           # s of the test run per anomaly: 20 s gap, up to 10 s of anomaly, 15 s to find the base driving
SEQUOR_NOMINAL = 'sequor_E2_normal_safe_escape_straight.bag'
SEQUOR_CRASHES = 'sequor_N3_anomalous_crash_wall.bag'
ALFA = 'alfa_carbonZ_engine_failure.bag'
ALFA_IMU, ALFA_FAILURE = '/mavros/imu/data_raw', '/failure_status/engines'
TYPES = sim.ANOMALY_TYPES + sim.SIM_ONLY_TYPES
DETECTORS = ('odometry', 'imu', 'command', 'imu rule', 'goal rule')
SIM_TOPICS = {'odom': sim.ODOM_TOPIC, 'imu': sim.IMU_TOPIC, 'cmd_vel': sim.CMD_TOPIC}


def sim_config(seed, minutes, types=None, per_type=0):
    """A simulated run with IMU and commands: nominal, or ``per_type`` anomalies of each of ``types``."""
    count = len(types) * per_type if types else 0
    return sim.SimConfig(seed=seed, minutes=minutes, anomalies=count, anomaly_types=types or sim.ANOMALY_TYPES,
                         imu=True, commands=True)


def train_classifier(records, feature_set, topics):
    """A model trained as ``cclog learn`` does (1 % trimmed) on ``records``: the feature set's vectors, one every
    STRIDE messages of its first input; ``topics`` maps its roles to topic names."""
    config = FeatureConfig(feature_set)
    roles = {topics[role]: role for role, _ in config.feature.inputs}
    first = topics[config.feature.inputs[0][0]]
    stream, vectors = FeatureStream(config, every=STRIDE), []
    for record in records:
        role = roles.get(record.topic)
        if role is None:
            continue
        if record.topic != first:
            stream.observe(role, record.msg, record.stamp)
            continue
        vector = stream.add(record.msg, record.stamp)
        if vector is not None:
            vectors.append(vector)
    model, _ = learning.train(np.array(vectors), config=config, trim=learning.DEFAULT_TRIM)
    return model


def largest_forward_acceleration(records, topic):
    """The largest |linear_acceleration.x| of ``topic``'s IMU messages."""
    return max(abs(r.msg.linear_acceleration.x) for r in records if r.topic == topic)


def detectors(training, topics, names=DETECTORS):
    """``{name: function making a fresh Trigger}`` of the detectors, trained on ``training`` (records)."""
    made = {}
    for name, feature_set in (('odometry', 'motion'), ('imu', 'imu'), ('command', 'command')):
        if name in names:
            model = train_classifier(training, feature_set, topics)
            inputs = [topics[role] for role, _ in model.config.feature.inputs]
            made[name] = (lambda model=model, inputs=inputs: ClassifierTrigger('classifier', model, inputs))
    if 'imu rule' in names:
        limit = RULE_FACTOR * largest_forward_acceleration(training, topics['imu'])
        made['imu rule'] = lambda: RuleTrigger('imu_rule', topic=topics['imu'],
                                               when='abs(linear_acceleration.x) > %.4g' % limit)
    if 'goal rule' in names:
        made['goal rule'] = lambda: RuleTrigger('goal_rule', topic=topics['status'],
                                                when='status_list[0].status == 4')
    return made


def replay(trigger, records, driving_topic):
    """Windows of one trigger replayed over ``records`` (bench/common.smart_replay)."""
    with tempfile.TemporaryDirectory() as directory:
        return common.smart_replay(None, records, driving_topic, directory, fmt='bag-lz4', pre='2s', post='2s',
                                   triggers=(trigger,))['windows']


def score(windows, truth):
    """``(per-anomaly [{type, caught, latency}], false windows)``."""
    per, false = common.match_anomalies(truth, windows, REACH)
    return [{'type': e['type'], 'caught': e['caught'], 'latency': e['delay']} for e in per], false


def husky_halves():
    """(first half, second half) of the Husky's odometry and IMU records in time order, and the second's hours."""
    records = sorted(common.husky_records((common.HUSKY_ODOM, common.HUSKY_IMU)), key=lambda r: r.stamp)
    first, second = common.split_half(records, common.HUSKY_ODOM)
    return first, second, (second[-1].stamp - second[0].stamp) / 3600.0


def sequor_crashes():
    """The Sequor robot's real wall crashes against its normal driving, on its /lin_acc (AccelStamped, 10 Hz):
    ``(nominal max |a|, [(trial, its max |a|)] of the crashes)``, |a| the larger of |x| and |y|."""
    def largest(path):
        label, peaks = None, {}
        for record in bagio.read_messages(path, ['/label', '/lin_acc']):
            if record.topic == '/label':
                label = record.msg.data
            elif label is not None:
                linear = record.msg.accel.linear
                peaks[label] = max(peaks.get(label, 0.0), abs(linear.x), abs(linear.y))
        return peaks
    from cc_log.storage.bag import bagio
    nominal = largest(os.path.join(common.DATA, SEQUOR_NOMINAL))
    return max(nominal.values()), sorted(largest(os.path.join(common.DATA, SEQUOR_CRASHES)).items())


def alfa_engine_failure():
    """The ALFA UAV's IMU (/mavros/imu/data_raw, 10 Hz) before and after its engine fails (the first True on
    /failure_status/engines): ``(largest |a_x|, |a_y| before, the same after)``."""
    from cc_log.storage.bag import bagio
    failed, before, after = None, [0.0, 0.0], [0.0, 0.0]
    for record in bagio.read_messages(os.path.join(common.DATA, ALFA), [ALFA_IMU, ALFA_FAILURE]):
        if record.topic == ALFA_FAILURE:
            failed = failed or (record.stamp if record.msg.data else None)
            continue
        peaks = after if failed is not None else before
        linear = record.msg.linear_acceleration
        peaks[0], peaks[1] = max(peaks[0], abs(linear.x)), max(peaks[1], abs(linear.y))
    return before, after


def upper95(count, hours):
    """The 95 % upper bound of a rate (per hour) from ``count`` events in ``hours`` (Poisson, exact)."""
    from scipy.stats import chi2
    return chi2.ppf(0.95, 2 * (count + 1)) / 2.0 / hours


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--train-minutes', type=float, default=8.0)
    parser.add_argument('--nominal-minutes', type=float, default=20.0)
    parser.add_argument('--per-type', type=int, default=3, help='anomalies of each type in the test run')
    parser.add_argument('--soft-decel', default='%g,%g' % sim.anomalies.SOFT_DECEL,
                        help='a soft collision\'s deceleration range as fractions of the planned braking (%g m/s^2; '
                             'the base\'s max_decel is %g)' % (sim.floor.PLANNED_DECEL, sim.BWIBOT_LIMITS.max_decel))
    parser.add_argument('--quick', action='store_true', help='tiny run: 2 min training, 1 of each type')
    args = parser.parse_args(argv)
    if args.quick:
        args.train_minutes, args.nominal_minutes, args.per_type = 2.0, 1.0, 1
    sim.anomalies.SOFT_DECEL = tuple(float(value) for value in args.soft_decel.split(','))
    started = time.time()
    common.header('Which signal each anomaly needs: odometry, IMU, command, goal status (simulated BWIBot, Husky)',
                  [common.describe_data(common.HUSKY_BAG, '(real IMU, nominal)'), 'revision: %s' % common.revision()])
    topics = dict(SIM_TOPICS, status=sim.STATUS_TOPIC)
    training, _ = common.sim_records(sim_config(21, args.train_minutes))
    made = detectors(training, topics)
    minutes = len(TYPES) * args.per_type * SLOT / 60.0 + 1.0
    test, truth = common.sim_records(sim_config(22, minutes, TYPES, args.per_type))
    nominal, _ = common.sim_records(sim_config(23, args.nominal_minutes))
    hours = (nominal[-1].stamp - nominal[0].stamp) / 3600.0
    results = {}
    for name, make in made.items():
        caught, false = score(replay(make(), test, sim.ODOM_TOPIC), truth)
        _, nominal_false = score(replay(make(), nominal, sim.ODOM_TOPIC), [])
        results[name] = (caught, false, nominal_false)
    print('simulated BWIBot: trained on %g min of nominal driving (seed 21); test run (seed 22): %d anomalies, '
          'soft collisions at %s x %g m/s^2; nominal run (seed 23): %.0f min; %s'
          % (args.train_minutes, len(truth), args.soft_decel, sim.floor.PLANNED_DECEL, hours * 60,
             made['imu rule']().condition.text))
    rows = []
    for kind in TYPES:
        row = [kind]
        for name in made:
            hits = [e for e in results[name][0] if e['type'] == kind]
            latency = [e['latency'] for e in hits if e['caught']]
            row.append('%d/%d (%s)' % (len(latency), len(hits), '%.2f s' % np.median(latency) if latency else '-'))
        rows.append(row)
    rows.append(['false windows, test run'] + [results[name][1] for name in made])
    rows.append(['false windows, nominal run'] + ['%d (< %.0f/h)' % (results[name][2], upper95(results[name][2], hours))
                                                  for name in made])
    common.table(['anomaly: caught/n (median latency)'] + list(made), rows)
    first, second, husky_hours = husky_halves()
    real = detectors(first, {'odom': common.HUSKY_ODOM, 'imu': common.HUSKY_IMU}, ('odometry', 'imu', 'imu rule'))
    counts = {name: len(replay(make(), second, common.HUSKY_ODOM)) for name, make in real.items()}
    print('Husky (real, nominal only): trained on the first half, replayed on the second (%.1f min); %s'
          % (husky_hours * 60, real['imu rule']().condition.text))
    common.table(['detector', 'false windows', '95% upper bound /h'],
                 [[name, count, upper95(count, husky_hours)] for name, count in counts.items()])
    nominal_peak, crashes = sequor_crashes()
    peaks = [peak for _, peak in crashes]
    beyond = [sum(p > factor * nominal_peak for p in peaks) for factor in (2.0, 1.5)]
    print('Sequor (real): %d wall crashes (%s) against 20 normal runs (%s), /lin_acc at 10 Hz; a rule at 2 x the '
          'normal runs\' largest |a| (%.2f m/s^2) catches %d/%d; at 1.5 x, %d/%d; crash peaks %.2f-%.2f m/s^2 (median '
          '%.2f)\n' % (len(crashes), SEQUOR_CRASHES, SEQUOR_NOMINAL, nominal_peak, beyond[0], len(peaks), beyond[1],
                       len(peaks), min(peaks), max(peaks), float(np.median(peaks))))
    before, after = alfa_engine_failure()
    print('ALFA UAV (real, %s, %s): largest |a_x|, |a_y| before the engine fails %.2f, %.2f m/s^2; after %.2f, %.2f: '
          'a failing engine is no shock\n' % (ALFA, ALFA_IMU, before[0], before[1], after[0], after[1]))
    soft = {name: [e for e in results[name][0] if e['type'] == 'soft_collision'] for name in made}
    for name in ('imu', 'command', 'imu rule'):
        prompt = sum(1 for e in soft[name] if e['caught'] and e['latency'] <= 0.5)
        print('target (%s) every soft collision caught within 0.5 s: %d/%d -> %s'
              % (name, prompt, len(soft[name]), 'met' if prompt == len(soft[name]) else 'NOT met'))
    print('total %.1f s' % (time.time() - started))
    return 0


if __name__ == '__main__':
    sys.exit(main())
