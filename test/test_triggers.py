"""Triggers (classifier, rule, manual) and SmartLogger running several at once (no roscore; real messages)."""
import math
import os

import pytest

from cc_log.storage import log_format
from cc_log.features import FeatureConfig
from cc_log.base.event_kinds import OPENED, WRITTEN
from cc_log.logger.smart import SmartLogger
from cc_log.triggers import ClassifierTrigger, ManualTrigger, RuleTrigger
from cc_log.triggers.rule import Condition
from cc_log.base.records import Record

diagnostic_msgs = pytest.importorskip('diagnostic_msgs.msg')
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

ODOM, IMU, DIAG = '/odom', '/imu/data', '/diagnostics'


def odom_msg(stamp, speed=0.5):
    msg = Odometry()
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9))
    msg.pose.pose.orientation.w = 1.0
    msg.pose.pose.position.x = speed * stamp
    msg.twist.twist.linear.x = speed
    return msg


def imu_msg(stamp):
    msg = Imu()
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9))
    msg.linear_acceleration.z = 9.81
    return msg


def diag_msg(stamp, level, name='motors', message='overcurrent'):
    msg = diagnostic_msgs.DiagnosticArray()
    msg.header.stamp.secs, msg.header.stamp.nsecs = int(stamp), int(round((stamp % 1) * 1e9))
    msg.status = [diagnostic_msgs.DiagnosticStatus(level=level, name=name, message=message)]
    return msg


class Scripted(object):
    """A stand-in model: anomalous exactly while ``start <= stamp-of-newest-message < end`` (set by the test)."""

    def __init__(self, feature_set, window='10', spans=()):
        self.config = FeatureConfig(feature_set, window)
        self.threshold = 0.0
        self.spans = spans
        self.now = None

    def is_anomalous(self, vector):
        anomalous = any(start <= self.now < end for start, end in self.spans)
        return anomalous, (-1.0 if anomalous else 1.0)


def stream(seconds, rate=50.0, extra=None):
    """(topic, msg, stamp) of odometry and IMU at ``rate`` from t=100 s; ``extra(stamp)``: more items."""
    out = []
    for i in range(int(seconds * rate)):
        stamp = 100.0 + i / rate
        out.append((ODOM, odom_msg(stamp), stamp))
        out.append((IMU, imu_msg(stamp + 0.001), stamp + 0.001))
        if extra is not None:
            out.extend(extra(stamp))
    return out


def feed(logger, items, models=()):
    for topic, msg, stamp in items:
        for model in models:
            model.now = stamp
        logger.on_message(topic, msg, stamp)
    assert logger.close(30)


def windows(directory):
    return [log_format.read_window(path) for path in log_format.window_files(str(directory))]


# -- rule conditions: parsed, never evaluated ----------------------------------------------------------------

def test_conditions_parse_fields_operators_and_values():
    condition = Condition('twist.twist.linear.x > 2.0')
    assert condition.path == [('twist', None), ('twist', None), ('linear', None), ('x', None)]
    assert condition.op_text == '>' and condition.value == 2.0 and not condition.absolute
    assert Condition('abs(twist.twist.angular.z) >= 1.5').absolute
    assert Condition('status[2].name == "motors"').path == [('status', 2), ('name', None)]
    assert Condition("status.text != 'ok'").value == 'ok'
    assert Condition('data == true').value is True
    msg = odom_msg(1.0, speed=2.5)
    assert Condition('twist.twist.linear.x > 2.0').holds(msg) == (True, 2.5)
    msg.twist.twist.angular.z = -2.0
    assert Condition('abs(twist.twist.angular.z) >= 1.5').holds(msg)[0]
    msg.twist.twist.linear.x = float('nan')
    assert not Condition('twist.twist.linear.x != 0').holds(msg)[0]  # NaN never holds


