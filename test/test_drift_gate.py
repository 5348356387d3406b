"""The envelope trigger once its drift monitor has stated drift for a whole span (``triggers.drift_gate``,
``on_drift``): synthetic odometry through the real trigger (pure numpy, no roscore), and ``cclog replay`` of a bag
written by rosbag."""
import json

import numpy as np
import pytest

from test_drift import rough_drive
from test_envelope import ODOM, envelope_windows, fires_of, learned, nominal_drive, odom_records

from cc_log.learning import drift
from cc_log.learning.envelope import Joint
from cc_log.triggers import drift_gate
from cc_log.triggers.envelope import EnvelopeTrigger

RATE = 25.0
SPAN = drift.DEFAULT_SPAN
SETTLE = SPAN / 2


def gated_envelope(rough):
    """The envelope of smooth driving with a joint check under which the shaken driving ``rough`` stays inside (its
    squared robust distance below the farthest training window's, 1.5x its own largest) while a pose jump of
    metres goes far beyond: a robot whose per-feature maxima are too tight for its new place, and the robust
    distance is not. No local part (the gate alone decides)."""
    envelope = learned(nominal_drive(seconds=240.0, seed=0, rate=RATE))
    trained = envelope.trained()
    train = envelope_windows(*nominal_drive(seconds=240.0, seed=0, rate=RATE))[1]
    mean = train.mean(axis=0)
    joint = Joint(mean, trained, np.zeros(len(trained)), np.eye(len(trained)), 0.0, 1.0)
    typical = float(np.median(joint.distances(train)))
    farthest = 1.5 * float(joint.distances(envelope_windows(*rough)[1]).max())
    return envelope._replace(joint=joint._replace(typical=typical, farthest=farthest), local=None)


def jumped(samples, at, metres=5.0):
    """``samples`` with the pose jumping ``metres`` ahead from ``at`` s into the run (the wheels saw nothing)."""
    t, x, y, yaw, v, w = (np.array(a, dtype=float) for a in samples)
    x[t >= t[0] + at] += metres
    return t, x, y, yaw, v, w


def run(envelope, samples, on_drift):
    trigger = EnvelopeTrigger('envelope', envelope, ODOM, on_drift=on_drift)
    [monitor] = drift.monitor_envelopes([trigger])
    return trigger, monitor, fires_of(trigger, odom_records(samples))


@pytest.fixture(scope='module')
def rough():
    return rough_drive(300.0, seed=2, rate=RATE)


def test_envelope_flags_the_robust_distance_does_not_confirm_stop_opening_once_drift_lasts_a_span(rough):
    """Shaken driving beyond 2x the smooth training's maxima (jerk, variations), inside the robust distance: the
    envelope flags every window. Without the gate (``none``) it fires to the end; with ``confirm`` it fires the
    same until drift has been stated (1 min settled) for a whole span (2 min), 3 min in, then never: the same
    monitor, fed the windows as without the gate, says drift all along and what the detector now does."""
    envelope = gated_envelope(rough)
    t0 = rough[0][0]
    _, plain, before = run(envelope, rough, 'none')
    trigger, monitor, after = run(envelope, rough, 'confirm')
    assert trigger.drift is monitor and trigger.observers == []   # the trigger's own monitor is the one reported
    assert plain.first_drift == monitor.first_drift == pytest.approx(t0 + 1.0 + SETTLE, abs=0.3)
    assert monitor.first_sustained == pytest.approx(monitor.first_stated + SPAN, abs=0.3)
    assert before[-1][0] > t0 + 295.0 and len(before) > 4 * 290       # every window beyond: a Fire every 0.25 s
    gated_from = monitor.first_sustained
    assert [(s, f) for s, f in before if s < gated_from] == after      # the same Fires up to it, none after
    assert after[-1][0] == pytest.approx(gated_from, abs=0.3)
    assert trigger.stats()['envelope_unconfirmed'] == len([s for s, _ in before if s >= gated_from])
    assert monitor.peak == 1.0 and monitor.sustained   # the drift is still stated: the gate hides nothing from it
    level, message = monitor.status()
    assert level == drift.WARN and message.endswith('; ' + drift_gate.ACTION), message
    assert monitor.report().endswith('; from 3 min into the run, ' + drift_gate.ACTION)
    assert 'on_drift' not in plain.report() and plain.first_sustained is not None


def test_a_true_event_far_outside_still_fires_under_drift_saying_it_was_confirmed(rough):
    """A pose jump of 5 m 4 min into the shaken run (the gate holding since 3 min): its windows go far past the
    robust distance of every training window, so it fires, its why naming what stood out (the robust distance,
    the pose gap) and last the confirmation under drift."""
    envelope = gated_envelope(rough)
    samples = jumped(rough, 240.0)
    trigger, monitor, fires = run(envelope, samples, 'confirm')
    t0 = samples[0][0]
    late = [(stamp, fire) for stamp, fire in fires if stamp > monitor.first_sustained + 1.0]
    assert late, 'the jump was not flagged under drift'
    assert all(t0 + 240.0 <= stamp <= t0 + 241.5 for stamp, _ in late)   # the windows holding the jump only
    stamp, fire = min(late, key=lambda item: item[1].score)
    assert {'max_pose_gap', 'sum_pose_gap', 'joint'} & {entry['feature'] for entry in fire.why[:-1]}, fire.why
    confirmed = fire.why[-1]
    assert confirmed['feature'] == 'drift_confirmed' and confirmed['ratio'] > 1.0 and len(fire.why) <= 3
    assert confirmed['limit'] == pytest.approx(envelope.joint.farthest)
    assert confirmed['text'] == ('under drift (on_drift: confirm): confirmed by the robust distance, %.1fx past '
                                 'every training window' % confirmed['ratio'])


