"""Training from real, dirty days: trimming the most outlying nominal vectors, the coverage a model records and
the drift monitor's warning when driving leaves it, and ``cclog tune`` saying which events a threshold loses."""
import copy
import json
import math
import os
from types import SimpleNamespace as NS

import numpy as np
import pytest

from cc_log import sim
from cc_log.learning import drift, learning
from cc_log.learning.model import AnomalyModel, ModelError
from cc_log.base.records import Record
from cc_log.features import FeatureConfig, FeatureStream, vector_length
from cc_log.offline import tuning
from cc_log.offline.cli.tune_cmd import tune_lines
from cc_log.triggers import ClassifierTrigger

from test_cli import ok, ok_json

CONFIG = FeatureConfig('motion', '2s')
D = vector_length(CONFIG)


def dirty_day(n=1000, seed=0):
    """``(vectors, stamps, anomalous rows)``: correlated nominal vectors, one every 0.1 s, with a run of 10
    consecutive anomalous windows (one 1 s anomaly seen by sliding windows) at 3/10 of the day."""
    rng = np.random.RandomState(seed)
    base = rng.normal(size=(n, 6))
    X = np.hstack([base, base.dot(rng.normal(size=(6, D - 6))) * 0.3 + rng.normal(size=(n, D - 6)) * 0.05])
    first = 3 * n // 10
    X[first:first + 10] = X[first:first + 10] + rng.normal(size=(10, D)) * 0.1 + 3.0
    return X, np.arange(n) * 0.1, X[first:first + 10]


# -- 1. trim ---------------------------------------------------------------------------------------------------

def test_trimming_keeps_a_dirty_days_anomaly_out_of_nominal_and_says_where_it_was():
    X, stamps, anomalous = dirty_day()
    untrimmed, info = learning.train(X, config=CONFIG, stamps=stamps, trim=0)
    assert info['trimmed'] == 0 and info['trimmed_spans'] == []
    assert np.sum(untrimmed.scores(anomalous) < untrimmed.threshold) == 0  # learnt as nominal
    assert learning.train(X, config=CONFIG, stamps=stamps)[1]['trimmed'] == 0  # train trims only when asked
    model, info = learning.train(X, config=CONFIG, stamps=stamps, trim=learning.DEFAULT_TRIM)
    assert info['trim'] == learning.DEFAULT_TRIM == 0.01 and info['trimmed'] == 10
    assert info['vectors_nominal'] == 1000 and info['vectors_train'] + info['vectors_held_out'] == 990
    [[start, end, count]] = info['trimmed_spans']
    assert (start, count) == (30.0, 10) and end == pytest.approx(30.9) and info['trimmed_by'] == 'stamp'
    assert np.all(model.scores(anomalous) < model.threshold)  # flagged now
    assert model.info['trimmed'] == 10
    text = learning.format_report(learning.evaluate(model, X[:100], anomalous), info)
    assert 'Trimmed          10 of 1000 nominal vectors, the most outlying (trim 1%): 1 span(s): 30.0-30.9 s (10)' \
        in text
    without_stamps = learning.train(X, config=CONFIG, trim=0.01)[1]
    assert without_stamps['trimmed_by'] == 'index' and without_stamps['trimmed_spans'] == [[300, 309, 10]]


def test_trim_refuses_bad_shares_and_mismatched_stamps():
    X, stamps, _ = dirty_day(200)
    for bad in (-0.1, 0.5, True, 'x'):
        with pytest.raises(ValueError, match='^trim: '):
            learning.train(X, config=CONFIG, trim=bad)
    with pytest.raises(ValueError, match='^stamps: 3 stamps for 200'):
        learning.train(X, config=CONFIG, stamps=stamps[:3])
    assert 'none (trim 0' in learning.trim_text(learning.train(X, config=CONFIG, trim=0)[1])