@pytest.mark.parametrize('text', [
    "__import__('os').system('touch /tmp/cc_log_pwned') > 0", 'twist.linear.x > os.system', 'x >', '> 1',
    'twist.linear.x >> 1', 'a.b > 1; import os', 'f() > 1', 'x > 1 or y < 2', 'x > "unterminated', 'x < "a"',
    'abs(x) == "a"', 'x[-1] > 0', '', None])
def test_conditions_that_are_not_field_op_value_are_refused_with_one_line(text):
    with pytest.raises(ValueError) as error:
        Condition(text, 'fast: when')
    assert str(error.value).startswith('fast: when: ') and '\n' not in str(error.value)
    assert not os.path.exists('/tmp/cc_log_pwned')


@pytest.mark.parametrize('text, message', [
    ('twist.linear.x > 2', "fast: when: nav_msgs/Odometry.twist has no field 'linear'"),
    ('twist.twist.linear > 2', 'is geometry_msgs/Vector3, not a number'),
    ('pose.covariance > 2', 'is an array: give an index'),
    ('header[0].seq > 2', 'header is not an array'),
    ('header.frame_id > 2', 'is a string'),
    ('twist.twist.linear.x == "fast"', 'is a number (float64), not a string'),
    ('twist.twist.linear.x.y > 1', 'is float64 and has no fields'),
    ('pose.covariance[36] > 0', 'nav_msgs/Odometry.pose.covariance[36] is outside 0..35 elements (it has 36)'),
])
def test_a_field_is_checked_against_the_message_type_at_start(text, message):
    rule = RuleTrigger('fast', ODOM, when=text, type='nav_msgs/Odometry')
    with pytest.raises(ValueError) as error:
        rule.check(Odometry)
    assert str(error.value).startswith('fast: when: ') and message in str(error.value)
    RuleTrigger('fine', ODOM, when='pose.covariance[35] >= 0').check(Odometry)


@pytest.mark.parametrize('kwargs, message', [
    ({}, 'give exactly one of when, level, arrival, silent, min_rate (got none)'),
    ({'when': 'a > 1', 'arrival': True}, 'got when, arrival'),
    ({'silent': '10 min'}, "silent: '10 min' is not a duration"),
    ({'min_rate': -1}, 'min_rate'),
    ({'level': 'BAD'}, "level: 'BAD' is not one of OK, WARN, ERROR, STALE"),
    ({'arrival': True, 'hold_off': 'soon'}, 'hold_off'),
])
def test_bad_rules_fail_at_start_naming_what(kwargs, message):
    with pytest.raises(ValueError) as error:
        RuleTrigger('r1', ODOM, **kwargs)
    assert str(error.value).startswith('r1: ') and message in str(error.value)
    with pytest.raises(ValueError, match='trigger name'):
        RuleTrigger('bad name!', ODOM, arrival=True)


# -- rules firing -----------------------------------------------------------------------------------------

def records(rule, items):
    fires = []
    for stamp, msg in items:
        fires += [(stamp, fire) for fire in rule.on_record(Record(stamp, rule.topic, msg))]
    return fires


def test_a_flapping_condition_makes_one_fire_per_hold_off():
    rule = RuleTrigger('fast', ODOM, when='twist.twist.linear.x > 2.0', type='nav_msgs/Odometry', hold_off='5s')
    rule.check(Odometry)
    speeds = [1.0] * 10 + [2.5, 1.0] * 20 + [1.0] * 300 + [3.0] * 50  # flapping for 0.8 s, quiet 6 s, fast
    fires = records(rule, [(i * 0.02, odom_msg(i * 0.02, speed)) for i, speed in enumerate(speeds)])
    assert [stamp for stamp, _ in fires] == [pytest.approx(0.2), pytest.approx(7.0)]
    assert fires[0][1].name == 'fast' and fires[0][1].reason == 'twist.twist.linear.x > 2.0 (2.5)'
    assert math.isnan(fires[0][1].score) and rule.stats()['fired'] == 2


