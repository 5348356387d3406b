"""A collision inside the robot's own stopping envelope: missed by odometry, caught by the IMU and by the command.

The simulated BWIBot's ``soft_collision`` stops the base no harder than its nominal stops, rings the IMU and
leaves the planner commanding speed. Classifiers are trained as ``cclog learn`` trains them on a nominal run
(motion: cc_log's default; imu; command), then fed a run with soft collisions message by message; their Fires
are the decisions (no roscore: the triggers are pure). bench/imu_collision.py measures the same at length.
"""
import numpy as np
import pytest

from cc_log import sim
from cc_log.learning import learning
from cc_log.base.records import Record
from cc_log.features import FeatureConfig, FeatureStream
from cc_log.triggers.classifier import ClassifierTrigger
from cc_log.triggers.rule import RuleTrigger

TOPICS = {'odom': sim.ODOM_TOPIC, 'imu': sim.IMU_TOPIC, 'cmd_vel': sim.CMD_TOPIC}
REACH = 4.0  # s after an anomaly's end a Fire still counts for it: the base speeding up again from rest


def records(config):
    simulator = sim.Simulator(config)
    return [Record(stamp, topic, msg) for topic, stamp, msg in simulator.messages()], simulator.truth


def trained(run, feature_set):
    """A classifier trained as ``cclog learn`` trains it (1 % trimmed), vectors every 10 messages."""
    config = FeatureConfig(feature_set)
    roles = {TOPICS[role]: role for role, _ in config.feature.inputs}
    first = TOPICS[config.feature.inputs[0][0]]
    stream, vectors = FeatureStream(config, every=10), []
    for record in run:
        if record.topic == first:
            vector = stream.add(record.msg, record.stamp)
            if vector is not None:
                vectors.append(vector)
        elif record.topic in roles:
            stream.observe(roles[record.topic], record.msg, record.stamp)
    model, _ = learning.train(np.array(vectors), config=config, trim=learning.DEFAULT_TRIM)
    return ClassifierTrigger(feature_set, model, [TOPICS[role] for role, _ in config.feature.inputs])


def fires(trigger, run):
    """Stamps of the trigger's Fires over the run."""
    return [record.stamp for record in run if record.topic in trigger.topics and trigger.on_record(record)]


@pytest.fixture(scope='module')
def soft_collisions():
    nominal, _ = records(sim.SimConfig(seed=21, minutes=3.0, anomalies=0, imu=True, commands=True))
    run, truth = records(sim.SimConfig(seed=4, minutes=2.5, anomalies=3, anomaly_types='soft_collision', imu=True,
                                       commands=True))
    return nominal, run, truth


def test_a_soft_collision_is_missed_by_odometry_and_caught_by_the_imu_and_the_command(soft_collisions):
    nominal, run, truth = soft_collisions
    assert [entry['type'] for entry in truth] == ['soft_collision'] * 3
    results = {}
    for feature_set in ('motion', 'imu', 'command'):
        stamps = fires(trained(nominal, feature_set), run)
        during = [any(e['start'] <= s <= e['end'] for s in stamps) for e in truth]
        prompt = [any(e['start'] <= s <= e['start'] + 0.5 for s in stamps) for e in truth]
        outside = [s for s in stamps if not any(e['start'] <= s <= e['end'] + REACH for e in truth)]
        results[feature_set] = during, prompt, len(outside)
    assert results['motion'][0] == [False, False, False]  # odometry alone: a nominal stop, a standstill
    assert results['imu'][1] == [True, True, True]        # the impact, within 0.5 s
    assert results['command'][1] == [True, True, True]    # commanded to drive, slowing down
    assert (results['imu'][2], results['command'][2]) == (0, 0)  # and no Fire elsewhere


def test_an_imu_rule_at_twice_the_nominal_maximum_catches_it_at_once(soft_collisions):
    nominal, run, truth = soft_collisions
    limit = 2.0 * max(abs(r.msg.linear_acceleration.x) for r in nominal if r.topic == sim.IMU_TOPIC)
    rule = RuleTrigger('shock', topic=sim.IMU_TOPIC, when='abs(linear_acceleration.x) > %.4g' % limit)
    stamps = fires(rule, run)
    assert [any(e['start'] <= s <= e['start'] + 0.1 for s in stamps) for e in truth] == [True, True, True]
    assert len(stamps) == 3  # nothing else: one Fire per impact (hold_off 5 s)