def test_cclog_learn_reports_what_it_trimmed(tmp_path):
    X, stamps, _ = dirty_day(400)
    for stamp, vector in zip(stamps, X):
        learning.write_vector(str(tmp_path / 'train'), 'nominal', 1000.0 + stamp, vector, CONFIG)
    out = ok('learn', '--train', tmp_path / 'train', '--model', tmp_path / 'model.json', '--trim', '0.025')
    [line] = [line for line in out.splitlines() if line.startswith('Trimmed')]
    assert line == 'Trimmed          10 of 400 nominal vectors, the most outlying (trim 2.5%): 1 span(s): ' \
        '1012.0-1012.9 s (10)', line
    out = ok('learn', '--train', tmp_path / 'train', '--model', tmp_path / 'default.json')
    assert 'Trimmed          4 of 400 nominal vectors' in out
    out = ok('learn', '--train', tmp_path / 'train', '--model', tmp_path / 'all.json', '--trim', '0')
    assert 'Trimmed          none (trim 0' in out
    assert json.loads((tmp_path / 'all.json').read_text())['info']['trimmed'] == 0


# -- 2. rule-flagged spans are not nominal ----------------------------------------------------------------------

RULES = """
driving_topic: /odom
windows: {pre: 2s, post: 2s}
triggers:
  - name: motion
    kind: classifier
    model: %s
    feature_set: motion
    window: 1s
    topics: [/odom]
  - name: events
    kind: rule
    topic: /sim/anomaly
    arrival: true
    pre: 1s
    post: 2s
"""


def test_cclog_collect_with_rules_keeps_no_vector_of_a_span_a_rule_fired_on(tmp_path):
    bag = str(tmp_path / 'day.bag')
    sim.simulate_to_bag(bag, sim.SimConfig(rate=20.0, seed=3, minutes=1.5, anomalies=2,
                                           anomaly_types='collision,sudden_acceleration'))
    truth = sim.load_truth(sim.truth_path(bag))
    plain = tmp_path / 'plain.yaml'
    plain.write_text(RULES.split('  - name: events')[0] % (tmp_path / 'none.json'))
    rules = tmp_path / 'rules.yaml'
    rules.write_text(RULES % (tmp_path / 'none.json'))
    every = ok_json('collect', bag, '--config', plain, '--out', tmp_path / 'every', '--stride', '2')
    assert every['flagged'] is None
    kept = ok_json('collect', bag, '--config', rules, '--out', tmp_path / 'kept', '--stride', '2')
    flagged = kept['flagged']
    # the rule fires at each event's start message (and at an end message past its 5 s hold-off): 1 s before, 2 after
    assert flagged['rules'] == ['events'] and len(flagged['spans']) >= 2
    for event in truth:
        assert [event['start'] - 1.0, event['start'] + 2.0, ['events']] in flagged['spans']
    stamps = sorted(float(name[:-5]) for name in os.listdir(str(tmp_path / 'kept' / 'motion' / 'nominal')))
    assert flagged['removed']['motion'] == every['sets']['motion']['vectors'] - len(stamps) > 0
    for start, end, _ in flagged['spans']:  # no kept window [stamp - 1 s, stamp] touches a span
        assert not any(stamp >= start and stamp - 1.0 <= end for stamp in stamps)
    text = ok('collect', bag, '--config', rules, '--out', tmp_path / 'text', '--stride', '2')
    assert '%d vector(s) not kept as nominal: their window overlaps %d span(s) where rules (events) fired: ' % (
        flagged['removed']['motion'], len(flagged['spans'])) in text


# -- 3. coverage -----------------------------------------------------------------------------------------------

def odometry(speed, seconds, rate=20.0, start=0.0, radius=5.0):
    """Records of a robot circling at ``speed`` (m/s): nav_msgs/Odometry-shaped messages on /odom."""
    w = speed / radius
    out = []
    for i in range(int(seconds * rate)):
        t = i / rate
        yaw = w * t
        msg = NS(header=NS(stamp=NS(to_sec=lambda s=start + t: s, secs=0, nsecs=0)),
                 pose=NS(pose=NS(position=NS(x=radius * math.sin(yaw), y=radius * (1 - math.cos(yaw)), z=0.0),
                                 orientation=NS(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))),
                 twist=NS(twist=NS(linear=NS(x=speed, y=0.0, z=0.0), angular=NS(x=0.0, y=0.0, z=w))))
        out.append(Record(start + t, '/odom', msg))
    return out


def circling_model(speeds=(0.3, 0.6), seconds=60.0):
    config = FeatureConfig('motion', '1s')
    vectors = []
    for k, speed in enumerate(speeds):
        stream = FeatureStream(config, every='100ms')
        vectors += [v for v in (stream.add(r.msg, r.stamp) for r in odometry(speed, seconds, start=1000.0 * k))
                    if v is not None]
    return learning.train(np.array(vectors), config=config)[0]


