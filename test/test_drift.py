"""Drift, stated: DriftMonitor on its own, and in `cclog replay`'s summary on a real car a simulator-trained
model does not fit (F1/10) against a nominal simulated run of the training distribution."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from cc_log.learning import drift, learning
from cc_log import sim
from cc_log.learning.drift import OK, WARN, DriftMonitor
from cc_log.features import FeatureConfig, FeatureStream

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
F1TENTH = 'f1tenth_DS2.bag'  # 158 s of a real F1/10 car racing, /odom at about 30 Hz


def cclog(*args):
    return subprocess.run([sys.executable, os.path.join(ROOT, 'scripts', 'cclog')] + [str(a) for a in args],
                          capture_output=True, text=True, timeout=600)


def decisions(monitor, start, seconds, share, rate=20.0):
    """Feed ``seconds`` of decisions at ``rate`` from ``start``, every ``round(1 / share)``-th anomalous."""
    every = int(round(1.0 / share)) if share else 0
    for i in range(int(seconds * rate)):
        monitor.observe(start + i / rate, bool(every) and i % every == 0)


# -- DriftMonitor ----------------------------------------------------------------------------------------------

def test_the_trained_rate_is_the_models_flagged_held_out_share_never_below_the_calibration():
    class Model(object):
        info = {'held_out_flagged': 12, 'vectors_held_out': 400}
    assert drift.trained_rate(Model()) == 0.03
    Model.info = {'held_out_flagged': 0, 'vectors_held_out': 400}
    assert drift.trained_rate(Model()) == learning.DEFAULT_QUANTILE == 0.002
    Model.info = {}
    assert drift.trained_rate(Model()) == 0.002


def test_drift_is_stated_once_the_span_is_judged_and_the_share_stays_far_above_the_trained_rate():
    monitor = DriftMonitor(0.002, name='motion')
    assert monitor.limit == 0.2  # 10 x 0.2 % is below the floor of 20 %
    decisions(monitor, 1000.0, 50.0, 0.5)
    level, message = monitor.status()
    assert (level, message) == (OK, 'drift: not judged yet (50 s of the 1 min of decisions needed)')
    decisions(monitor, 1050.0, 70.0, 0.5)
    level, message = monitor.status()
    assert level == WARN and message.startswith(
        'drift: motion flagged 50% of the last 2 min (trained: 0.2%): this robot drives unlike its training data; '
        'remedies: learn_online: true') and 'kind: periodic' in message and 'cclog learn' in message
    assert monitor.first_drift == pytest.approx(1060.0, abs=0.1)  # judged from 60 s of decisions
    # back to the trained distribution: the share of the last 2 min falls, drift ends
    decisions(monitor, 1120.0, 120.0, 0.0)
    assert monitor.status() == (OK, 'drift: none: motion flagged 0.0% of the last 2 min (trained: 0.2%)')
    assert monitor.report().startswith('drift: from 1 min into the run motion flagged up to 50% of 2 min')


def test_a_few_true_anomalies_are_not_drift_and_time_going_back_starts_again():
    monitor = DriftMonitor(0.002)
    decisions(monitor, 0.0, 300.0, 0.0)
    decisions(monitor, 300.0, 9.0, 1.0)  # a 9 s anomaly flagged whole: 7.5 % of 2 min
    decisions(monitor, 309.0, 100.0, 0.0)
    assert monitor.status()[0] == OK and monitor.first_drift is None
    assert monitor.report() == 'drift: none: classifier flagged at most 7.5% of any 2 min (trained: 0.2%)'
    decisions(monitor, 10.0, 30.0, 1.0)  # another run, earlier stamps: not judged with the old decisions
    assert monitor.status() == (OK, 'drift: not judged yet (30 s of the 1 min of decisions needed)')
    short = DriftMonitor(0.002)
    decisions(short, 10.0, 30.0, 1.0)
    assert short.report() == ('drift: not judged: 30 s of classifier\'s decisions, 1 min needed '
                              '(it flagged 100% of them)')
    assert DriftMonitor(0.002).report() == 'drift: not judged: 0 s of classifier\'s decisions, 1 min needed'


def test_many_short_episodes_are_drift_even_when_the_share_is_small():
    """A new place flags a second here and there: 4 separate episodes within 2 min (3 % of the decisions) are
    drift; the same flags a second apart (one episode of an event) are not, nor are 3 episodes."""
    def episodes(monitor, start, count, apart):
        for k in range(count):
            decisions(monitor, start + k * apart, apart - 1.0, 0.0)
            decisions(monitor, start + (k + 1) * apart - 1.0, 1.0, 1.0)  # one flagged second

    new_place = DriftMonitor(0.002, name='motion')
    decisions(new_place, 0.0, 200.0, 0.0)
    episodes(new_place, 200.0, 3, drift.EPISODE_GAP + 5.0)
    assert new_place.status()[0] == OK and new_place.first_drift is None  # three are not drift
    episodes(new_place, 200.0 + 3 * (drift.EPISODE_GAP + 5.0), 1, drift.EPISODE_GAP + 5.0)
    level, message = new_place.status()
    assert new_place.share < new_place.limit and level == WARN and new_place.flag_episodes == 4
    assert message.startswith('drift: motion flagged 3.3% of the last 2 min (trained: 0.2%) in 4 separate episodes: '
                              'this robot drives unlike its training data')
    assert new_place.first_drift == pytest.approx(200.0 + 4 * (drift.EPISODE_GAP + 5.0) - 1.0, abs=0.1)
    assert 'in up to 4 separate episodes' in new_place.report()
    assert new_place.as_dict()['peak_episodes'] == 4
    one_event = DriftMonitor(0.002)
    decisions(one_event, 0.0, 200.0, 0.0)
    episodes(one_event, 200.0, 8, drift.EPISODE_GAP - 1.0)  # flags closer than the gap: one episode
    assert one_event.status()[0] == OK and one_event.flag_episodes == 1 and one_event.first_drift is None


@pytest.mark.parametrize('kwargs, message', [
    ({'trained_rate': 0.0}, 'trained_rate: 0.0 must be a number > 0 and <= 1'),
    ({'trained_rate': 'x' * 100}, 'trained_rate: ' + repr('x' * 100)[:40] + ' must be a number > 0 and <= 1'),
    ({'trained_rate': 0.01, 'span': -1}, 'span: -1 must be a number > 0'),
    ({'trained_rate': 0.01, 'settle': 500}, 'settle: 500 must be between 0 and span (120 s)'),
    ({'trained_rate': 0.01, 'min_rate': 2}, 'min_rate: 2 must be a number > 0 and <= 1'),
    ({'trained_rate': 0.01, 'episodes': 1}, 'episodes: 1 must be a whole number >= 2')])
def test_bad_parameters_are_one_line_naming_them(kwargs, message):
    with pytest.raises(ValueError) as error:
        DriftMonitor(**kwargs)
    assert str(error.value) == message


# -- cclog replay: a car the model never saw, and the model's own distribution --------------------------------

@pytest.fixture(scope='module')
def sim_model(tmp_path_factory):
    """The demo's model: motion, 1 s window, 8 minutes of the simulated BWIBot (seed 7), a vector every 10."""
    config = FeatureConfig('motion', '1s')
    stream = FeatureStream(config, every='10')
    simulator = sim.Simulator(sim.SimConfig(minutes=8, anomalies=0, seed=7))
    vectors = [v for v in (stream.add(msg, stamp) for topic, stamp, msg in simulator.messages()
                           if topic == sim.ODOM_TOPIC) if v is not None]
    model, _ = learning.train(np.array(vectors), config=config)
    path = str(tmp_path_factory.mktemp('model') / 'sim.json')
    model.save(path)
    return path


