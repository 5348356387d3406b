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


def test_drift_is_sustained_once_stated_without_a_break_for_a_whole_span_and_the_action_said_then():
    """``stated_for`` counts from the decision drift was first stated and starts again after a break;
    ``sustained`` holds from a whole span on; the ``action`` (what the detector does then) ends ``status()`` only
    while it holds and ``report()`` from the first time it held; ``as_dict()`` carries both times."""
    monitor = DriftMonitor(0.002, name='envelope', action='the detector now does this')
    decisions(monitor, 1000.0, 150.0, 0.5)       # stated from 1060 s (judged after 60 s)
    assert monitor.first_stated == pytest.approx(1060.0, abs=0.1)
    assert monitor.stated_for == pytest.approx(90.0, abs=0.1) and not monitor.sustained
    assert not monitor.status()[1].endswith('the detector now does this')
    assert 'the detector now does this' not in monitor.report()
    decisions(monitor, 1150.0, 40.0, 0.5)
    assert monitor.sustained and monitor.first_sustained == pytest.approx(1180.0, abs=0.1)
    level, message = monitor.status()
    assert level == WARN and message.endswith('; the detector now does this')
    decisions(monitor, 1190.0, 200.0, 0.0)       # the share falls under 20 %: no longer stated, the count restarts
    assert not monitor.stated and monitor.stated_for == 0.0 and not monitor.sustained
    assert monitor.status()[0] == OK and 'the detector' not in monitor.status()[1]
    assert monitor.report().endswith('; from 3 min into the run, the detector now does this')
    state = monitor.as_dict()
    assert state['first_sustained'] == monitor.first_sustained and state['action'] == 'the detector now does this'
    plain = DriftMonitor(0.002)
    decisions(plain, 1000.0, 300.0, 0.5)
    assert plain.sustained and plain.as_dict()['action'] is None and 'into the run, ' not in plain.report()


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


# -- the physics envelope: its windows against its trained rate and its training maxima -----------------------

JERK = 29.6  # m/s^3, the training maximum of the synthetic envelope below (its floor is 5)


def synthetic_envelope():
    """An envelope whose training reached JERK in jerk and every other feature's floor."""
    from cc_log.features.envelope import ENVELOPE_COLUMNS, ENVELOPE_FLOORS
    from cc_log.learning.envelope import Envelope
    maxima = dict((name, ENVELOPE_FLOORS[name]) for name in ENVELOPE_COLUMNS)
    maxima['max_jerk'] = JERK
    return Envelope(maxima, '/odom', 1.0, 0.25, 2000, 500.0, None)


def envelope_windows(monitor, envelope, start, seconds, jerk_ratios):
    """Feed ``seconds`` of envelope windows (one every 0.25 s, as the trigger) from ``start``: every feature at
    half its training maximum but jerk, at ``jerk_ratios[i % len]`` x its maximum; each decided as the trigger
    decides (``learning.envelope.scores`` < 0, the limits at 2x)."""
    from cc_log.features.envelope import ENVELOPE_COLUMNS
    from cc_log.learning.envelope import scores
    jerk = ENVELOPE_COLUMNS.index('max_jerk')
    for i in range(int(seconds * 4)):
        row = 0.5 * envelope.trained()
        row[jerk] = jerk_ratios[i % len(jerk_ratios)] * JERK
        monitor.observe(start + 0.25 * i, bool(scores(row[None], envelope.limits())[0] < 0), row)


def envelope_monitor(envelope):
    class Trigger(object):   # what monitor_envelopes reads of a triggers.envelope.EnvelopeTrigger
        kind, name, observers = 'envelope', 'envelope', []
    trigger = Trigger()
    trigger.envelope = envelope
    [monitor] = drift.monitor_envelopes([trigger, DriftMonitor])   # the other object: not of kind envelope
    assert trigger.observers == [monitor.observe]
    return monitor


