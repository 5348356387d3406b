"""The physics envelope's features on synthetic odometry (pure numpy, no roscore)."""
import re

import numpy as np
import pytest
from conftest import approx_floats

from cc_log.features.envelope import (
    ENVELOPE_COLUMNS, ENVELOPE_FLOORS, ENVELOPE_UNITS, HISTORY, envelope_rows, envelope_windows)

RATE = 50.0
COL = {name: i for i, name in enumerate(ENVELOPE_COLUMNS)}


def drive(v, w, t0=1000.0, rate=RATE, stamps=None):
    """Samples of a unicycle following speeds ``v`` and yaw rates ``w`` (arrays), integrated by the trapezoid rule."""
    v, w = np.asarray(v, float), np.asarray(w, float)
    t = t0 + np.arange(len(v)) / rate if stamps is None else np.asarray(stamps, float)
    dt = np.diff(t, prepend=t[0])
    mean_v = 0.5 * (v + np.concatenate((v[:1], v[:-1])))    # the trapezoid rule, as the features predict
    mean_w = 0.5 * (w + np.concatenate((w[:1], w[:-1])))
    yaw = np.cumsum(mean_w * dt)
    heading = yaw - 0.5 * mean_w * dt
    x = np.cumsum(mean_v * dt * np.cos(heading))
    y = np.cumsum(mean_v * dt * np.sin(heading))
    return t, x, y, yaw, v, w


def column_max(samples, name):
    ends, matrix = envelope_windows(*samples)
    assert len(ends) == matrix.shape[0] > 0
    return float(matrix[:, COL[name]].max())


def test_the_interface_names_19_non_negative_columns_with_units_and_floors():
    assert len(ENVELOPE_COLUMNS) == len(set(ENVELOPE_COLUMNS)) == 19
    assert set(ENVELOPE_UNITS) == set(ENVELOPE_FLOORS) == set(ENVELOPE_COLUMNS)
    assert all(ENVELOPE_FLOORS[name] > 0 for name in ENVELOPE_COLUMNS)
    rng = np.random.default_rng(1)
    samples = drive(rng.uniform(-1, 2, 500), rng.uniform(-1, 1, 500))
    ends, matrix = envelope_windows(*samples)
    assert matrix.shape == (len(ends), 19) and np.all(matrix >= 0) and np.all(np.isfinite(matrix))
    # windows end on the grid of multiples of the stride, the first one a full window after the first sample
    assert np.allclose(ends / 0.25, np.round(ends / 0.25)) and ends[0] >= samples[0][0] + 1.0
    assert np.allclose(np.diff(ends), 0.25) and ends[-1] <= samples[0][-1]


def test_a_constant_straight_run_has_near_zero_change_features():
    samples = drive(np.full(500, 1.5), np.zeros(500))
    ends, matrix = envelope_windows(*samples)
    assert matrix[:, COL['max_speed']] == pytest.approx(1.5)
    for name in ('max_yaw_rate', 'max_accel', 'max_yaw_accel', 'max_jerk', 'speed_variation', 'yaw_rate_variation',
                 'yaw_rate_flips', 'max_pose_gap', 'sum_pose_gap', 'max_heading_gap', 'sum_heading_gap',
                 'still_fraction', 'still_yaw_rate', 'max_span_accel', 'max_decel', 'max_speedup',
                 'max_speed_drop', 'max_speed_rise'):
        assert matrix[:, COL[name]].max() == pytest.approx(0.0, abs=1e-9), name


def test_a_step_in_speed_raises_the_acceleration_and_the_speed_drop():
    v = np.full(500, 2.0)
    v[250:] = 0.5           # a 1.5 m/s drop between two samples
    samples = drive(v, np.zeros(500))
    # the derivative spans the newest sample at least 0.05 s back: 3 steps of 0.02 s at 50 Hz
    assert column_max(samples, 'max_accel') == pytest.approx(1.5 / 0.06)
    assert column_max(samples, 'max_decel') == pytest.approx(1.5 / 0.06)
    assert column_max(samples, 'max_speedup') == pytest.approx(0.0)
    assert column_max(samples, 'max_speed_drop') == pytest.approx(1.5)
    assert column_max(samples, 'max_speed_rise') == pytest.approx(0.0)
    assert column_max(samples, 'speed_variation') == pytest.approx(1.5)
    assert column_max(samples, 'max_span_accel') == pytest.approx(1.5 / 0.2)
    assert column_max(samples, 'max_jerk') > 100.0
    assert column_max(samples, 'max_pose_gap') < 1e-9    # pose and twist still agree


def test_a_pose_jump_raises_the_pose_and_heading_gaps():
    t, x, y, yaw, v, w = drive(np.full(500, 1.0), np.zeros(500))
    x, yaw = x.copy(), yaw.copy()
    x[300:] += 1.2          # the pose jumps 1.2 m ahead while the wheels report 0.02 m
    yaw[300:] += 0.5
    ends, matrix = envelope_windows(t, x, y, yaw, v, w)
    assert matrix[:, COL['max_pose_gap']].max() == pytest.approx(np.hypot(0.02 * np.cos(0.25) - 1.22,
                                                                          0.02 * np.sin(0.25)), rel=0.05)
    assert matrix[:, COL['sum_pose_gap']].max() >= matrix[:, COL['max_pose_gap']].max()
    assert matrix[:, COL['max_heading_gap']].max() == pytest.approx(0.5)
    quiet = ends < t[300] - 1e-9
    assert matrix[quiet, COL['max_pose_gap']].max() < 1e-9
    assert matrix[quiet, COL['max_heading_gap']].max() < 1e-9


