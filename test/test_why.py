"""Windows that say why: a Fire's ``why`` goes into the metadata of every format and part, ``cclog info`` prints
it, readers refuse or sanitise a hostile one, the classifier names the feature that stood out and the rule the
level it crossed."""
import json
import math
import random

import numpy as np
import pytest

from cc_log.learning import learning
from cc_log.logger import smart_events
from cc_log.base import why
from cc_log.learning.model import AnomalyModel
from cc_log.base.records import LogWindow, Record, Trigger
from cc_log.base.event_kinds import OPENED
from cc_log.logger.smart import SmartLogger
from cc_log.features import FeatureConfig, FeatureStream
from cc_log.offline import cli
from cc_log.storage import log_format, window_info
from cc_log.storage.log_format import window_files
from cc_log.triggers import ClassifierTrigger, RuleTrigger
from cc_log.triggers.base import Fire, Trigger as BaseTrigger
from test_event_windows import odom


ODOM = '/odom'
RATE = 20.0
WHY = (why.entry('max(wz)', 4.2, 1.826, 'rad/s', label='yaw rate'),
       why.entry('pose_step', 1.2, 0.1, 'm', text='pose moved 1.2 m while the wheels reported 0.1 m'))
WHY_TEXT = 'yaw rate 4.2 rad/s, 2.3x the most seen in training'


def drive(seconds, start=100.0, spin=None, seed=0):
    """Records of a base cruising at 0.5 m/s with noise; ``spin``: (onset, end) turning at 2 rad/s."""
    rng = random.Random(seed)
    out, x = [], 0.0
    for i in range(int(seconds * RATE)):
        stamp = start + i / RATE
        speed, yaw_rate = 0.5 + rng.gauss(0.0, 0.02), rng.gauss(0.0, 0.05)
        if spin and spin[0] <= stamp < spin[1]:
            yaw_rate = 2.0
        x += speed / RATE
        out.append(Record(stamp, ODOM, odom(stamp, x, speed, yaw_rate)))
    return out


class Explained(BaseTrigger):
    """Fires with WHY on every driving message within ``spans``."""

    kind = 'explained-test'

    def __init__(self, spans):
        super(Explained, self).__init__('spin')
        self.topics = frozenset([ODOM])
        self.spans = spans

    def on_record(self, record):
        if any(start <= record.stamp < end for start, end in self.spans):
            return [self.fire('spin', score_at(record.stamp), WHY)]
        return []


def score_at(stamp):
    """The scores of Explained: lowest at 106.0 s."""
    return -2.0 + abs(stamp - 106.0)


def test_a_fire_says_why_last_and_nothing_by_default():
    assert Fire._fields[-1] == 'why' and Fire('a', 'b', 1.0).why == ()
    assert Explained([]).fire('spin', -1.0, WHY).why == WHY
    assert WHY[0]['text'] == WHY_TEXT and WHY[0]['ratio'] == pytest.approx(4.2 / 1.826)
    assert WHY[1]['text'] == 'pose moved 1.2 m while the wheels reported 0.1 m'


def write(directory, fmt, spans, max_window='60s'):
    logger = SmartLogger(None, str(directory), fmt, '0.5s', '0.5s', driving_topic=ODOM, max_window=max_window,
                         triggers=[Explained(spans)], background=False)
    events = []
    logger.on_event(events.append)
    for record in drive(20):
        logger.on_message(record.topic, record.msg, record.stamp)
    assert logger.close(30)
    return events


