"""``tuning.choose`` and ``cclog tune --windows --classify-every``: the feature window and classify rate chosen
on small simulated bags (no roscore)."""
import copy
import json
import os

import numpy as np
import pytest

from cc_log.storage.bag import bagio
from cc_log.learning import learning
from cc_log import sim
from cc_log.offline import tuning
from cc_log.features import FeatureConfig, FeatureStream
from cc_log.learning.model import AnomalyModel
from cc_log.base.records import LogWindow, Trigger
from cc_log.storage import log_format

from test_cli import fails, ok_json, run

pytest.importorskip('rosbag')
RATE = 20.0


@pytest.fixture(scope='module')
def simulated(tmp_path_factory):
    """(model path: motion 2s trained on one nominal run, a nominal bag of another run, its records)."""
    base = tmp_path_factory.mktemp('tuning')
    train_bag, bag = str(base / 'train.bag'), str(base / 'nominal.bag')
    sim.simulate_to_bag(train_bag, sim.SimConfig(rate=RATE, seed=31, minutes=5, anomalies=0))
    sim.simulate_to_bag(bag, sim.SimConfig(rate=RATE, seed=32, minutes=3, anomalies=0))
    config = FeatureConfig('motion', '2s')
    stream = FeatureStream(config, every='100ms')
    vectors = [v for v in (stream.add(r.msg, r.stamp) for r in bagio.read_messages(train_bag, [sim.ODOM_TOPIC]))
               if v is not None]
    model, _ = learning.train(np.array(vectors), config=config)
    path = str(base / 'model.json')
    model.save(path)
    return path, bag, list(bagio.read_messages(bag, [sim.ODOM_TOPIC]))


def test_choose_tries_every_window_and_rate_and_keeps_the_fastest_within_the_budget(simulated):
    path, _, records = simulated
    model = AnomalyModel.load(path)
    chosen, record = tuning.choose(model, [records], sim.ODOM_TOPIC, 20.0, windows=['1s', '2s'],
                                   rates=['100ms', '200ms'])
    grid = record['grid']
    assert [(g['window'], g['classify_every']) for g in grid] == [('1s', '0.1s'), ('1s', '0.2s'),
                                                                  ('2s', '0.1s'), ('2s', '0.2s')]
    assert [g['trained'] for g in grid] == [True, True, False, False]
    # a threshold below every nominal score gives no window, so every setting can be tuned into the budget
    assert all(g['meets_budget'] and g['false_per_hour'] <= 20.0 for g in grid)
    # the chosen setting meets the budget and no setting within it catches more types, or as many sooner
    assert record['false_per_hour'] <= 20.0 and chosen.config.window == record['window']
    within = [g for g in grid if g['meets_budget']]
    most = max(len(g['catches']) for g in within)
    assert len(record['catches']) == most and record['catches']
    assert record['mean_latency'] == min(g['mean_latency'] for g in within if len(g['catches']) == most)
    assert set(record['latencies']) == set(record['catches']) and all(0 <= d for d in record['latencies'].values())
    assert chosen.info['tuned'] == record and chosen.threshold == record['threshold']
    assert model.threshold == AnomalyModel.load(path).threshold  # the given model is not changed


def test_cclog_tune_chooses_the_window_and_rate_and_refuses_bad_ones(simulated, tmp_path):
    path, bag, _ = simulated
    out = tmp_path / 'tuned.json'
    result = ok_json('tune', '--model', path, '--bag', bag, '--topic', sim.ODOM_TOPIC, '--max-false-per-hour', '20',
                     '--windows', '1s,2s', '--classify-every', '100ms,200ms', '--out', out)
    saved = json.loads(out.read_text())
    assert saved['config']['window'] == result['window'] and len(result['grid']) == 4
    assert saved['info']['tuned']['classify_every'] == result['classify_every'] in ('0.1s', '0.2s')
    line = fails('tune', '--model', path, '--bag', bag, '--topic', sim.ODOM_TOPIC, '--max-false-per-hour', '1',
                 '--windows', '1s,fast', '--out', tmp_path / 'x.json', status=2)
    assert 'windows' in line and 'fast' in line
    line = fails('tune', '--model', path, '--bag', bag, '--topic', sim.ODOM_TOPIC, '--max-false-per-hour', '1',
                 '--windows', '100000s', '--out', tmp_path / 'x.json')
    assert line == "cclog tune: error: window: '100000s' is outside 0.01..3600 s" and not (tmp_path / 'x.json').exists()


