"""``tuning.choose`` and ``cclog tune --windows --classify-every``: the feature window and classify rate chosen
on small simulated bags (no roscore)."""
import json

import numpy as np
import pytest

from cc_log.storage.bag import bagio
from cc_log.core import learning
from cc_log import sim
from cc_log.offline import tuning
from cc_log.features import FeatureConfig, FeatureStream
from cc_log.core.model import AnomalyModel

from test_cli import fails, ok_json

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
    assert line.startswith('cclog tune: error: windows: 100000s: nominal: ') and not (tmp_path / 'x.json').exists()