def test_a_field_rule_without_a_type_is_checked_at_the_first_message_and_turned_off_when_wrong():
    rule = RuleTrigger('typo', ODOM, when='twist.linaer.x > 2.0')
    assert records(rule, [(0.0, odom_msg(0.0, 5.0)), (10.0, odom_msg(10.0, 5.0))]) == []
    assert "has no field 'linaer'" in rule.stats()['error']


def test_diagnostics_level_at_or_above_by_name_ignoring_cc_logs_own_status():
    rule = RuleTrigger('motors', level='ERROR', status='motor*', hold_off='2s')
    assert rule.topic == DIAG
    items = [(0.0, diag_msg(0.0, 1)), (1.0, diag_msg(1.0, 2, name='cameras')), (2.0, diag_msg(2.0, 2)),
             (3.0, diag_msg(3.0, 2)), (4.0, diag_msg(4.0, 0)), (5.0, diag_msg(5.0, 3, message='no data')),
             (9.0, diag_msg(9.0, 2, name='cc_log: smart_logger'))]
    fires = records(rule, items)
    assert [(stamp, fire.reason) for stamp, fire in fires] == [(2.0, 'motors: ERROR overcurrent'),
                                                               (5.0, 'motors: STALE no data')]
    rule = RuleTrigger('any', level=2)
    assert records(rule, [(9.0, diag_msg(9.0, 2, name='cc_log: smart_logger'))]) == []


def test_arrival_fires_per_message_outside_the_hold_off():
    rule = RuleTrigger('bumper', '/bumper', arrival=True, hold_off='1s')
    fires = records(rule, [(t, odom_msg(t)) for t in (0.0, 0.5, 0.9, 1.0, 5.0)])
    assert [stamp for stamp, _ in fires] == [0.0, 1.0, 5.0]
    assert fires[0][1].reason == 'message on /bumper'


def test_silence_and_low_rate_fire_once_per_episode():
    silent = RuleTrigger('scan_dead', '/scan', silent='1s')
    slow = RuleTrigger('scan_slow', '/scan', min_rate=8.0, over='1s')
    fired = {'scan_dead': [], 'scan_slow': []}
    scan = [t / 10.0 for t in range(0, 30)] + [3.0 + t / 4.0 for t in range(0, 8)] + [t / 10.0 for t in range(50, 80)]
    scan = set(round(t, 3) for t in scan)
    for i in range(0, 800):
        now = round(i / 100.0, 3)
        for rule in (silent, slow):
            if now in scan:
                rule.on_record(Record(now, '/scan', None))
            fired[rule.name] += [now for _ in rule.on_time(now)]
    # 10 Hz until 3 s, 4 Hz until 5 s (slow, never more than 1 s silent), 10 Hz after 5 s: 7 messages in the
    # second before 3.4 s
    assert fired['scan_slow'] == [pytest.approx(3.4, abs=0.001)]
    assert fired['scan_dead'] == []
    for i in range(800, 1200):  # the scan stops at 7.9 s
        now = i / 100.0
        fired['scan_dead'] += [now for _ in silent.on_time(now)]
    assert fired['scan_dead'] == [pytest.approx(8.91, abs=0.011)]


# -- SmartLogger with several triggers --------------------------------------------------------------------