def _twist_set(record, value):
    """``record`` with a copy of its message whose twist.twist.linear.x is ``value``."""
    msg = copy.deepcopy(record.msg)
    msg.twist.twist.linear.x = value
    return record._replace(msg=msg)


def test_tune_leaves_out_non_finite_and_huge_samples_and_takes_its_threshold_from_the_rest(simulated):
    """A NaN twist in 1% of the messages, or one 1e308 sample, is left out and counted (as feature rows reject
    it): the threshold and the catches are those of the run without these messages; none usable: one line
    naming the bag and the field."""
    path, bag, records = simulated
    model = AnomalyModel.load(path)
    spoiled = set(range(50, len(records), 100)) | {len(records) // 2}
    without = [r for i, r in enumerate(records) if i not in spoiled]
    expected = tuning.tune(AnomalyModel.load(path), [without], sim.ODOM_TOPIC, 5.0, sources=[bag])
    assert expected['rejected'] == [0]
    run = [_twist_set(r, 1e308 if i == len(records) // 2 else float('nan')) if i in spoiled else r
           for i, r in enumerate(records)]
    record = tuning.tune(model, [run], sim.ODOM_TOPIC, 5.0, sources=[bag])
    assert record['rejected'] == [len(spoiled)]
    assert record['threshold'] == pytest.approx(expected['threshold'], rel=1e-9, abs=1e-12)
    assert record['catches'] == expected['catches'] and record['misses'] == expected['misses']
    json.dumps(record, allow_nan=False)
    assert tuning.rejected_lines(record) == [
        'warning: %s: %d /odom message(s) left out of tuning: a non-finite or huge value (beyond 1e+06)'
        % (bag, len(spoiled))]
    with pytest.raises(ValueError) as error:
        tuning.tune(model, [[_twist_set(r, float('inf')) for r in records]], sim.ODOM_TOPIC, 5.0, sources=[bag])
    assert str(error.value) == ('%s: no usable /odom messages to tune on: %d of them have a non-finite or huge '
                                'value (beyond 1e+06; e.g. twist.twist.linear.x)' % (bag, len(records)))


def _string_then_odometry(bag, out, strings=40):
    """A copy of ``bag`` whose /odom carries ``strings`` std_msgs/String first, then its Odometry."""
    import rosbag
    import rospy
    from std_msgs.msg import String
    other = '/odo_'  # as long as /odom: renamed in the bytes (rosbag writes one connection per topic)
    with rosbag.Bag(bag) as source, rosbag.Bag(out, 'w') as target:
        start = source.get_start_time()
        for i in range(strings):
            target.write(other, String(data='not odometry %d' % i), rospy.Time.from_sec(start - 1 + i * 0.01))
        for topic, msg, t in source.read_messages():
            target.write(topic, msg, t)
    with open(out, 'rb') as stream:
        data = stream.read()
    assert data.count(other.encode()) >= 1
    with open(out, 'wb') as stream:
        stream.write(data.replace(other.encode(), sim.ODOM_TOPIC.encode()))
    return out


def test_tune_and_plot_read_a_topic_of_two_types_as_the_type_they_need(simulated, tmp_path):
    """/odom carrying String then Odometry: tune tunes on the Odometry, plot --bag draws it; each says in one
    line how many String messages it skipped."""
    path, bag, records = simulated
    mixed = _string_then_odometry(bag, str(tmp_path / 'mixed.bag'))
    result = run('tune', '--model', path, '--bag', mixed, '--topic', sim.ODOM_TOPIC, '--max-false-per-hour', '20',
                 '--out', tmp_path / 'tuned.json', '--json')
    assert result.returncode == 0, result.stderr[-2000:]
    skipped = 'warning: %s: read as /odom nav_msgs/Odometry; skipped 40 std_msgs/String on /odom' % mixed
    assert skipped in result.stderr.splitlines()
    assert json.loads(result.stdout)['hours'] == pytest.approx((records[-1].stamp - records[0].stamp) / 3600.0)
    windows = tmp_path / 'windows'
    windows.mkdir()
    log_format.write_window(LogWindow(records[100:140], [Trigger(records[120].stamp, 'test', None)]), str(windows),
                            'json-xz', {'driving_topic': sim.ODOM_TOPIC})
    result = run('plot', windows, '--bag', mixed, '--topic', sim.ODOM_TOPIC, '--out', tmp_path / 'plot.png')
    assert result.returncode == 0 and 'Traceback' not in result.stderr, result.stderr[-2000:]
    assert skipped in result.stderr.splitlines() and os.path.getsize(str(tmp_path / 'plot.png')) > 0