def test_a_spin_in_place_raises_the_yaw_rate_and_the_yaw_rate_while_standing():
    w = np.zeros(500)
    w[200:300] = 3.0
    samples = drive(np.zeros(500), w)
    assert column_max(samples, 'max_yaw_rate') == pytest.approx(3.0)
    assert column_max(samples, 'still_yaw_rate') == pytest.approx(3.0)
    assert column_max(samples, 'still_fraction') == pytest.approx(1.0)
    assert column_max(samples, 'max_yaw_accel') == pytest.approx(3.0 / 0.06)
    assert column_max(samples, 'max_heading_gap') < 1e-9


def test_yaw_rate_sign_flips_are_counted_outside_the_deadband():
    w = np.where(np.arange(500) // 10 % 2 == 0, 0.5, -0.5)    # a flip every 0.2 s
    w[::7] = 0.01          # near zero: no sign, no flip
    samples = drive(np.full(500, 1.0), w)
    assert column_max(samples, 'yaw_rate_flips') == pytest.approx(5.0, abs=1.0)


def test_irregular_stamps_and_a_dropped_sample_make_no_false_extremes():
    rng = np.random.default_rng(2)
    n = 1000
    regular = drive(1.0 + 0.5 * np.sin(np.arange(n) / 50.0), 0.3 * np.cos(np.arange(n) / 80.0))
    reference = envelope_windows(*regular)[1].max(axis=0)
    # jittered stamps (+-4 ms at 50 Hz), the values those of the motion at the stamps
    stamps = 1000.0 + np.arange(n) / RATE + rng.uniform(-0.004, 0.004, n)
    stamps[1::2] = 1000.0 + np.arange(1, n, 2) / RATE + 0.009     # two samples 1-10 ms apart
    phase = (stamps - 1000.0) * RATE
    jittered = drive(1.0 + 0.5 * np.sin(phase / 50.0), 0.3 * np.cos(phase / 80.0), stamps=stamps)
    dropped = tuple(np.delete(a, [400, 401, 402, 700]) for a in regular)
    for samples in (jittered, dropped):
        ends, matrix = envelope_windows(*samples)
        for name in ('max_accel', 'max_yaw_accel', 'max_decel', 'max_speedup', 'max_span_accel',
                     'max_speed_drop', 'max_speed_rise', 'max_jerk'):
            assert matrix[:, COL[name]].max() <= 1.5 * reference[COL[name]] + 0.05, name
        for name in ('max_pose_gap', 'max_heading_gap'):
            assert matrix[:, COL[name]].max() < 0.01, name


def test_bad_samples_are_dropped_and_mismatched_lengths_refused():
    t, x, y, yaw, v, w = drive(np.full(300, 1.0), np.zeros(300))
    v = v.copy()
    v[100] = np.nan
    t = t.copy()
    t[200] = t[150]        # time going backwards: dropped
    ends, matrix = envelope_windows(t, x, y, yaw, v, w)
    assert np.all(np.isfinite(matrix)) and matrix[:, COL['max_accel']].max() < 1e-9
    assert envelope_windows(t[:1], x[:1], y[:1], yaw[:1], v[:1], w[:1])[1].shape == (0, 19)
    with pytest.raises(ValueError, match='^envelope: stamps, x, y, yaw, v and w must have one length'):
        envelope_windows(t, x[:-1], y, yaw, v, w)
    with pytest.raises(ValueError, match='^envelope: window and stride must be positive'):
        envelope_windows(t, x, y, yaw, v, w, stride=0)


def test_a_window_from_the_recent_samples_only_equals_the_whole_runs_row():
    """What a live trigger computes from a ring of the last window + HISTORY seconds is the offline row."""
    rng = np.random.default_rng(3)
    fast = drive(rng.uniform(0, 2, 800), rng.uniform(-1, 1, 800))
    # 2-3 Hz: a derivative's reference is the sample before, a jerk's nearly a second before the window
    slow = drive(rng.uniform(0, 2, 80), rng.uniform(-1, 1, 80), stamps=1000.0 + np.cumsum(rng.uniform(0.3, 0.49, 80)))
    for samples in (fast, slow):
        ends, matrix = envelope_windows(*samples)
        for k in range(len(ends)):
            ring = samples[0] > ends[k] - 1.0 - HISTORY
            got_ends, row = envelope_rows(*(a[ring] for a in samples), ends=[ends[k]])
            assert got_ends[0] == ends[k] and np.allclose(row[0], matrix[k])


def test_a_long_run_is_fast():
    import time
    n = 25 * 60 * 66
    samples = drive(np.ones(n), np.zeros(n), rate=66.0)
    start = time.perf_counter()
    ends, _ = envelope_windows(*samples)
    assert len(ends) > 5900 and time.perf_counter() - start < 2.0


# -- the envelope model and trigger ---------------------------------------------------------------------------

ODOM = '/odom'


def nominal_drive(seconds=120.0, seed=0, rate=RATE):
    """Smooth driving from 0.2 to 1 m/s and up to 0.5 rad/s, with sensor noise."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate)
    phase = np.arange(n) / rate
    v = 0.6 + 0.4 * np.sin(phase / 7.0 + seed) + rng.normal(0, 0.005, n)
    w = 0.5 * np.sin(phase / 5.0 + 2 * seed) + rng.normal(0, 0.005, n)
    return drive(v, w, rate=rate)


def odom_records(samples, topic=ODOM):
    """Records of decoded nav_msgs/Odometry-shaped messages (SimpleNamespace) of planar samples."""
    from types import SimpleNamespace as NS
    from cc_log.base.records import Record
    records = []
    for t, x, y, yaw, v, w in zip(*samples):
        pose = NS(position=NS(x=x, y=y, z=0.0), orientation=NS(x=0.0, y=0.0, z=np.sin(yaw / 2), w=np.cos(yaw / 2)))
        twist = NS(linear=NS(x=v, y=0.0, z=0.0), angular=NS(x=0.0, y=0.0, z=w))
        records.append(Record(float(t), topic, NS(pose=NS(pose=pose), twist=NS(twist=twist))))
    return records


def learned(samples):
    from cc_log.learning import envelope
    return envelope.learn([envelope_windows(*samples)[1]], ODOM, 1.0, 0.25, samples[0][-1] - samples[0][0])


def fires_of(trigger, records, batch=64):
    fires = []
    for start in range(0, len(records), batch):
        for record, fired in zip(records[start:start + batch], trigger.on_records(records[start:start + batch])):
            fires.extend((record.stamp, fire) for fire in fired)
    return fires


def test_limits_are_the_training_maxima_floored_times_the_factor():
    from cc_log.learning.envelope import Envelope
    samples = nominal_drive()
    env = learned(samples)
    matrix = envelope_windows(*samples)[1]
    assert env.windows == len(matrix)
    for i, name in enumerate(ENVELOPE_COLUMNS):
        assert env.maxima[name] == pytest.approx(matrix[:, i].max())
        assert env.trained()[i] == pytest.approx(max(matrix[:, i].max(), ENVELOPE_FLOORS[name]))
    # never standing still, never spinning in place, pose and twist agreeing: the floors set those limits
    for name in ('still_yaw_rate', 'max_pose_gap', 'max_heading_gap'):
        assert env.maxima[name] < ENVELOPE_FLOORS[name]
        assert env.limits(3.0)[ENVELOPE_COLUMNS.index(name)] == pytest.approx(3.0 * ENVELOPE_FLOORS[name])
    assert Envelope.from_dict(env.to_dict()) == env


def test_a_surge_to_three_times_the_top_speed_fires_saying_why_and_nominal_driving_does_not():
    from cc_log.triggers.envelope import EnvelopeTrigger
    env = learned(nominal_drive(seed=0))
    top = env.maxima['max_speed']
    trigger = EnvelopeTrigger('envelope', env, ODOM)
    assert fires_of(trigger, odom_records(nominal_drive(seed=0))) == []     # the training itself
    trigger.reset()
    assert fires_of(trigger, odom_records(nominal_drive(seed=1))) == []     # other nominal driving
    # a slow surge (0.3 m/s^2, within the accelerations seen) from 0.5 m/s to 3x the top speed, held 2 s
    n = int(60 * RATE)
    v = np.full(n, 0.5)
    ramp = int((3 * top - 0.5) / 0.3 * RATE)
    v[1000:1000 + ramp] = 0.5 + 0.3 * np.arange(ramp) / RATE
    v[1000 + ramp:1000 + ramp + 100] = 3 * top
    v[1000 + ramp + 100:1000 + 2 * ramp + 100] = 3 * top - 0.3 * np.arange(ramp) / RATE
    samples = drive(v, np.zeros(n))
    trigger = EnvelopeTrigger('envelope', env, ODOM, joint_factor=0, local_factor=0)   # per feature (a ramp is new)
    fires = fires_of(trigger, odom_records(samples))
    assert fires, 'the surge was not flagged'
    t_over = samples[0][np.argmax(v > 2 * top)]      # the limit at factor 2
    assert fires[0][0] == pytest.approx(np.ceil(t_over / 0.25) * 0.25, abs=0.03)
    stamp, fire = min(fires, key=lambda item: item[1].score)
    assert fire.name == 'envelope' and fire.reason == 'envelope'
    assert fire.score == pytest.approx(-np.log(3 * top / (2 * top)), abs=1e-3)
    assert fire.why[0]['feature'] == 'max_speed' and len(fire.why) <= 3
    assert fire.why[0]['value'] == pytest.approx(3 * top, rel=1e-3)
    assert fire.why[0]['limit'] == pytest.approx(top) and fire.why[0]['ratio'] == pytest.approx(3.0, rel=1e-3)
    assert fire.why[0]['unit'] == 'm/s'
    assert fire.why[0]['text'] == 'speed %.3g m/s, 3.0x the most seen in training' % (3 * top)
    assert all(entry['ratio'] > 2 for entry in fire.why)     # beyond factor x the most seen
    stats = trigger.stats()
    assert stats['fired'] == len(fires) and stats['envelope_beyond'] >= len(fires)
    assert stats['envelope_windows'] == len(envelope_windows(*samples)[0])


def test_the_trigger_fires_alike_whatever_the_batches():
    from cc_log.triggers.envelope import EnvelopeTrigger
    env = learned(nominal_drive(seed=0))
    samples = nominal_drive(seconds=40, seed=3)
    x = samples[1].copy()
    x[1200:] += 0.8                              # a localization jump
    records = odom_records((samples[0], x) + samples[2:])
    runs = []
    for batch in (1, 7, 256):
        trigger = EnvelopeTrigger('envelope', env, ODOM)
        runs.append(fires_of(trigger, records, batch))
    decisions = [[(stamp, [entry['feature'] for entry in fire.why]) for stamp, fire in run] for run in runs]
    assert decisions[0] == decisions[1] == decisions[2] and len(decisions[0]) >= 1
    for run in runs[1:]:     # sums over a ring that starts elsewhere differ in the last bits only
        assert [fire.score for _, fire in run] == pytest.approx([fire.score for _, fire in runs[0]], abs=1e-9)
        assert [entry['value'] for _, fire in run for entry in fire.why] == \
            pytest.approx([entry['value'] for _, fire in runs[0] for entry in fire.why], abs=1e-9)
    why = runs[0][0][1].why
    assert why[0]['feature'] in ('max_pose_gap', 'sum_pose_gap')
    pose = next(entry for entry in why if entry['feature'] == 'max_pose_gap')
    assert re.match(r'^pose moved 0\.[78]\d m in a step while the wheels reported 0\.0\d m, 1\d\.\dx the floor '
                    r'0\.05 m \(training never reached it\)$', pose['text']), pose['text']


def odometry_messages(samples, topic=ODOM):
    """Records of real nav_msgs/Odometry messages of planar samples (what a logger writes)."""
    from nav_msgs.msg import Odometry
    from cc_log.base.records import Record
    records = []
    for t, x, y, yaw, v, w in zip(*samples):
        msg = Odometry()
        msg.header.stamp.secs, msg.header.stamp.nsecs = int(t), int(round((t % 1) * 1e9)) % 1000000000
        msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
        msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = np.sin(yaw / 2), np.cos(yaw / 2)
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = v, w
        records.append(Record(float(t), topic, msg))
    return records


@pytest.mark.parametrize('value', [1e200, float('inf'), float('nan'), -1e7])
def test_five_seconds_of_speed_out_of_any_physical_range_fire_and_the_logger_keeps_their_span(tmp_path, value):
    from cc_log.logger.smart import SmartLogger
    from cc_log.storage import log_format
    from cc_log.triggers.envelope import OUT_OF_RANGE_SCORE, EnvelopeTrigger
    env = learned(nominal_drive(seed=0))
    t, x, y, yaw, v, w = nominal_drive(seconds=30, seed=1)
    bad = (t >= t[0] + 10.0) & (t < t[0] + 15.0)
    v = np.where(bad, value, v)
    trigger = EnvelopeTrigger('envelope', env, ODOM)
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '0.5s', '0.5s', driving_topic=ODOM, triggers=[trigger])
    for record in odometry_messages((t, x, y, yaw, v, w)):
        logger.on_message(record.topic, record.msg, record.stamp)
    assert logger.close(30)
    (metadata, records), = [log_format.read_window(path) for path in log_format.window_files(str(tmp_path))]
    kept = [r.stamp for r in records if t[0] + 10.0 <= r.stamp < t[0] + 15.0]
    assert len(kept) == bad.sum()  # every message of the 5 s, in one window
    assert metadata['start'] <= t[0] + 10.0 and metadata['end'] >= t[0] + 15.0
    assert min(entry['score'] for entry in metadata['triggers']) == OUT_OF_RANGE_SCORE
    assert metadata['triggers'][0]['why'][0]['feature'] == 'out_of_range'


def test_time_going_back_starts_the_ring_over():
    from cc_log.triggers.envelope import EnvelopeTrigger
    env = learned(nominal_drive(seed=0))
    records = odom_records(nominal_drive(seconds=20, seed=1))
    trigger = EnvelopeTrigger('envelope', env, ODOM)
    assert fires_of(trigger, records + records, batch=100) == []     # a bag played twice: no false extreme
    once = len(envelope_windows(*nominal_drive(seconds=20, seed=1))[0])
    assert trigger.stats()['envelope_windows'] == 2 * once


def test_a_stamp_repeated_for_ever_does_not_grow_the_ring():
    from cc_log.triggers.envelope import EnvelopeTrigger
    env = learned(nominal_drive(seed=0))
    trigger = EnvelopeTrigger('envelope', env, ODOM)
    records = odom_records(nominal_drive(seconds=5, seed=1))
    stuck = [records[-1]] * 5000
    assert fires_of(trigger, records + stuck, batch=100) == []
    assert trigger.stats()['envelope_ring'] <= (1.0 + HISTORY + 0.25) * RATE + 1   # window, history, a stride


def test_a_configuration_entry_of_kind_envelope(tmp_path):
    from cc_log.logger.config import Config
    from cc_log.base.raw_message import installed_class
    from cc_log.learning.model import AnomalyModel
    env = learned(nominal_drive(seconds=30))
    path = str(tmp_path / 'envelope.json')
    env.save(path)
    cfg = Config.from_dict({'triggers': [{'name': 'env', 'kind': 'envelope', 'limits': path, 'factor': 3}]})
    trigger, = cfg.build_triggers(AnomalyModel.load, installed_class, resolve=lambda t: '/robot1' + t)
    assert (trigger.kind, trigger.topic, trigger.factor) == ('envelope', '/robot1/odom', 3.0)
    assert trigger.topic_types() == {'/robot1/odom': 'nav_msgs/Odometry'}
    assert trigger.describe()['limits']['max_speed'] == pytest.approx(3.0 * env.trained()[0])
    for entry, said in (({'name': 'env', 'kind': 'envelope'}, 'limits: required'),
                        ({'name': 'env', 'kind': 'envelope', 'limits': str(tmp_path / 'none.json')},
                         'none.json: cannot be read'),
                        ({'name': 'env', 'kind': 'envelope', 'limits': path, 'factor': 'x'}, "factor: 'x' must be"),
                        ({'name': 'env', 'kind': 'envelope', 'limits': path, 'facter': 2}, 'facter')):
        with pytest.raises(ValueError) as error:
            Config.from_dict({'triggers': [entry]}).build_triggers(AnomalyModel.load, installed_class)
        assert said in str(error.value) and str(error.value).startswith('config: triggers[0] (env): ') and \
            '\n' not in str(error.value), str(error.value)


def test_envelope_files_are_read_with_bounds(tmp_path):
    import json
    from cc_log.learning.envelope import Envelope
    env = learned(nominal_drive(seconds=30))
    path = str(tmp_path / 'envelope.json')
    env.save(path)
    assert Envelope.load(path) == env
    document = env.to_dict()
    cases = [(dict(document, extra=1), 'unknown key'),
             (dict(document, maxima=dict(document['maxima'], max_speed=-1.0)), 'maxima: max_speed: -1.0 must be'),
             (dict(document, maxima={k: v for k, v in document['maxima'].items() if k != 'max_jerk'}),
              'missing max_jerk'),
             (dict(document, window=0), 'window: 0 must be a finite positive number'),
             (dict(document, kind='model'), 'not an envelope file')]
    for bad, said in cases:
        with open(path, 'w') as stream:
            json.dump(bad, stream)
        with pytest.raises(ValueError) as error:
            Envelope.load(path)
        assert str(error.value).startswith(path + ': ') and said in str(error.value) and '\n' not in str(error.value)
    with open(path, 'w') as stream:
        stream.write(json.dumps(document).replace('"max_speed": %r' % document['maxima']['max_speed'],
                                                  '"max_speed": NaN'))
    with pytest.raises(ValueError, match='NaN is not a number JSON allows'):
        Envelope.load(path)
    with open(path, 'w') as stream:  # issue 42 item 15: an integer no float holds (an OverflowError traceback)
        json.dump(dict(document, maxima=dict(document['maxima'], max_speed=int('9' * 401))), stream)
    with pytest.raises(ValueError) as error:
        Envelope.load(path)
    assert str(error.value) == '%s: not JSON (an integer of 401 digits is out of range)' % path
    from cc_log.triggers.envelope import EnvelopeTrigger
    with pytest.raises(ValueError, match='^envelope: factor: 0.5 must be a number from 1 up'):
        EnvelopeTrigger('envelope', env, ODOM, factor=0.5)


# -- the joint check ----------------------------------------------------------------------------------------------

def paired_windows(n=600, seed=0):
    """Synthetic training windows (n, 19): every feature spreads on its own but for speed and yaw rate, which
    always move together (yaw rate = speed / 2, give or take 0.01)."""
    rng = np.random.default_rng(seed)
    matrix = rng.uniform(0.5, 1.5, (n, len(ENVELOPE_COLUMNS))) * rng.uniform(0.1, 10.0, len(ENVELOPE_COLUMNS))
    matrix[:, COL['max_speed']] = rng.uniform(0.2, 1.0, n)
    matrix[:, COL['max_yaw_rate']] = 0.5 * matrix[:, COL['max_speed']] + rng.normal(0.0, 0.01, n)
    return matrix


def apart(matrix):
    """A window of typical values whose speed is near the most seen while its yaw rate is near the least."""
    row = np.median(matrix, axis=0)
    row[COL['max_speed']], row[COL['max_yaw_rate']] = 0.95, 0.12
    return row


def test_the_joint_check_flags_a_combination_never_seen_although_each_feature_is_inside_its_limit():
    from cc_log.learning import envelope
    matrix = paired_windows()
    env = envelope.learn([matrix], ODOM, 1.0, 0.25, 150.0)
    assert env.joint is not None and 0 < env.joint.typical < env.joint.farthest
    row = apart(matrix)
    assert np.all(row <= matrix.max(axis=0))                       # inside the training's own range, each
    limits = env.limits()
    assert envelope.scores(row[None], limits, None)[0] > 0         # per feature: nothing to flag
    assert envelope.scores(row[None], limits, env.joint)[0] < 0    # jointly: flagged
    assert env.joint.ratios(row[None])[0] > 1
    assert np.all(envelope.scores(matrix, limits, env.joint) >= 0)  # no training window is
    assert np.max(env.joint.ratios(matrix)) == approx_floats(1.0 / envelope.DEFAULT_JOINT_FACTOR)
    assert envelope.scores(row[None], limits, env.joint, joint_factor=0)[0] > 0   # 0: off
    rows = np.vstack([matrix, row, 3.0 * matrix[:50]])    # the OR: whatever the limits flag, it flags too
    assert np.all(envelope.scores(rows, limits, env.joint) <= envelope.scores(rows, limits))
    assert envelope.learn([matrix], ODOM, 1.0, 0.25, 150.0, joint=False).joint is None
    few = envelope.learn([matrix[:49]], ODOM, 1.0, 0.25, 12.0)
    assert few.joint is None and envelope.joint_shortfall(49) == '49 training windows, fewer than 50'
    assert envelope.joint_shortfall(50) == ''


def test_the_joint_ratio_is_the_detector_benchmarks_robust_mahalanobis_at_its_level():
    """The bench's ``mahalanobis``: sklearn's StandardScaler, MinCovDet(random_state=0) on the scaled training
    windows, its squared ``mahalanobis`` distance, the threshold ``zero - level x (zero - extreme)`` with zero /
    extreme the median / lowest training score (-d2)."""
    from sklearn.covariance import MinCovDet
    from sklearn.preprocessing import StandardScaler
    from cc_log.learning import envelope
    matrix = paired_windows(seed=1)
    joint = envelope.learn([matrix], ODOM, 1.0, 0.25, 150.0).joint
    scaler = StandardScaler().fit(matrix)
    assert joint.mean == approx_floats(scaler.mean_) and joint.scale == approx_floats(scaler.scale_)
    standardised = (matrix - joint.mean) / joint.scale
    robust = MinCovDet(random_state=0).fit(standardised)
    assert joint.location == approx_floats(robust.location_)
    assert joint.precision.ravel() == approx_floats(robust.precision_.ravel())
    train = -robust.mahalanobis(standardised)
    assert joint.distances(matrix) == approx_floats(-train)
    assert (joint.typical, joint.farthest) == approx_floats((-np.median(train), -train.min()))
    rng = np.random.default_rng(2)   # typical windows pushed out along random directions, near and far
    typical = np.median(matrix, axis=0)
    rows = typical + np.outer(np.geomspace(0.01, 3.0, 60), np.ones(len(ENVELOPE_COLUMNS))) * \
        rng.normal(0.0, 1.0, (60, len(ENVELOPE_COLUMNS))) * matrix.std(axis=0)
    rows = np.vstack([rows, apart(matrix)])
    scores = -robust.mahalanobis((rows - joint.mean) / joint.scale)
    zero, extreme = np.median(train), train.min()
    for level in (1.0, 2.0, 4.0):
        flagged = scores < zero - level * (zero - extreme)
        assert 0 < flagged.sum() < len(rows)
        assert list(joint.ratios(rows, level) > 1) == list(flagged)
    assert joint.ratios(rows) == approx_floats((-scores - joint.typical) / (4.0 * (joint.farthest - joint.typical)))


def test_a_joint_fire_says_why_naming_the_three_features_that_stand_out_together():
    from cc_log.learning import envelope
    from cc_log.base.why import MAX_TEXT
    matrix = paired_windows()
    env = envelope.learn([matrix], ODOM, 1.0, 0.25, 150.0)
    row = apart(matrix)
    why, = envelope.explain(row, env)
    d2 = float(env.joint.distances(row[None])[0])
    assert (why['feature'], why['unit']) == ('joint', '1')
    assert why['value'] == approx_floats(d2) and why['limit'] == env.joint.farthest
    assert why['ratio'] == approx_floats((d2 - env.joint.typical) / (env.joint.farthest - env.joint.typical))
    match = re.match(r'^(.+), (.+) and (.+) together (\d+\.\d)x farther from typical driving than any training '
                     r'window$', why['text'])
    assert match, why['text']
    named = set(match.groups()[:3])
    assert len(named) == 3 and {'speed', 'yaw rate'} <= named
    assert float(match.group(4)) == pytest.approx(why['ratio'], abs=0.05)
    assert envelope.explain(row, env, joint_factor=0) == ()              # off: nothing beyond
    assert envelope.explain(np.median(matrix, axis=0), env) == ()        # typical: nothing
    # beside a feature beyond its own limit: both said, the one further past its factor first
    both = row.copy()
    both[COL['max_jerk']] = 3.0 * env.trained()[COL['max_jerk']]
    said = envelope.explain(both, env, local_factor=0)
    assert [entry['feature'] for entry in said] == ['joint', 'max_jerk'] or \
        [entry['feature'] for entry in said] == ['max_jerk', 'joint']
    past = [entry['ratio'] / (envelope.DEFAULT_JOINT_FACTOR if entry['feature'] == 'joint' else 2.0)
            for entry in said]
    assert past == sorted(past, reverse=True)
    # the longest names and a large ratio: a shorter sentence, within a why's text length, the three still named
    size = len(ENVELOPE_COLUMNS)
    unit = envelope.Joint(np.zeros(size), np.ones(size), np.zeros(size), np.eye(size), 1.0, 2.0)
    row = np.zeros(size)
    row[[COL['yaw_rate_variation'], COL['max_span_accel'], COL['yaw_rate_flips']]] = [300.0, 200.0, 100.0]
    said = envelope.joint_why(row, unit)
    assert said['text'] == 'yaw rate variation, 0.2 s acceleration and yaw rate sign flips together 139999.0x past ' \
        'any training window'
    assert len(said['text']) <= MAX_TEXT and said['ratio'] == 139999.0


def test_the_trigger_scores_with_the_joint_check_alike_whatever_the_batches():
    from cc_log.learning import envelope
    from cc_log.triggers.envelope import EnvelopeTrigger
    env = learned(nominal_drive(seed=0))
    assert env.joint is not None
    samples = nominal_drive(seconds=40, seed=3)
    v = samples[4].copy()
    v[1000:1100] = 0.05      # crawling while turning as usual: each feature inside, together new
    records = odom_records(drive(v, samples[5]))
    runs = [fires_of(EnvelopeTrigger('envelope', env, ODOM), records, batch) for batch in (1, 64, 512)]
    decisions = [[(stamp, tuple(entry['feature'] for entry in fire.why)) for stamp, fire in run] for run in runs]
    assert decisions[0] == decisions[1] == decisions[2]
    assert any('joint' in features for _, features in decisions[0]), decisions[0]
    for run in runs[1:]:
        assert [fire.score for _, fire in run] == pytest.approx([fire.score for _, fire in runs[0]], abs=1e-9)
    off = fires_of(EnvelopeTrigger('envelope', env, ODOM, joint_factor=0), records)
    assert all('joint' not in [entry['feature'] for entry in fire.why] for _, fire in off)
    trigger = EnvelopeTrigger('envelope', env, ODOM, joint_factor=8)
    assert trigger.describe()['joint_factor'] == 8.0
    assert trigger.describe()['joint'] == {'typical': env.joint.typical, 'farthest': env.joint.farthest}
    for bad in (0.5, -1, 'x', True, float('nan')):
        with pytest.raises(ValueError, match='^envelope: joint_factor: .* must be 0 \\(off\\) or a number from 1 up'):
            EnvelopeTrigger('envelope', env, ODOM, joint_factor=bad)
    assert envelope.check_joint_factor(0) == 0.0


def test_version_1_files_load_without_a_joint_check(tmp_path):
    import json
    from cc_log.learning.envelope import Envelope
    env = learned(nominal_drive(seconds=30))
    document = env.to_dict()
    assert document['version'] == 4 and set(document['joint']) == {
        'mean', 'scale', 'location', 'precision', 'typical', 'farthest'}
    old = {key: value for key, value in document.items() if key not in ('joint', 'local')}
    old['version'] = 1
    path = tmp_path / 'v1.json'
    path.write_text(json.dumps(old))
    loaded = Envelope.load(str(path))
    assert loaded.joint is None and loaded == env._replace(joint=None, local=None)
    path.write_text(json.dumps(dict(old, joint=document['joint'])))
    with pytest.raises(ValueError, match="v1.json: unknown key 'joint'$"):
        Envelope.load(str(path))
    path.write_text(json.dumps(dict(document, joint=None)))
    assert Envelope.load(str(path)).joint is None


def assert_blocks_refused(path, document, key, cases):
    """Each ``(bad, said)`` of ``cases``: ``document`` with its ``key`` block replaced by ``bad``, written to
    ``path``, is refused by ``Envelope.load`` in one line starting with the path and the block and saying ``said``."""
    import json
    from cc_log.learning.envelope import Envelope
    for bad, said in cases:
        with open(path, 'w') as stream:
            json.dump(dict(document, **{key: bad}), stream)
        with pytest.raises(ValueError) as error:
            Envelope.load(path)
        message = str(error.value)
        assert message.startswith('%s: %s' % (path, key)) and said in message and '\n' not in message, message


def test_bad_joint_blocks_are_refused_in_one_line(tmp_path):
    import json
    from cc_log.learning.envelope import Envelope
    env = learned(nominal_drive(seconds=30))
    document = env.to_dict()
    joint = document['joint']
    path = str(tmp_path / 'envelope.json')
    env.save(path)
    assert Envelope.load(path) == env
    precision = [list(line) for line in joint['precision']]
    precision[3][4] = 'x'
    cases = [([1, 2], 'joint: must map mean, scale, location, precision, typical, farthest to numbers'),
             ({k: v for k, v in joint.items() if k != 'typical'}, 'joint: must map mean,'),
             (dict(joint, extra=1), "(unknown key 'extra')"),
             (dict(joint, mean=joint['mean'][:18]), 'joint: mean: must be 19 numbers'),
             (dict(joint, precision=[line[:18] for line in joint['precision']]),
              'joint: precision: must be 19 x 19 numbers'),
             (dict(joint, precision=joint['precision'][0]), 'joint: precision: must be 19 x 19 numbers'),
             (dict(joint, precision=precision), "joint: precision: 'x' is not a finite number"),
             (dict(joint, location=[True] * 19), 'joint: location: True is not a finite number'),
             (dict(joint, scale=[0.0] * 19), 'joint: scale: every entry must be positive'),
             (dict(joint, typical=-1.0), 'joint: typical: -1.0 must be a finite non-negative number'),
             (dict(joint, typical=joint['farthest']), 'joint: typical %r must be below farthest' % joint['farthest']),
             (dict(joint, farthest='far'), "joint: farthest: 'far' must be")]
    assert_blocks_refused(path, document, 'joint', cases)
    with open(path, 'w') as stream:
        stream.write(json.dumps(document).replace(json.dumps(joint['farthest']), 'Infinity', 1))
    with pytest.raises(ValueError, match='Infinity is not a number JSON allows'):
        Envelope.load(path)


# -- end to end: cclog learn-envelope, then cclog replay --config with a trigger of kind envelope ----------------

HUSKY_ODOM = '/husky_velocity_controller/odom'


@pytest.fixture(scope='module')
def husky_surge(tmp_path_factory):
    """The Husky's real odometry: the envelope learned on its first half (cclog learn-envelope, default: with the
    joint check), a sudden acceleration at the robot's own scale injected into the second half
    (sim.inject_anomalies) and written to a bag: ``{'train', 'injected'}`` bag paths, ``limits`` (the envelope
    file), ``records`` (the injected records), ``event`` (its truth)."""
    import json
    import rosbag
    import rospy
    from conftest import cclog, real_data
    from cc_log import sim
    from cc_log.base.records import Record
    tmp_path = tmp_path_factory.mktemp('husky_surge')
    records = []
    with rosbag.Bag(real_data('husky_outdoor_2015.bag')) as bag:
        for topic, msg, t in bag.read_messages(topics=[HUSKY_ODOM]):
            records.append(Record(msg.header.stamp.to_sec() or t.to_sec(), topic, msg))
    middle = 0.5 * (records[0].stamp + records[-1].stamp)
    first = [r for r in records if r.stamp < middle]
    second = [r for r in records if r.stamp >= middle]
    scale = sim.nominal_envelope(first, HUSKY_ODOM)
    injected, truth = sim.inject_anomalies(second, ['sudden_acceleration'], seed=0, topic=HUSKY_ODOM, scale=scale,
                                           limits=scale)
    paths = {}
    for name, part in (('train', first), ('injected', injected)):
        paths[name] = str(tmp_path / (name + '.bag'))
        with rosbag.Bag(paths[name], 'w') as bag:
            for record in part:
                bag.write(record.topic, record.msg, rospy.Time.from_sec(record.stamp))
    limits = tmp_path / 'envelope.json'
    learned = cclog('learn-envelope', paths['train'], '--topic', HUSKY_ODOM, '--out', limits, '--json')
    assert learned.returncode == 0, learned.stderr
    printed = json.loads(learned.stdout)
    assert printed['windows'] > 300
    assert set(printed['local']) == {'k', 'windows', 'typical', 'extreme'}  # not its training windows
    assert len(learned.stdout) < 20000
    return dict(paths, limits=limits, records=injected, event=truth[0])


def windows_over(summary, event):
    """The metadata of the windows of a ``cclog replay --json`` summary that overlap ``event``, in start order."""
    from cc_log.storage import log_format
    return [log_format.read_window(window['path'])[0] for window in summary['windows']
            if window['start'] <= event['end'] and window['end'] >= event['start']]


def test_cclog_replay_with_an_envelope_trigger_catches_a_surge_injected_into_real_driving(tmp_path, husky_surge):
    """The injected half replayed with a configuration whose only trigger is of kind envelope: the surge is
    caught within 0.5 s and its window's trigger says why."""
    import json
    from conftest import cclog
    from cc_log.triggers.envelope import EnvelopeTrigger
    from cc_log.learning.envelope import Envelope
    limits, injected, event = husky_surge['limits'], husky_surge['records'], husky_surge['event']
    config = tmp_path / 'config.yaml'
    config.write_text('driving_topic: %s\nformat: json-xz\nwindows: {pre: 1s, post: 1s}\ntriggers:\n'
                      '  - {name: envelope, kind: envelope, limits: %s}\n' % (HUSKY_ODOM, limits))
    result = cclog('replay', husky_surge['injected'], '--config', config, '--out', tmp_path / 'logs', '--json')
    assert result.returncode == 0, result.stderr
    caught = windows_over(json.loads(result.stdout), event)
    assert caught, 'the injected surge was not kept'
    metadata = caught[0]       # windows in start order: the first one opened at the onset
    assert metadata['names'] == ['envelope']
    fired = [t for t in metadata['triggers'] if t['name'] == 'envelope']
    assert fired and event['start'] <= fired[0]['stamp'] <= event['start'] + 0.5
    assert fired[0]['score'] < 0
    info = metadata['trigger_info']['envelope']
    assert info['kind'] == 'envelope' and info['factor'] == 2.0 and set(info['limits']) == set(ENVELOPE_COLUMNS)
    if 'why' in fired[0]:      # the window metadata carries a Fire's why once that plumbing is in
        assert fired[0]['why'][0]['feature'] in ('max_span_accel', 'max_accel', 'max_speedup')
    # the same records through the trigger itself: its first Fire in the surge says why
    trigger = EnvelopeTrigger('envelope', Envelope.load(str(limits)), HUSKY_ODOM)
    fires = [(record.stamp, fire) for record, fired in zip(injected, trigger.on_records(injected)) for fire in fired
             if event['start'] <= record.stamp <= event['end']]
    stamp, fire = fires[0]
    assert stamp - event['start'] <= 0.5
    assert fire.why[0]['feature'] in ('max_span_accel', 'max_accel', 'max_speedup') and fire.why[0]['ratio'] > 2
    assert re.match(r'^(acceleration|acceleration over 0\.2 s|speed-up) \d+\.\d+ m/s\^2, \d+\.\dx ',
                    fire.why[0]['text']), fire.why[0]['text']