def test_a_diagnostics_rule_saves_exactly_one_window_with_its_span_and_reason(tmp_path):
    """A status switching to ERROR (and flapping) at 3 s of a 10 s run: one window, pre before and post after
    the first ERROR, named after the rule."""
    def diagnostics(stamp):
        k = int(round((stamp - 100.0) * 50))
        if k % 25:
            return []
        level = 2 if 150 <= k < 300 and k % 50 == 0 else 0  # ERROR at 3 s, 4 s, 5 s: flapping at 1 Hz
        return [(DIAG, diag_msg(stamp + 0.002, level), stamp + 0.002)]
    rule = RuleTrigger('motor_error', level='ERROR', hold_off='5s')
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '1s', '2s', driving_topic=ODOM, side_topics=[IMU],
                         triggers=[rule])
    events = []
    logger.on_event(events.append)
    feed(logger, stream(10.0, extra=diagnostics))
    [(metadata, kept)] = windows(tmp_path)
    odom = [r.stamp for r in kept if r.topic == ODOM]
    assert odom[0] == pytest.approx(102.0) and odom[-1] == pytest.approx(105.0)
    assert metadata['trigger'] == 'motor_error' and metadata['names'] == ['motor_error']
    assert metadata['reason'] == 'motors: ERROR overcurrent' and len(metadata['triggers']) == 1
    assert sorted(set(r.topic for r in kept)) == [DIAG, IMU, ODOM]
    assert log_format.window_files(str(tmp_path))[0].endswith('_motor-error.json.xz')
    opened = [e for e in events if e.kind == OPENED]
    assert [(e.trigger, e.reason) for e in opened] == [('motor_error', 'motors: ERROR overcurrent')]


def test_imu_and_odometry_classifiers_side_by_side_merge_overlapping_windows_into_one_file(tmp_path):
    odom_model = Scripted('motion', spans=[(103.0, 103.1)])
    imu_model = Scripted('imu', spans=[(103.5, 103.6), (108.0, 108.05)])
    triggers = [ClassifierTrigger('odom_motion', odom_model, ODOM, classify_every='1'),
                ClassifierTrigger('imu_shock', imu_model, IMU, classify_every='1', retrigger='onset')]
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '0.5s', '0.5s', driving_topic=ODOM, triggers=triggers)
    feed(logger, stream(10.0), [odom_model, imu_model])
    found = sorted(windows(tmp_path), key=lambda w: w[0]['start'])
    assert len(found) == 2
    (first, kept), (second, _) = found
    assert first['names'] == ['odom_motion', 'imu_shock'] and first['trigger'] == 'odom_motion'
    # odometry anomalous at 103.0..103.08, the IMU's onset at 103.501 (at the newest odometry, 103.5): 0.5 s
    assert first['start'] == pytest.approx(102.5) and first['end'] == pytest.approx(104.0)
    assert [t['name'] for t in first['triggers']].count('imu_shock') == 1  # onset only
    assert sorted(first['trigger_info']) == ['imu_shock', 'odom_motion']
    assert first['trigger_info']['imu_shock']['model']['feature_set'] == 'imu'
    assert second['names'] == ['imu_shock']
    assert logger.stats()['triggers']['odom_motion']['fired'] == 5


@pytest.mark.parametrize('value', [1e200, 1e155, 1e7])
def test_five_seconds_of_odometry_beyond_any_physical_range_fire_and_their_span_is_kept(tmp_path, value):
    """linear.x = 1e200 from 105 s to 110 s: a classifier whose model calls every window nominal (a threshold
    tuned low) still fires, and one window keeps the whole 5 s."""
    model = Scripted('motion', window='10')  # never anomalous

    def huge(item):
        topic, msg, stamp = item
        if topic == ODOM and 105.0 <= stamp < 110.0:
            msg.twist.twist.linear.x = value
        return item
    trigger = ClassifierTrigger('motion', model, ODOM)
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '1s', '1s', driving_topic=ODOM, triggers=[trigger])
    feed(logger, [huge(item) for item in stream(20.0)], [model])
    (metadata, records), = windows(tmp_path)
    assert metadata['names'] == ['motion'] and metadata['triggers'][0]['score'] == -1e6
    assert metadata['start'] <= 104.0 + 0.06 and metadata['end'] >= 110.0  # fired within classify_every (50 ms)
    kept = [r.stamp for r in records if r.topic == ODOM and 105.0 <= r.stamp < 110.0]
    assert len(kept) == 250  # every message of the 5 s at 50 Hz