def test_replay_of_a_real_car_states_drift_within_two_minutes(tmp_path, sim_model, real_bag):
    bag = real_bag(F1TENTH)
    result = cclog('replay', bag, '--topic', '/odom', '--model', sim_model, '--out', tmp_path / 'json', '--json')
    assert result.returncode == 0, result.stderr
    [state] = json.loads(result.stdout)['drift']
    from cc_log.storage.bag import bagio
    first = next(iter(bagio.read_messages(bag, ['/odom']))).stamp
    assert state['drift'] and state['first_drift'] - first <= 120.0
    assert state['peak'] > 0.5 and state['trained_rate'] == 0.002
    result = cclog('replay', bag, '--topic', '/odom', '--model', sim_model, '--out', tmp_path / 'text')
    [line] = [line for line in result.stdout.splitlines() if 'drift' in line]
    assert line.startswith('  drift: from ') and 'classifier flagged up to ' in line and 'remedies: ' in line


def test_replay_of_the_training_distribution_states_no_drift(tmp_path, sim_model):
    bag = str(tmp_path / 'nominal.bag')
    sim.simulate_to_bag(bag, sim.SimConfig(minutes=4, anomalies=0, seed=9))
    result = cclog('replay', bag, '--topic', sim.ODOM_TOPIC, '--model', sim_model, '--out', tmp_path / 'out')
    assert result.returncode == 0, result.stderr
    [line] = [line for line in result.stdout.splitlines() if 'drift' in line]
    assert line.startswith('  drift: none: classifier flagged at most ') and '(trained: 0.2%)' in line