def test_the_model_file_records_its_coverage_and_old_files_still_load(tmp_path):
    model = circling_model()
    [v, w] = model.coverage['quantities']
    assert (v['name'], v['unit'], w['name'], w['unit']) == ('|v|', 'm/s', '|w|', 'rad/s')
    assert v['max'] == pytest.approx(0.6, abs=0.01) and w['max'] == pytest.approx(0.12, abs=0.01)
    assert model.coverage['stopped_share'] == 0.0
    path = str(tmp_path / 'model.json')
    model.save(path)
    assert AnomalyModel.load(path).coverage == model.coverage
    document = json.loads(open(path).read())
    del document['coverage']  # a model file of an earlier version
    old = AnomalyModel.from_dict(document)
    assert old.coverage is None and 'coverage' not in old.to_dict()
    monitor = drift.DriftMonitor(drift.trained_rate(old), coverage=old.coverage, config=old.config)
    monitor.observe(0.0, False, np.zeros(old.dimension))
    assert 'coverage' not in monitor.report() and monitor.as_dict()['coverage'] is None
    document['coverage'] = {'quantities': [{'name': '|v|', 'unit': 'm/s', 'min': 1.0, 'max': 0.5}]}
    with pytest.raises(ModelError, match='coverage.quantities\\[0\\]: max is below min'):
        AnomalyModel.from_dict(document, 'm.json')
    document['coverage'] = {'quantities': []}
    with pytest.raises(ModelError, match='^m.json: coverage: "quantities" must be a non-empty list'):
        AnomalyModel.from_dict(document, 'm.json')


def feed(trigger, records):
    for record in records:
        trigger.on_record(record)


def test_the_drift_line_warns_when_driving_leaves_the_speeds_the_model_was_trained_on():
    model = circling_model()
    slow = ClassifierTrigger('motion', model, '/odom', classify_every='100ms')
    [monitor] = drift.monitor_classifiers([slow])
    feed(slow, odometry(0.5, 90.0))
    assert monitor.status()[0] == drift.OK
    assert monitor.report().endswith('; coverage: within the training range (|v| <= 0.6 m/s, |w| <= 0.12 rad/s)')
    fast = ClassifierTrigger('motion', model, '/odom', classify_every='100ms')
    [monitor] = drift.monitor_classifiers([fast])
    feed(fast, odometry(1.3, 90.0))
    level, line = monitor.status()
    assert level == drift.WARN and 'training covers |v| <= 0.6 m/s, |w| <= 0.12 rad/s; this run reaches 1.3 m/s, ' \
        '0.26 rad/s' in line and '(100% of the last 89 s beyond)' in line and 'remedies: ' in line
    report = monitor.report()
    assert 'coverage: training covers |v| <= 0.6 m/s, |w| <= 0.12 rad/s; this run reaches 1.3 m/s, 0.26 rad/s ' \
        '(100% of decisions beyond)' in report
    state = monitor.as_dict()['coverage']
    assert state['beyond'] == state['decisions'] > 0 and state['quantities'][0]['reached_max'] == pytest.approx(1.3)


def test_stopping_more_than_in_training_and_per_feature_coverage():
    model = circling_model()
    monitor = drift.DriftMonitor(0.002, coverage=model.coverage, config=model.config)
    stopped = np.zeros(model.dimension)
    for i in range(1200):  # 2 min at 10 decisions per second, standing still
        monitor.observe(i / 10.0, False, stopped)
    level, line = monitor.status()
    assert level == drift.WARN and 'training was stopped 0.0% of the time, this run 100%' in line
    assert 'training was stopped 0.0% of the time, this run 100%' in monitor.report()
    imu = FeatureConfig('imu', '1s')
    rng = np.random.RandomState(1)
    X = rng.normal(size=(300, vector_length(imu)))
    imu_model = learning.train(X, config=imu)[0]
    assert len(imu_model.coverage['quantities']) == vector_length(imu) and 'stopped_share' not in imu_model.coverage
    monitor = drift.DriftMonitor(0.002, coverage=imu_model.coverage, config=imu)
    shifted = X[:50].copy()
    shifted[:, 3] += 20.0  # mean(acc_norm) far past anything trained
    for i, vector in enumerate(shifted):
        monitor.observe(float(i), False, vector)
    assert 'coverage: training covers mean(acc_norm) in [' in monitor.report()
    assert '(1 of 40 features beyond) (100% of decisions beyond)' in monitor.report()