@pytest.mark.parametrize('fmt', ['bag-lz4', 'json-xz'])
@pytest.mark.parametrize('max_window', ['60s', '1s'])  # one file; parts (json-xz: a file each; bag-lz4: one file)
def test_the_why_of_a_fire_is_in_every_file_of_its_window_and_cclog_info_prints_it(tmp_path, capsys, fmt, max_window):
    events = write(tmp_path, fmt, [(105.0, 107.0)], max_window)
    paths = window_files(str(tmp_path))
    assert paths and (len(paths) > 1) == (fmt == 'json-xz' and max_window == '1s')
    explained = []
    for path in paths:
        triggers = log_format.read_metadata(path)['triggers']
        said = [trigger for trigger in triggers if 'why' in trigger]
        assert said and all(trigger['why'] == list(WHY) for trigger in said), path
        # the first firing and the most anomalous one of the file's (or part's) firings say why
        lowest = min(triggers, key=lambda trigger: trigger['score'])
        assert said[0] is triggers[0] and lowest in said and len(said) <= 2
        explained += [trigger['stamp'] for trigger in said]
    assert 106.0 in explained and 105.0 in explained
    opened = [event for event in events if event.kind == OPENED]
    assert opened and opened[0].why == WHY
    assert smart_events.reason_text(opened[0]) == 'spin; why: ' + WHY_TEXT
    assert cli.main(['info', str(tmp_path)]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith('  why ')]
    assert lines and set(lines) == {'  why        spin: %s; %s' % (WHY_TEXT, WHY[1]['text'])}
    assert cli.main(['info', str(tmp_path), '--json']) == 0
    windows = json.loads(capsys.readouterr().out)['windows']
    said = [trigger['why'] for w in windows for trigger in w['triggers'] if trigger['why']]
    assert said and all(entries[0]['text'] == WHY_TEXT for entries in said)


def hostile_file(directory, entries):
    """A json-xz window whose first trigger says ``entries`` as its why, as a hostile writer would."""
    records = drive(1)
    window = LogWindow(records, [Trigger(records[0].stamp, 'spin', -1.0, 'spin')])
    trigger = {'stamp': records[0].stamp, 'reason': 'spin', 'score': -1.0, 'name': 'spin', 'why': entries}
    return log_format.write_window(window, str(directory), 'json-xz', {'triggers': [trigger]})[0]


@pytest.mark.parametrize('entries', [
    [{'feature': 'x', 'text': 'y' * 10000}],                    # 10 kB of text
    [{'feature': 'x', 'value': 'NaN', 'text': 'nan'}],         # not a number
    [{'text': 'a'}] * 4,                                        # more than 3
    'yaw rate',                                                # not a list
    [{'feature': 'x', 'value': [1, 2], 'text': 'a'}],
])
def test_a_hostile_why_is_refused_by_the_reader_with_one_line(tmp_path, capsys, entries):
    path = hostile_file(tmp_path, entries)
    with pytest.raises(ValueError, match=r': metadata: triggers must be a list of objects .*"why"'):
        log_format.read_metadata(path)
    assert cli.main(['info', path]) != 0
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


@pytest.mark.parametrize('value', [float('nan'), float('inf'), -float('inf')])
def test_a_why_with_a_non_finite_number_is_refused(value):
    trigger = {'stamp': 1.0, 'reason': 'spin', 'score': -1.0, 'why': [{'feature': 'x', 'value': value, 'text': 'a'}]}
    with pytest.raises(ValueError, match=r'^metadata: triggers must be'):
        window_info.check_metadata({'triggers': [trigger]})


def test_control_characters_of_a_why_reach_the_terminal_escaped(tmp_path, capsys):
    path = hostile_file(tmp_path, [{'feature': 'x', 'value': 1.0, 'text': 'evil \x1b[2J\x07 text'}])
    assert cli.main(['info', path]) == 0
    out = capsys.readouterr().out
    assert 'why        spin: evil \\x1b[2J\\x07 text' in out and '\x1b' not in out and '\x07' not in out


def test_bounded_keeps_three_short_finite_entries():
    entries = why.bounded([{'feature': 'f' * 500, 'value': float('nan'), 'limit': np.float32(2.0), 'ratio': True,
                            'text': 't' * 500}] * 5)
    assert len(entries) == why.MAX_ENTRIES and why.check(entries)
    first = entries[0]
    assert len(first['text']) == why.MAX_TEXT and len(first['feature']) == why.MAX_FEATURE
    assert first['value'] is None and first['limit'] == 2.0 and first['ratio'] is None
    many = why.bounded([dict({'k%d' % i: i for i in range(40)}, text='t', feature='f')])
    assert why.check(many) and many[0]['text'] == 't' and many[0]['feature'] == 'f'
    assert not why.check([dict({'k%d' % i: i for i in range(40)}, text='t')])