def test_an_envelope_run_like_its_training_reports_no_drift_and_a_rougher_one_drift_naming_the_feature():
    """The envelope flags no training window: its monitor takes the floor, 0.2 %, so 20 % of 2 min flagged is
    drift. A run like training (up to its maxima): none, within the training maxima. A rougher run, jerk past the
    training maximum in half of its windows and past 2x in a quarter: drift, its coverage naming jerk."""
    envelope = synthetic_envelope()
    like = envelope_monitor(envelope)
    assert like.trained_rate == drift.TRAINED_RATE_FLOOR == 0.002 and like.limit == 0.2
    envelope_windows(like, envelope, 1000.0, 240.0, [0.5, 0.9, 1.0, 1.1, 0.7])
    assert like.status() == (OK, 'drift: none: envelope flagged 0.0% of the last 2 min (trained: 0.2%)')
    assert like.report() == ('drift: none: envelope flagged at most 0.0% of any 2 min (trained: 0.2%); coverage: '
                             'within the training maxima (no window 10% past one)')
    rough = envelope_monitor(envelope)
    envelope_windows(rough, envelope, 1000.0, 240.0, [3.1, 1.5, 0.8, 0.5])
    level, message = rough.status()
    assert level == WARN and message == (
        'drift: envelope flagged 25% of the last 2 min (trained: 0.2%): this robot drives unlike its training data '
        '(training reaches jerk 29.6 m/s^3; this run goes up to 3.1x (50% of the last 2 min beyond)); remedies: '
        + drift.ENVELOPE_REMEDIES)
    assert rough.first_drift == pytest.approx(1060.0, abs=0.3)   # judged from 60 s of windows
    assert rough.report() == (
        'drift: from 1 min into the run envelope flagged up to 25%% of 2 min (trained: 0.2%%): this robot drives '
        'unlike its training data; remedies: %s; coverage: training reaches jerk 29.6 m/s^3; this run exceeds it in '
        '50%% of windows (up to 3.1x)' % drift.ENVELOPE_REMEDIES)
    state = rough.as_dict()
    assert state['drift'] and state['name'] == 'envelope' and state['coverage']['decisions'] == 960
    [jerk] = [feature for feature in state['coverage']['features'] if feature['beyond']]
    assert (jerk['name'], jerk['unit'], jerk['max'], jerk['beyond']) == ('max_jerk', 'm/s^3', JERK, 480)
    assert jerk['peak_ratio'] == pytest.approx(3.1, rel=1e-12)


def test_an_envelope_run_past_its_training_maxima_but_not_yet_flagged_warns_on_its_coverage():
    """Jerk at 1.5x its training maximum in half of the windows: the trigger flags none (its limit is 2x), the
    monitor warns that the driving leaves the training data, and the run's report says by how much."""
    envelope = synthetic_envelope()
    monitor = envelope_monitor(envelope)
    envelope_windows(monitor, envelope, 0.0, 180.0, [1.5, 0.6])
    assert monitor.share == 0.0 and monitor.first_drift is None
    assert monitor.status() == (WARN, (
        'drift: envelope flagged 0.0% of the last 2 min (trained: 0.2%), but the driving leaves the training data: '
        'training reaches jerk 29.6 m/s^3; this run goes up to 1.5x (50% of the last 2 min beyond); remedies: '
        + drift.ENVELOPE_REMEDIES))
    assert monitor.report() == ('drift: none: envelope flagged at most 0.0% of any 2 min (trained: 0.2%); '
                                'coverage: training reaches jerk 29.6 m/s^3; this run exceeds it in 50% of windows '
                                '(up to 1.5x)')


def rough_drive(seconds, seed, rate=25.0):
    """``test_envelope.nominal_drive`` with a 1.5 Hz shake of 0.1 m/s and 0.2 rad/s on top: jerk, acceleration and
    the variation of speed and yaw rate in a window well beyond 2x the smooth driving's."""
    from test_envelope import drive
    rng = np.random.default_rng(seed)
    phase = np.arange(int(seconds * rate)) / rate
    shake = np.sin(2 * np.pi * 1.5 * phase)
    v = 0.6 + 0.4 * np.sin(phase / 7.0 + seed) + 0.1 * shake + rng.normal(0, 0.005, len(phase))
    w = 0.5 * np.sin(phase / 5.0 + 2 * seed) + 0.2 * shake + rng.normal(0, 0.005, len(phase))
    return drive(v, w, rate=rate)


