"""Classifier windows that fit the event: retrigger 'event' against 'every' with a model trained on real rows."""
import random

import numpy as np
import pytest

from cc_log.learning import learning
from cc_log.features import FeatureConfig, FeatureStream
from cc_log.features.window import FeatureWindow
from cc_log.base.spans import Span
from cc_log.triggers import ClassifierTrigger
from cc_log.triggers.classifier import recent_span
from cc_log.base.records import Record

from nav_msgs.msg import Odometry  # noqa: E402

ODOM = '/odom'
RATE = 20.0
WINDOW = '2s'
ONSET, END = 130.0, 131.0   # a surge to 2.5 m/s


def odom(stamp, x, speed, yaw_rate=0.0):
    """An Odometry message at ``stamp`` driving along x."""
    msg = Odometry()
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9))
    msg.pose.pose.orientation.w = 1.0
    msg.pose.pose.position.x = x
    msg.twist.twist.linear.x = speed
    msg.twist.twist.angular.z = yaw_rate
    return msg


def drive(seconds, start=100.0, surge=None, seed=0):
    """Records of a base cruising at 0.5 m/s with noise; ``surge``: (onset, end) at 2.5 m/s."""
    rng = random.Random(seed)
    out, x = [], 0.0
    for i in range(int(seconds * RATE)):
        stamp = start + i / RATE
        speed = 0.5 + rng.gauss(0.0, 0.02)
        if surge and surge[0] <= stamp < surge[1]:
            speed = 2.5
        x += speed / RATE
        out.append(Record(stamp, ODOM, odom(stamp, x, speed)))
    return out


@pytest.fixture(scope='module')
def model():
    config = FeatureConfig('motion', WINDOW)
    stream = FeatureStream(config, every='2')
    vectors = [v for v in (stream.add(r.msg, r.stamp) for r in drive(300, seed=1)) if v is not None]
    return learning.train(np.array(vectors), config=config)[0]


def fire_stamps(model, rule, records, **kwargs):
    trigger = ClassifierTrigger('classifier', model, ODOM, classify_every='1', retrigger=rule, **kwargs)
    return [r.stamp for r in records if trigger.on_record(r)]


def test_event_fires_at_the_onset_and_stops_with_the_anomaly_not_a_feature_window_later(model):
    records = drive(60, surge=(ONSET, END))
    every = fire_stamps(model, 'every', records)
    event = fire_stamps(model, 'event', records)
    assert every and event
    assert ONSET <= every[0] < ONSET + 0.2 and event[0] == every[0]
    assert every[-1] >= END + 1.5                   # the surge's rows keep the whole 2 s window anomalous
    assert END - 0.1 <= event[-1] <= END + 0.5 + 0.1  # recent = a quarter of 2 s
    assert set(event) <= set(every)
    assert fire_stamps(model, 'event', drive(60, seed=3)) == fire_stamps(model, 'every', drive(60, seed=3)) == []


def test_event_with_a_shorter_recent_ends_sooner(model):
    records = drive(60, surge=(ONSET, END))
    short = fire_stamps(model, 'event', records, recent='0.1s')
    assert short and short[-1] <= END + 0.2


def test_recent_defaults_to_a_quarter_of_the_window_and_is_checked():
    assert recent_span(Span.parse('2s'), None) == Span.duration(0.5)
    assert recent_span(Span.parse('500'), None) == Span.messages(125)
    assert recent_span(Span.parse('2s'), '250ms') == Span.duration(0.25)
    for recent, match in (('10', 'positive duration'), ('3s', 'longer than the feature window'),
                          ('0s', 'positive'), ('soon', 'recent')):
        with pytest.raises(ValueError, match=match):
            recent_span(Span.parse('2s'), recent)


def test_newest_rows_of_the_feature_window():
    window = FeatureWindow(FeatureConfig('motion', '1s'))
    for i in range(30):
        window.add(100.0 + i * 0.1, [float(i)] * 18)
    assert window.newest(Span.duration(0.25))[:, 0].tolist() == [27.0, 28.0, 29.0]
    assert window.newest(Span.messages(2))[:, 0].tolist() == [28.0, 29.0]
    assert window.newest(Span.messages(100)).shape == window.rows().shape
    assert FeatureWindow(FeatureConfig('motion', '1s')).newest(Span.messages(2)).shape == (0, 18)


def test_a_configuration_sets_event_and_recent_and_refuses_a_bad_recent(model, tmp_path):
    from cc_log.logger.config import Config
    from cc_log.learning.model import AnomalyModel
    path = str(tmp_path / 'model.json')
    model.save(path)
    entry = {'name': 'motion', 'kind': 'classifier', 'model': path, 'topics': [ODOM], 'retrigger': 'event',
             'recent': '250ms'}
    trigger, = Config.from_dict({'triggers': [entry]}).build_triggers(AnomalyModel.load, lambda kind: None)
    assert (trigger.retrigger, trigger.recent) == ('event', Span.duration(0.25))
    assert trigger.describe()['recent'] == '0.25s'
    with pytest.raises(ValueError, match=r'\(motion\): recent: 3s is longer than the feature window 2s'):
        Config.from_dict({'triggers': [dict(entry, recent='3s')]}).build_triggers(AnomalyModel.load,
                                                                                  lambda kind: None)