def test_a_run_without_drift_decides_exactly_as_before():
    """Smooth driving like training with a 5 m pose jump: no drift is ever stated, and ``confirm`` fires exactly
    what ``none`` (the trigger before the gate) fires, with the same scores and why, on the learned envelope with
    its joint check and local part."""
    envelope = learned(nominal_drive(seconds=240.0, seed=0, rate=RATE))
    assert envelope.joint is not None and envelope.local is not None
    samples = jumped(nominal_drive(seconds=300.0, seed=1, rate=RATE), 200.0)
    _, _, before = run(envelope, samples, 'none')
    trigger, monitor, after = run(envelope, samples, 'confirm')
    assert monitor.first_stated is None and monitor.first_sustained is None and monitor.peak < 0.05
    assert before and [(s, f.score, f.why) for s, f in after] == [(s, f.score, f.why) for s, f in before]
    assert trigger.stats()['envelope_unconfirmed'] == 0
    assert 'on_drift' not in monitor.report()


def test_on_drift_is_checked_and_changes_nothing_without_a_joint_check():
    envelope = learned(nominal_drive(seconds=120.0, seed=0, rate=RATE))
    with pytest.raises(ValueError, match=r'^envelope: on_drift: .maybe. is not one of confirm, none$'):
        EnvelopeTrigger('envelope', envelope, ODOM, on_drift='maybe')
    assert EnvelopeTrigger('envelope', envelope, ODOM).drift is not None                  # confirm, the default
    assert EnvelopeTrigger('envelope', envelope, ODOM, on_drift='none').drift is None
    assert EnvelopeTrigger('envelope', envelope, ODOM, joint_factor=0).drift is None       # nothing to confirm with
    assert EnvelopeTrigger('envelope', envelope._replace(joint=None), ODOM).drift is None
    assert EnvelopeTrigger('envelope', envelope, ODOM).describe()['on_drift'] == 'confirm'


# -- cclog replay ------------------------------------------------------------------------------------------------

def test_the_gated_monitors_coverage_sees_a_batchs_windows_at_once_and_counts_as_one_at_a_time(rough):
    """The monitor the gate follows takes each batch's rows at once (``EnvelopeCoverage.observe_rows``: counted,
    no call per window; before, ``observe`` of each window): the same windows beyond, per feature and in all, and
    the same peaks as the monitor a trigger without the gate feeds one window at a time."""
    envelope = gated_envelope(rough)
    calls = {'observe': 0, 'observe_rows': 0}
    trigger = EnvelopeTrigger('envelope', envelope, ODOM, on_drift='confirm')
    coverage = trigger.drift.coverage
    for name in calls:
        def counted(*args, name=name, method=getattr(coverage, name)):
            calls[name] += 1
            return method(*args)
        setattr(coverage, name, counted)
    records = odom_records(rough)
    fires_of(trigger, records, batch=256)
    _, one_at_a_time, _ = run(envelope, rough, 'none')
    single = one_at_a_time.coverage
    assert calls['observe'] == 0 and 0 < calls['observe_rows'] <= -(-len(records) // 256), calls
    assert coverage.decisions == single.decisions == trigger.evaluated > 1000
    assert coverage.beyond.tolist() == single.beyond.tolist() and coverage.beyond_any == single.beyond_any > 0
    assert coverage.peak == pytest.approx(single.peak, rel=1e-12)


@pytest.fixture(scope='module')
def rough_bag(tmp_path_factory, rough):
    """A bag of real nav_msgs/Odometry written by rosbag (the shaken run, 5 min) and the gated envelope's file."""
    import rosbag
    import rospy
    from test_envelope import odometry_messages
    tmp = tmp_path_factory.mktemp('drift_gate')
    paths = {'bag': str(tmp / 'rough.bag'), 'limits': str(tmp / 'envelope.json')}
    with rosbag.Bag(paths['bag'], 'w') as bag:
        for record in odometry_messages(rough):
            bag.write(ODOM, record.msg, rospy.Time.from_sec(record.stamp))
    gated_envelope(rough).save(paths['limits'])
    return paths


def test_cclog_replay_keeps_the_shaken_driving_only_until_drift_lasts_and_says_so(tmp_path, rough_bag):
    """``cclog replay --model envelope.json``: by default (``confirm``) the windows end once drift has lasted a
    span, and the summary's drift line says what the detector does from then on (``--json``: first_sustained,
    action); ``--on-drift none`` keeps the shaken driving to the end, as before."""
    from conftest import cclog
    summaries = {}
    for mode in ('confirm', 'none'):
        args = ['replay', rough_bag['bag'], '--model', rough_bag['limits'], '--out', tmp_path / mode, '--json']
        result = cclog(*(args + ([] if mode == 'confirm' else ['--on-drift', 'none'])))
        assert result.returncode == 0, result.stderr
        summaries[mode] = json.loads(result.stdout)
    [state] = summaries['confirm']['drift']
    assert state['drift'] and state['action'] == drift_gate.ACTION
    assert state['first_sustained'] == pytest.approx(state['first_stated'] + SPAN, abs=0.3)
    [plain] = summaries['none']['drift']
    assert plain['action'] is None and plain['first_sustained'] == state['first_sustained']
    last = max(w['end'] for w in summaries['confirm']['windows'])
    assert last < state['first_sustained'] + 10.0          # the last window closes after its post margin
    assert max(w['end'] for w in summaries['none']['windows']) > state['first_sustained'] + 100.0
    result = cclog('replay', rough_bag['bag'], '--model', rough_bag['limits'], '--out', tmp_path / 'text')
    assert result.returncode == 0, result.stderr
    [line] = [line for line in result.stdout.splitlines() if line.startswith('  drift')]
    assert line.endswith('; from 3 min into the run, ' + drift_gate.ACTION), line