def test_cclog_replay_model_with_an_envelope_file_opens_the_envelopes_windows(tmp_path, husky_surge):
    """``cclog replay --model envelope.json``, no --topic, no configuration: the file decides the trigger (the
    envelope, on the odometry topic it was learned on, with its joint check); the surge opens a window and
    little else does. A file that is neither an envelope nor a model: one line naming it."""
    import json
    from conftest import cclog
    event = husky_surge['event']
    result = cclog('replay', husky_surge['injected'], '--model', husky_surge['limits'], '--out', tmp_path / 'logs',
                   '--json')
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    caught = windows_over(summary, event)
    assert caught and caught[0]['names'] == ['envelope'], caught
    fired = [t for t in caught[0]['triggers'] if t['name'] == 'envelope']
    assert fired and event['start'] <= fired[0]['stamp'] <= event['start'] + 0.5 and fired[0]['score'] < 0
    info = caught[0]['trigger_info']['envelope']
    assert (info['kind'], info['factor'], info['joint_factor']) == ('envelope', 2.0, 4.0)
    assert info['joint'] is not None and info['joint']['typical'] < info['joint']['farthest']
    assert len(summary['windows']) <= 3, summary['windows']
    other = tmp_path / 'notes.json'
    other.write_text('{"kind": "something else"}')
    result = cclog('replay', husky_surge['injected'], '--model', other, '--out', tmp_path / 'logs2')
    assert result.returncode == 1 and result.stderr == 'cclog replay: error: %s: not a cc_log model nor an envelope ' \
        'file (cclog learn or cclog learn-envelope writes one)\n' % other, result.stderr