# -- 4. an honest tune -----------------------------------------------------------------------------------------

@pytest.fixture(scope='module')
def dirty_tuning_run():
    """(model: motion 1 s on 1 min of the simulated BWIBot, a 1 min "nominal" run holding a collision)."""
    def records(seed):
        simulator = sim.Simulator(sim.SimConfig(rate=20.0, seed=seed, minutes=1.0, anomalies=0))
        return [Record(stamp, topic, msg) for topic, stamp, msg in simulator.messages() if topic == sim.ODOM_TOPIC]
    config = FeatureConfig('motion', '1s')
    stream = FeatureStream(config, every='100ms')
    vectors = [v for v in (stream.add(r.msg, r.stamp) for r in records(31)) if v is not None]
    model = learning.train(np.array(vectors), config=config)[0]
    run, _ = sim.inject_anomalies(records(32), ['collision'], seed=5, topic=sim.ODOM_TOPIC, warmup=40.0, gap=2.0)
    return model, run


def test_tune_names_the_events_its_budget_loses_and_keep_recall_keeps_them(dirty_tuning_run):
    model, run = dirty_tuning_run
    budget = copy.deepcopy(model)
    record = tuning.tune(budget, [run], sim.ODOM_TOPIC, 0.0)
    assert record['injected'] == 6 and record['caught_before'] and not record['keep_recall']
    # a budget of 0 on a run holding a collision: the threshold goes below the scores of the injected events too
    assert record['false_windows'] == 0 and record['lost']
    assert set(record['lost']) == set(record['caught_before']) - set(record['catches'])
    assert record['keep_recall_false_windows'] >= 1 and record['keep_recall_threshold'] > record['threshold']
    curve = record['curve']
    assert [p['threshold'] for p in curve] == sorted((p['threshold'] for p in curve), reverse=True)
    assert len(curve) >= 3 and {record['threshold_before'], record['threshold'],
                                record['keep_recall_threshold']} <= {p['threshold'] for p in curve}
    lines = tune_lines(record)
    assert lines[-1].startswith('chosen: threshold ') and ': %d event(s) lost at this threshold (' % len(
        record['lost']) in lines[-1] and 'the best threshold keeping every event' in lines[-1]
    assert '/h (--keep-recall)' in lines[-1]
    kept = copy.deepcopy(model)
    record = tuning.tune(kept, [run], sim.ODOM_TOPIC, 0.0, keep_recall=True)
    assert record['lost'] == [] and set(record['caught_before']) <= set(record['catches'])
    assert record['threshold'] == record['keep_recall_threshold'] == kept.threshold
    assert record['false_windows'] == record['keep_recall_false_windows'] >= 1
    assert 'every event kept, above the budget of 0/h' in tune_tail(record)


def tune_tail(record):
    return tune_lines(record)[-1]


def test_a_model_tuned_lower_is_judged_for_drift_at_the_threshold_training_set():
    """``cclog tune`` lowers a threshold to open fewer windows; the driving is no different, so drift is judged
    where training set it: 1.3 m/s against a 0.3-0.6 m/s training is drift for the tuned model too."""
    model = circling_model()
    fast = odometry(1.3, 90.0)
    stream = FeatureStream(model.config, every='100ms')
    scores = model.scores(np.array([v for v in (stream.add(r.msg, r.stamp) for r in fast) if v is not None]))
    tuned = AnomalyModel.from_dict(model.to_dict())
    tuned.threshold = float(scores.min()) - 1.0          # flags none of it
    assert tuned.info['threshold'] == model.threshold > tuned.threshold
    assert drift.judged_margin(tuned) == pytest.approx(model.threshold - tuned.threshold)
    assert drift.judged_margin(model) == 0.0
    trigger = ClassifierTrigger('motion', tuned, '/odom', classify_every='100ms')
    [monitor] = drift.monitor_classifiers([trigger])
    as_decided = drift.DriftMonitor(drift.trained_rate(tuned))
    trigger.observers.append(as_decided.observe)
    feed(trigger, fast)
    assert trigger.anomalous == 0 and not as_decided.drifting   # its own decisions: nothing flagged
    assert monitor.drifting and monitor.first_drift is not None
    assert monitor.status()[0] == drift.WARN and 'flagged 100%' in monitor.status()[1]