@pytest.fixture(scope='module')
def model():
    config = FeatureConfig('motion', '2s')
    stream = FeatureStream(config, every='2')
    vectors = [v for v in (stream.add(r.msg, r.stamp) for r in drive(300, seed=1)) if v is not None]
    return learning.train(np.array(vectors), config=config)[0]


def spin_fires(model):
    trigger = ClassifierTrigger('classifier', model, ODOM, classify_every='1', retrigger='onset')
    return [fire for record in drive(60, spin=(130.0, 131.0)) for fire in trigger.on_record(record)]


def test_the_classifier_names_the_yaw_rate_of_a_spin_against_the_most_seen_in_training(model):
    assert model.ranges is not None
    index = model.names.index('max(wz)')
    fires = spin_fires(model)
    assert fires and fires[0].why
    first = fires[0].why[0]
    assert first['feature'] == 'max(wz)' and first['value'] == pytest.approx(2.0)
    assert first['limit'] == pytest.approx(model.ranges['max'][index])
    assert first['ratio'] == pytest.approx(2.0 / first['limit'])
    assert first['text'] == 'max yaw rate 2 rad/s, %.3gx the most seen in training' % first['ratio']
    assert all(entry['sd'] > 0 for entry in fires[0].why)  # outside the training range, most outstanding first
    assert [entry['sd'] for entry in fires[0].why] == sorted((entry['sd'] for entry in fires[0].why), reverse=True)
    assert model.ranges['max'][index] < 0.5  # nominal driving never turned at 2 rad/s
    assert len(fires[0].why) <= why.MAX_ENTRIES and all(len(e['text']) <= why.MAX_TEXT for e in fires[0].why)


def test_the_ranges_survive_the_model_file_and_a_model_without_them_still_loads_and_fires(model, tmp_path):
    path = str(tmp_path / 'model.json')
    model.save(path)
    loaded = AnomalyModel.load(path)
    assert np.allclose(loaded.ranges['max'], model.ranges['max'])
    document = model.to_dict()
    del document['ranges']
    old = AnomalyModel.from_dict(document)
    assert old.ranges is None
    fires = spin_fires(old)
    assert fires and fires[0].why
    first = fires[0].why[0]
    assert first['feature'] == 'max(wz)' and first['ratio'] is None
    assert first['text'] == 'max yaw rate 2 rad/s, %.3g sd above the training mean' % first['sd']
    document['ranges'] = {'min': [0.0], 'max': [1.0]}
    with pytest.raises(ValueError, match='ranges'):
        AnomalyModel.from_dict(document)


def test_a_rule_says_the_field_its_value_and_the_level_it_crossed():
    rule = RuleTrigger('fast', topic=ODOM, when='abs(twist.twist.angular.z) > 1.5')
    fires = [fire for record in drive(40, spin=(110.0, 111.0)) for fire in rule.on_record(record)]
    assert len(fires) == 1
    said, = fires[0].why
    assert said['feature'] == 'abs(twist.twist.angular.z)' and said['value'] == pytest.approx(2.0)
    assert said['limit'] == 1.5 and said['ratio'] == pytest.approx(2.0 / 1.5)
    assert said['text'] == 'abs(twist.twist.angular.z) 2 > 1.5'
    assert not math.isnan(said['value'])


def test_a_recovered_window_keeps_the_why_of_its_triggers_bounded():
    from cc_log.storage import recovery
    metadata = {'triggers': [{'stamp': 5.0, 'reason': 'spin', 'score': -1.0, 'name': 'spin', 'why': list(WHY)},
                             {'stamp': 6.0, 'reason': 'spin', 'why': [{'text': 'x' * 1000, 'value': 'NaN'}] * 9}]}
    first, second = recovery._triggers(metadata, 0.0)
    assert first.why == list(WHY)
    assert len(second.why) == why.MAX_ENTRIES and why.check(second.why) and second.why[0]['value'] is None