def test_cclog_learn_envelope_learns_the_joint_check_by_default_and_says_its_figures(tmp_path, husky_surge):
    """Without --topic, the bag's only odometry topic; the joint check learned unless --no-joint, its figures
    said on the line before the local part's."""
    import json
    from conftest import cclog
    from cc_log.learning.envelope import Envelope
    out = tmp_path / 'envelope.json'
    result = cclog('learn-envelope', husky_surge['train'], '--out', out)
    assert result.returncode == 0, result.stderr
    assert 'driving topic %s (the bag\'s only nav_msgs/Odometry topic' % HUSKY_ODOM in result.stderr
    learned = Envelope.load(str(out))
    assert learned.topic == HUSKY_ODOM and learned.joint is not None
    last = result.stdout.strip().splitlines()[-2]
    assert last == 'joint check over %d windows: squared distance from typical driving %.4g typical (median), ' \
        '%.4g farthest; flagged beyond %.4g (joint_factor 4)' % (
            learned.windows, learned.joint.typical, learned.joint.farthest,
            learned.joint.typical + 4 * (learned.joint.farthest - learned.joint.typical)), last
    result = cclog('learn-envelope', husky_surge['train'], '--topic', HUSKY_ODOM, '--out', out, '--no-joint', '--json')
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    assert document['version'] == 4 and document['joint'] is None and Envelope.load(str(out)).joint is None


def test_cclog_learn_envelope_says_what_is_wrong_in_one_line(tmp_path):
    from conftest import cclog, real_data
    bag = real_data('husky_outdoor_2015.bag')
    out = tmp_path / 'envelope.json'
    for args, said in ((('--topic', '/imu/data'), 'topic /imu/data is sensor_msgs/Imu, expected nav_msgs/Odometry'),
                       (('--topic', HUSKY_ODOM, '--window', '5'), 'window: 5 must be a duration'),
                       (('--topic', HUSKY_ODOM, '--window', '500s'), 'no whole window of 500 s of odometry')):
        result = cclog('learn-envelope', bag, '--out', out, *args)
        assert result.returncode == 1 and result.stderr.count('\n') == 1, result.stderr
        assert result.stderr.startswith('cclog learn-envelope: error: ') and said in result.stderr, result.stderr
    assert not out.exists()