def test_a_manual_request_reaching_beyond_what_the_logger_holds_says_it_was_cut(tmp_path):
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '2s', '1s', driving_topic=ODOM)
    items = stream(10.0)  # 50 Hz from 100 s
    for topic, msg, stamp in items[:52]:  # 26 odometry messages: 100.00 .. 100.50 s
        logger.on_message(topic, msg, stamp)
    ok, message = logger.trigger_now('early', before=1.5, after=0.1)
    assert ok and message.endswith('; before 1.5 s cut to 0.500 s: nothing older is held (the logger keeps ~pre 2s)')
    for topic, msg, stamp in items[52:600]:  # up to 105.98 s: the pre buffer holds its 2 s
        logger.on_message(topic, msg, stamp)
    ok, message = logger.trigger_now('far', before=10.0, after=0.1)
    assert ok and message.endswith('; before 10 s cut to 2.000 s: nothing older is held (the logger keeps ~pre 2s)')
    for topic, msg, stamp in items[600:1000]:  # the window before is complete (its post and a pre after it)
        logger.on_message(topic, msg, stamp)
    ok, message = logger.trigger_now('near', before=1.0, after=0.1)
    assert ok and 'cut' not in message and message.endswith('from 108.980')  # as asked
    assert logger.close(30)


def test_manual_request_with_a_reason_and_its_own_span(tmp_path):
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '2s', '1s', driving_topic=ODOM)
    items = stream(10.0)
    for topic, msg, stamp in items[:500]:  # up to 105 s
        logger.on_message(topic, msg, stamp)
    ok, message = logger.trigger_now('operator saw a wobble', before=0.5, after=3.0)
    assert ok and 'operator saw a wobble' in message and 'from 104.480' in message
    assert logger.trigger_now('x', before=-1.0) == (False, 'before: -1.0 must be a number of seconds from 0 to 86400')
    for topic, msg, stamp in items[500:]:
        logger.on_message(topic, msg, stamp)
    assert logger.close(30)
    [(metadata, kept)] = windows(tmp_path)
    odom = [r.stamp for r in kept if r.topic == ODOM]
    assert odom[0] == pytest.approx(104.48) and odom[-1] == pytest.approx(107.98)
    assert metadata['trigger'] == 'manual' and metadata['reason'] == 'operator saw a wobble'
    assert metadata['triggers'][0]['score'] == 'NaN'


def test_a_window_reaches_as_far_as_its_longest_post(tmp_path):
    short = RuleTrigger('short', '/bumper', arrival=True, post='0.2s')
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '0.1s', '1s', driving_topic=ODOM, triggers=[short])
    bumps = {102.0: 'a', 102.1: 'b'}

    def bumper(stamp):
        return [('/bumper', odom_msg(stamp + 0.001), stamp + 0.001)] if round(stamp, 3) in bumps else []
    items = stream(5.0, extra=bumper)
    for topic, msg, stamp in items:
        logger.on_message(topic, msg, stamp)
        if round(stamp, 3) == 101.5:
            logger.trigger_now('long')  # post 1 s: until 102.5 s; the bumps (0.2 s) do not shorten it
    assert logger.close(30)
    [(metadata, kept)] = windows(tmp_path)
    assert metadata['names'] == ['manual', 'short']
    assert [r.stamp for r in kept if r.topic == ODOM][-1] == pytest.approx(102.5)


def test_triggers_are_checked_together_at_start(tmp_path):
    with pytest.raises(ValueError, match="^triggers: two triggers are named 'manual'$"):
        SmartLogger(None, str(tmp_path), driving_topic=ODOM, triggers=[ManualTrigger(), ManualTrigger()])
    imu_model = Scripted('imu')
    with pytest.raises(ValueError, match='^topics: /odom is nav_msgs/Odometry for trigger classifier and '
                                         'sensor_msgs/Imu for trigger imu$'):
        SmartLogger(Scripted('motion'), str(tmp_path), driving_topic=ODOM,
                    triggers=[ClassifierTrigger('imu', imu_model, ODOM)])
    with pytest.raises(ValueError, match='^c: topics: the command feature set reads 2 topic'):
        ClassifierTrigger('c', Scripted('command'), ODOM)