def test_the_envelope_trigger_tells_its_monitor_every_window_it_evaluates():
    """``monitor_envelopes`` on a real EnvelopeTrigger: each window evaluated (one every 0.25 s) is observed;
    smooth driving like training is no drift, the shaken one is, from the first judged minute."""
    from test_envelope import ODOM, fires_of, learned, nominal_drive, odom_records
    from cc_log.triggers.envelope import EnvelopeTrigger
    envelope = learned(nominal_drive(seconds=240.0, seed=0, rate=25.0))
    for samples, drifting in ((nominal_drive(seconds=180.0, seed=1, rate=25.0), False),
                              (rough_drive(180.0, seed=2), True)):
        trigger = EnvelopeTrigger('envelope', envelope, ODOM)
        [monitor] = drift.monitor_envelopes([trigger])
        fires_of(trigger, odom_records(samples))
        assert monitor.coverage.decisions == trigger.evaluated > 600
        assert (monitor.first_drift is not None) == drifting, monitor.report()
        if drifting:
            assert monitor.first_drift - samples[0][0] == pytest.approx(61.0, abs=0.5)   # 1 s window + 60 s settle
            assert monitor.peak == 1.0 and 'coverage: training reaches ' in monitor.report()


@pytest.fixture(scope='module')
def envelope_bags(tmp_path_factory):
    """Bags of real nav_msgs/Odometry written by rosbag: smooth driving (4 min) and the envelope cclog
    learn-envelope learns from it, and the same robot shaken (3 min): ``{'train', 'rough', 'limits'}``."""
    import rosbag
    import rospy
    from test_envelope import ODOM, nominal_drive, odometry_messages
    from conftest import cclog as run
    tmp = tmp_path_factory.mktemp('envelope_drift')
    paths = {}
    for name, samples in (('train', nominal_drive(seconds=240.0, seed=0, rate=25.0)),
                          ('rough', rough_drive(180.0, seed=2))):
        paths[name] = str(tmp / (name + '.bag'))
        with rosbag.Bag(paths[name], 'w') as bag:
            for record in odometry_messages(samples):
                bag.write(ODOM, record.msg, rospy.Time.from_sec(record.stamp))
    paths['limits'] = str(tmp / 'envelope.json')
    learned = run('learn-envelope', paths['train'], '--out', paths['limits'])
    assert learned.returncode == 0, learned.stderr
    return paths


def test_cclog_replay_model_envelope_of_rougher_driving_states_drift(tmp_path, envelope_bags):
    """``cclog replay --model envelope.json`` of the shaken robot: the summary says the envelope's drift (from
    about 1 min in, the re-learning remedy, the features past their training maxima); ``--json`` carries it. Of
    the smooth driving it was learned on: none, within the training maxima."""
    from conftest import cclog as run
    result = run('replay', envelope_bags['train'], '--model', envelope_bags['limits'], '--out', tmp_path / 'train')
    assert result.returncode == 0, result.stderr
    assert [line for line in result.stdout.splitlines() if line.startswith('  drift')] == [
        '  drift: none: envelope flagged at most 0.0% of any 2 min (trained: 0.2%); coverage: within the training '
        'maxima (no window 10% past one)']
    result = run('replay', envelope_bags['rough'], '--model', envelope_bags['limits'], '--out', tmp_path / 'text')
    assert result.returncode == 0, result.stderr
    [line] = [line for line in result.stdout.splitlines() if line.startswith('  drift')]
    assert line.startswith('  drift: from 1 min into the run envelope flagged up to 100% of 2 min (trained: 0.2%): '
                           'this robot drives unlike its training data; remedies: re-learn the envelope'), line
    assert '; coverage: training reaches ' in line and 'this run exceeds them in 100%, 100%, 100% of windows' in line
    result = run('replay', envelope_bags['rough'], '--model', envelope_bags['limits'], '--out', tmp_path / 'json',
                 '--json')
    assert result.returncode == 0, result.stderr
    [state] = json.loads(result.stdout)['drift']
    assert state['name'] == 'envelope' and state['drift'] and state['trained_rate'] == 0.002
    assert state['peak'] == 1.0 and state['coverage']['beyond'] == state['coverage']['decisions'] > 600