def test_a_fire_before_any_driving_message_is_counted_not_kept(tmp_path):
    bumper = RuleTrigger('b', '/bumper', arrival=True)
    logger = SmartLogger(None, str(tmp_path), driving_topic=ODOM, triggers=[bumper])
    logger.on_message('/bumper', odom_msg(1.0), 1.0)
    assert logger.trigger_now() == (False, 'no /odom message received yet')
    logger.on_message(ODOM, odom_msg(1.5), 1.5)  # its Fire waited for the driving clock (fire_order): none before it
    assert logger.stats()['fires_dropped'] == 1 and logger.stats()['triggers']['b']['fired'] == 1
    logger.close()
    assert windows(tmp_path) == []


def test_a_silent_sensor_is_caught_by_message_time_and_by_ticks(tmp_path):
    rule = RuleTrigger('imu_dead', IMU, silent='0.5s')
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '0.2s', '0.2s', driving_topic=ODOM, triggers=[rule])
    events = []
    logger.on_event(events.append)
    for topic, msg, stamp in stream(4.0):
        if topic == IMU and stamp > 102.0:
            continue  # the IMU dies at 102 s
        logger.on_message(topic, msg, stamp)
    logger.tick(110.0)  # nothing else arrives either: a tick still sees the silence (already fired)
    assert logger.close(30)
    [(metadata, kept)] = windows(tmp_path)
    assert metadata['reason'] == '/imu/data silent for more than 0.5s'
    assert metadata['triggers'][0]['stamp'] == pytest.approx(102.5)  # the last IMU message came at 101.981
    assert [e.kind for e in events] == [OPENED, WRITTEN]


def test_a_goal_status_rule_catches_every_simulated_planning_failure_once(tmp_path):
    """The simulated move_base aborts its goal when a planning failure ends: a rule on /move_base/status
    saves one window at the end of each failure, and none elsewhere."""
    from cc_log import sim
    run = sim.SimConfig(minutes=4, anomalies=3, anomaly_types=('planning_failure', 'collision'), seed=4,
                        commands=True)
    simulator = sim.Simulator(run)
    rule = RuleTrigger('goal_aborted', sim.STATUS_TOPIC, type='actionlib_msgs/GoalStatusArray',
                       when='status_list[0].status == 4')
    from cc_log.base.raw_message import installed_class
    rule.check(installed_class(rule.type))
    logger = SmartLogger(None, str(tmp_path), 'json-xz', '1s', '1s', driving_topic=sim.ODOM_TOPIC, triggers=[rule])
    feed(logger, [(topic, msg, stamp) for topic, stamp, msg in simulator.messages()])
    failures = [e for e in simulator.truth if e['type'] == 'planning_failure']
    found = sorted(windows(tmp_path), key=lambda w: w[0]['start'])
    assert failures and len(found) == len(failures)
    for (metadata, _), entry in zip(found, failures):
        assert metadata['names'] == ['goal_aborted'] and len(metadata['triggers']) == 1
        assert abs(metadata['triggers'][0]['stamp'] - entry['end']) < 0.02
        assert metadata['reason'] == 'status_list[0].status == 4 (4)'


# -- pre and post per trigger, from the configuration -----------------------------------------------------

HUSKY, HUSKY_ODOM = 'husky_outdoor_2015.bag', '/husky_velocity_controller/odom'


def configured_logger(directory, text):
    """A SmartLogger as the node and ``cclog replay --config`` build it from a configuration's text."""
    import yaml
    from cc_log.logger.config import Config
    from cc_log.base.raw_message import installed_class
    from cc_log.learning.model import AnomalyModel
    cfg = Config.from_dict(yaml.safe_load(text), 'test.yaml')
    triggers = cfg.build_triggers(AnomalyModel.load, installed_class)
    return SmartLogger(None, str(directory), **cfg.logger_options(triggers))


def test_a_trigger_of_the_configuration_keeps_its_own_pre_and_post_on_real_driving(tmp_path, real_bag):
    """windows.pre 10 s, post 5 s; a turn rule of its own 1 s before and 0.5 s after: its windows on the Husky's
    real turns start 1 s before its first fire and end 0.5 s after its last, not 10 s and 5 s."""
    from cc_log.storage.bag import bagio
    logger = configured_logger(tmp_path, """
windows: {pre: 10s, post: 5s}
triggers:
  - {name: turn, kind: rule, topic: %s, type: nav_msgs/Odometry, when: 'abs(twist.twist.angular.z) > 0.4',
     hold_off: 0.1s, pre: 1s, post: 0.5s}
""" % HUSKY_ODOM)
    feed(logger, [(r.topic, r.msg, r.stamp) for r in bagio.read_messages(real_bag(HUSKY), [HUSKY_ODOM])])
    found = windows(tmp_path)
    assert found
    for metadata, kept in found:
        odom = [r.stamp for r in kept if r.topic == HUSKY_ODOM]
        fires = [t['stamp'] for t in metadata['triggers']]
        assert metadata['names'] == ['turn']
        assert odom[0] == pytest.approx(fires[0] - 1.0, abs=0.11)  # the Husky's odometry comes at 10 Hz
        assert odom[-1] == pytest.approx(fires[-1] + 0.5, abs=0.11)


def test_a_goal_abort_keeps_the_whole_planning_failure_before_it(tmp_path):
    """The demo's rule with its own pre of 10 s (windows.pre 10 s, the classifier's 1 s): each simulated
    planning failure (5-9 s of oscillation, aborted at its end) is inside the abort's window."""
    from cc_log import sim
    run = sim.SimConfig(minutes=3, anomalies=2, anomaly_types=('planning_failure',), seed=4, commands=True)
    simulator = sim.Simulator(run)
    logger = configured_logger(tmp_path, """
driving_topic: /odom
windows: {pre: 10s, post: 5s}
triggers:
  - {name: goal_aborted, kind: rule, topic: /move_base/status, type: actionlib_msgs/GoalStatusArray,
     when: 'status_list[0].status == 4', pre: 10s, post: 1s}
""")
    feed(logger, [(topic, msg, stamp) for topic, stamp, msg in simulator.messages()])
    found = sorted(windows(tmp_path), key=lambda w: w[0]['start'])
    failures = simulator.truth
    assert len(failures) == 2 and len(found) == 2
    for (metadata, _), entry in zip(found, failures):
        assert metadata['start'] <= entry['start'] and metadata['end'] >= entry['end'] - 0.02
        assert metadata['end'] == pytest.approx(metadata['triggers'][-1]['stamp'] + 1.0, abs=0.02)


def test_a_trigger_pre_longer_than_the_logger_holds_is_refused_with_one_line():
    from cc_log.logger.config import Config
    entry = {'name': 'goal_aborted', 'kind': 'rule', 'topic': 'bumper', 'arrival': True, 'pre': '10s'}
    with pytest.raises(ValueError) as error:
        Config.from_dict({'windows': {'pre': '2s'}, 'triggers': [entry]}, 'robot.yaml')
    assert str(error.value) == (
        'robot.yaml: triggers[0] (goal_aborted): pre: 10s is longer than windows.pre 2s, the most the logger holds '
        'before a trigger: raise windows.pre (and give shorter triggers their own pre)')
    Config.from_dict({'windows': {'pre': '10s'}, 'triggers': [entry]})
    Config.from_dict({'windows': {'pre': '100'}, 'triggers': [entry]})  # messages and seconds: not comparable
    assert str(Config.from_dict({'triggers': [entry]}).pre) == '10s'  # not given: the longest a trigger asks for
    assert str(Config.from_dict({'triggers': [dict(entry, pre='1s')]}).pre) == '2s'  # ... or the default


# -- the periodic trigger -----------------------------------------------------------------------------------

def test_a_periodic_trigger_keeps_a_sample_every_period_of_real_driving(tmp_path, real_bag):
    """``kind: periodic, every: 1min`` on the Husky's 392 s of real odometry: a window of its own 2 s before
    and 3 s after every minute of message time from the first message, reason ``periodic``, nothing else."""
    from cc_log.storage.bag import bagio
    logger = configured_logger(tmp_path, """
driving_topic: %s
windows: {pre: 10s, post: 5s}
triggers:
  - {name: sample, kind: periodic, every: 1min, pre: 2s, post: 3s}
""" % HUSKY_ODOM)
    items = [(r.topic, r.msg, r.stamp) for r in bagio.read_messages(real_bag(HUSKY), [HUSKY_ODOM])]
    feed(logger, items)
    first, last = items[0][2], items[-1][2]
    found = sorted(windows(tmp_path), key=lambda w: w[0]['start'])
    assert len(found) == int((last - first) // 60.0) == 6
    for k, (metadata, kept) in enumerate(found, 1):
        [fire] = metadata['triggers']
        assert metadata['names'] == ['sample'] and metadata['reason'] == 'periodic'
        assert first + 60.0 * k <= fire['stamp'] < first + 60.0 * k + 0.11  # the first message past each minute
        odom = [r.stamp for r in kept]
        assert odom[0] == pytest.approx(fire['stamp'] - 2.0, abs=0.11)
        assert odom[-1] == pytest.approx(fire['stamp'] + 3.0, abs=0.11)
    assert found[0][0]['trigger_info']['sample']['every'] == '1min'


def test_a_periodic_trigger_keeps_its_grid_and_makes_one_window_after_a_gap():
    from cc_log.triggers.periodic import PeriodicTrigger
    periodic = PeriodicTrigger('periodic', every='10s')
    fired = [t for t in [0.0, 5.0, 9.99, 10.03, 15.0, 20.01, 29.0, 95.0, 96.0, 105.0, 50.0, 59.0, 60.0]
             if periodic.on_time(t)]
    # grid 10, 20, 30 from the first stamp; the gap to 95 s gives one window, then 105; back to 50 s: restart
    assert fired == [10.03, 20.01, 95.0, 105.0, 60.0]
    assert periodic.stats()['fired'] == 5 and periodic.fire('periodic').reason == 'periodic'


@pytest.mark.parametrize('every, message', [
    (None, 'every: required'), ('10', "every: '10' is not a duration like 30s, 10min or 1h"),
    ('0s', "every: '0s' must be a positive duration"), ('x' * 500, 'is not a duration'),
    (12.5, 'is not a duration')])
def test_a_bad_period_is_one_line_naming_every(every, message):
    from cc_log.logger.config import Config
    entry = {'name': 'sample', 'kind': 'periodic', 'every': every}
    with pytest.raises(ValueError) as error:
        Config.from_dict({'driving_topic': 'odom', 'triggers': [entry]}, 'robot.yaml').build_triggers(
            None, None)
    text = str(error.value)
    assert text.startswith('robot.yaml: triggers[0] (sample): every: ') and message in text
    assert '\n' not in text and len(text) < 160


@pytest.mark.parametrize('text', ['pose.covariance[99999999] > 0', 'header.frame_id[1000001] == "a"'])
def test_an_index_beyond_any_message_is_refused_at_configuration_time(text):
    """Issue 42 item 9: a rule on pose.covariance[99999999] never fired; it is refused where it enters, before
    any message type is known (a fixed-size array's own length is checked with the type)."""
    with pytest.raises(ValueError) as error:
        RuleTrigger('r', ODOM, when=text)
    assert str(error.value).startswith("r: when: '") and str(error.value).endswith(
        "]' is outside 0..1e+06 elements")
    RuleTrigger('r', ODOM, when='pose.covariance[1000000] > 0')  # at the bound: the type decides
