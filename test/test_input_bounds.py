"""Hostile input is bounded where it enters (issue 29): each example fails with one short line naming the
input, in bounded time and memory, never a traceback."""
import pytest

from cc_log.logger import config
from cc_log.base import safe_input
from cc_log.logger.config import Config


def one_line(error, limit=300):
    """The text of ``error``, checked to be one short line."""
    text = str(error.value)
    assert '\n' not in text and len(text) <= limit, text[:400]
    return text


# -- 11: YAML alias bombs and unbounded reprs --------------------------------------------------------------

def alias_bomb(levels, key='driving_topic'):
    """A YAML document of a few hundred bytes whose ``key`` expands to 9 ** levels strings."""
    lines = ['a0: &a0 [%s]' % ', '.join(['lol'] * 9)]
    for level in range(1, levels):
        lines.append('a%d: &a%d [%s]' % (level, level, ', '.join(['*a%d' % (level - 1)] * 9)))
    lines.append('%s: *a%d' % (key, levels - 1))
    return '\n'.join(lines) + '\n'


def test_yaml_alias_bomb_is_refused_with_one_line(tmp_path):
    path = tmp_path / 'bomb.yaml'
    path.write_text(alias_bomb(7))
    assert path.stat().st_size < 500
    with pytest.raises(ValueError) as error:
        Config.from_dict(config.load_file(str(path)), str(path))
    assert one_line(error).startswith('%s: not YAML: YAML aliases expand' % path)


def test_yaml_too_many_aliases_is_refused(tmp_path):
    path = tmp_path / 'aliases.yaml'
    path.write_text('a: &a x\nb: [%s]\n' % ', '.join(['*a'] * (safe_input.MAX_YAML_ALIASES + 1)))
    with pytest.raises(ValueError) as error:
        config.load_file(str(path))
    assert 'more than %d YAML aliases' % safe_input.MAX_YAML_ALIASES in one_line(error)


def test_yaml_recursive_alias_is_refused(tmp_path):
    path = tmp_path / 'loop.yaml'
    path.write_text('topics: &a [*a]\n')
    with pytest.raises(ValueError) as error:
        config.load_file(str(path))
    assert 'contains it' in one_line(error)


def test_yaml_anchors_of_an_ordinary_configuration_still_load(tmp_path):
    path = tmp_path / 'robot.yaml'
    path.write_text('hold: &hold {hold_off: 3s}\n'
                    'triggers:\n  - {name: a, kind: rule, topic: /bumper, arrival: true}\n'
                    '  - {<<: *hold, name: b, kind: rule, topic: /scan, silent: 1s}\n')
    data = config.load_file(str(path))
    assert data['triggers'][1]['hold_off'] == '3s'
    del data['hold']
    cfg = Config.from_dict(data, str(path))
    assert [entry['name'] for entry in cfg.triggers] == ['a', 'b']


@pytest.mark.parametrize('document', [
    {'driving_topic': ['x' * 100000] * 50},
    {'topics': [[list(range(100000))]]},
    {'triggers': 'y' * 1000000},
    {'windows': {'pre': 'z' * 1000000}},
    {'triggers': [{'name': 'n' * 1000000, 'kind': 'rule'}]},
    {'triggers': [{'name': 'r', 'kind': 'k' * 1000000}]},
    {'k' * 1000000: 1},
])
def test_errors_show_a_bounded_part_of_the_value(document):
    with pytest.raises(ValueError) as error:
        Config.from_dict(document, 'robot.yaml')
    assert one_line(error).startswith('robot.yaml: ')


@pytest.mark.parametrize('options', [{'when': 'q' * 10 ** 6}, {'when': 'a.b > ' + 'v' * 10 ** 6},
                                     {'level': ['E'] * 10 ** 6}, {'silent': 's' * 10 ** 6},
                                     {'min_rate': 'm' * 10 ** 6}])
def test_rule_errors_show_a_bounded_part_of_the_value(options):
    from cc_log.triggers import RuleTrigger
    with pytest.raises(ValueError) as error:
        RuleTrigger('r', topic='/a', **options)
    assert one_line(error).startswith('r: ')


def test_brief_is_bounded():
    assert len(safe_input.brief('x' * 10 ** 6)) <= safe_input.BRIEF_CHARS
    assert len(safe_input.brief([[list(range(10 ** 5))] * 10 ** 3])) <= safe_input.BRIEF_CHARS
    assert safe_input.brief('/odom') == "'/odom'"


# -- 13: types and ranges where each input enters ----------------------------------------------------------

@pytest.mark.parametrize('document, expected', [
    ({'format': ['json-xz']}, 'format: '),
    ({'format': {'bag-lz4': 1}}, 'format: '),
    ({'windows': {'pre': '1e303'}}, 'windows.pre: '),
    ({'windows': {'post': 1e303}}, 'windows.post: '),
    ({'windows': {'max': '1e303s'}}, 'windows.max: '),
    ({'limits': {'max_buffer_mb': '1e303'}}, 'limits.max_buffer_mb: '),
    ({'limits': {'max_disk_mb': '1e300GB'}}, 'limits.max_disk_mb: '),
    ({'triggers': [{'name': 'r', 'kind': 'rule', 'topic': '/a', 'silent': '1e303s'}]}, 'silent: '),
])
def test_config_types_and_ranges_are_one_line_naming_the_key(document, expected):
    with pytest.raises(ValueError) as error:
        cfg = Config.from_dict(document, 'robot.yaml')
        cfg.build_triggers(lambda path: None, lambda msg_type: None)
    text = one_line(error)
    assert text.startswith('robot.yaml: ') and expected in text


def test_a_rule_topic_must_be_a_string():
    cfg = Config.from_dict({'triggers': [{'name': 'r', 'kind': 'rule', 'topic': 5, 'arrival': True}]}, 'robot.yaml')
    with pytest.raises(ValueError) as error:
        cfg.build_triggers(lambda path: None, lambda msg_type: None)
    assert one_line(error) == 'robot.yaml: triggers[0] (r): topic: 5 is not a topic name'


def test_a_classifier_window_of_collect_mode_is_bounded():
    cfg = Config.from_dict({'triggers': [{'name': 'c', 'kind': 'classifier', 'window': 99999999999999}]}, 'x')
    with pytest.raises(ValueError) as error:
        cfg.feature_specs()
    assert "(c): window: '99999999999999' is outside 1..100000 messages" in one_line(error)
    cfg = Config.from_dict({'triggers': [{'name': 'c', 'kind': 'classifier', 'window': 200000}]}, 'x')
    with pytest.raises(ValueError) as error:
        cfg.feature_specs()
    assert "(c): window: '200000' is outside 1..100000 messages" in one_line(error)


def test_spans_and_sizes_are_bounded():
    from cc_log.base.spans import Span, megabytes, MAX_COUNT, MAX_SECONDS
    assert Span.parse(str(MAX_COUNT)).count == MAX_COUNT
    assert Span.parse('%gs' % MAX_SECONDS).seconds == MAX_SECONDS
    for value in ('1e303', 1e303, '1e300s', '1e300ms', 10 ** 400):
        with pytest.raises(ValueError):
            Span.parse(value, 'size')
    with pytest.raises(ValueError):
        megabytes('1e303', 'size')


def test_the_diagnostic_period_is_bounded():
    node_common = pytest.importorskip('cc_log.nodes.node_common')
    params = node_common.Params(get={'diagnostic_period': 1e308}.get, log=lambda *args: None)
    with pytest.raises(node_common.ConfigError) as error:
        params.option('diagnostic_period')
    assert one_line(error) == '~diagnostic_period: 1e+308 is outside 0.01..3600 s (or 0: off)'
    params = node_common.Params(get={'diagnostic_period': 30}.get, log=lambda *args: None)
    assert params.option('diagnostic_period') == 30


def small_model_document(window='5s'):
    """The document of a small valid ocsvm model of the motion features."""
    import numpy as np
    from cc_log.features import FeatureConfig, vector_length
    from cc_log.learning.model import AnomalyModel
    config_ = FeatureConfig('motion', window)
    dimension = vector_length(config_)
    model = AnomalyModel(config_, np.zeros(dimension), np.ones(dimension), 'ocsvm',
                         {'support_vectors': np.eye(2, dimension), 'dual_coef': [0.5, 0.5], 'intercept': -0.1,
                          'gamma': 0.1}, threshold=0.0)
    return model.to_dict()


@pytest.mark.parametrize('change, expected', [
    (lambda doc: doc['config'].update(window='99999999999999'), "window: '99999999999999' is outside 1..100000 "),
    (lambda doc: doc['config'].update(window='200000'), "window: '200000' is outside 1..100000 messages"),
    (lambda doc: doc['config'].update(window='1e300s'), 'window: '),
    (lambda doc: doc['config'].update(window='7200s'), "window: '7200s' is outside 0.01..3600 s"),
    (lambda doc: doc['kernel'].update(gamma=1e308), 'kernel.gamma: 1e+308 is not in'),
    (lambda doc: doc['scaler'].update(scale=[5e-324] * len(doc['scaler']['scale'])), 'scaler.scale must be'),
])
def test_implausible_models_are_refused_naming_the_key(tmp_path, change, expected):
    import json
    from cc_log.learning.model import AnomalyModel, ModelError
    document = small_model_document()
    change(document)
    path = tmp_path / 'model.json'
    path.write_text(json.dumps(document))
    with pytest.raises(ModelError) as error:
        AnomalyModel.load(str(path))
    text = one_line(error)
    assert text.startswith(str(path)) and expected in text


@pytest.mark.parametrize('key', ['threshold', 'gamma', 'support_vectors', 'coverage'])
def test_a_model_number_of_401_digits_is_refused_with_one_line(tmp_path, key):
    """Issue 42 item 15: an integer no float holds (math and numpy raised OverflowError: a traceback in replay,
    learn and the node) is refused by the model's one reader of numbers, naming the file."""
    import json
    from cc_log.learning.model import AnomalyModel, ModelError
    document = small_model_document()
    huge = int('9' * 401)
    if key == 'threshold':
        document['threshold'] = huge
    elif key == 'gamma':
        document['kernel']['gamma'] = -huge
    elif key == 'support_vectors':
        document['kernel']['support_vectors'][0][0] = huge
    else:
        document['coverage'] = {'quantities': [{'name': 'v', 'unit': 'm/s', 'min': 0, 'max': huge}]}
    path = tmp_path / 'model.json'
    path.write_text(json.dumps(document))
    with pytest.raises(ModelError) as error:
        AnomalyModel.load(str(path))
    text = one_line(error)
    assert text.startswith(str(path) + ': ') and 'integer of 401 digits is out of range' in text


def test_model_integers_a_float_holds_are_read(tmp_path):
    """The bound of item 15 keeps every integer a float holds (here the threshold, 309 digits)."""
    import json
    from cc_log.learning.model import AnomalyModel
    document = small_model_document()
    document['threshold'] = int('1' + '0' * 308)
    path = tmp_path / 'model.json'
    path.write_text(json.dumps(document))
    assert AnomalyModel.load(str(path)).threshold == pytest.approx(1e308)


# -- 10: topic patterns and rule conditions ----------------------------------------------------------------

@pytest.mark.parametrize('pattern', ['(a+)+', '(/a|/a)*', '(x*y?)*z', '(.*)*', '.*.*.*.*x', r'(/a)\1',
                                     '/' + 'a' * 300], ids=range(7))
def test_patterns_that_backtrack_badly_are_refused_with_one_line(pattern):
    from cc_log.base.topic_select import TopicSelection
    for entry in ('re:' + pattern, '!re:' + pattern):
        with pytest.raises(ValueError) as error:
            TopicSelection.parse([entry])
        assert one_line(error).startswith('topics: regular expression ')


def test_ordinary_patterns_are_kept():
    from cc_log.base.topic_select import TopicSelection
    selection = TopicSelection.parse(['re:/(camera|lidar)/.*', '!re:.*/compressed', 're:/a{2,5}/b', 're:(/ns)?/odom'])
    assert selection.select(['/camera/x', '/lidar/y', '/camera/x/compressed', '/aaa/b', '/odom', '/ns/odom',
                             '/imu']) == ['/camera/x', '/lidar/y', '/aaa/b', '/odom', '/ns/odom']


def test_a_topic_is_matched_once():
    from cc_log.base.topic_select import TopicSelection
    selection = TopicSelection(regex=['/camera/.*'], exclude=['.*/compressed'])
    calls = []

    class Counting(object):
        def __init__(self, compiled):
            self.compiled, self.pattern = compiled, compiled.pattern

        def fullmatch(self, topic):
            calls.append((self.pattern, topic))
            return self.compiled.fullmatch(topic)

    selection.regex = [Counting(p) for p in selection.regex]
    selection.exclude = [Counting(p) for p in selection.exclude]
    for _ in range(5):  # the topic watcher polls every second
        assert selection.select(['/camera/a', '/camera/a/compressed', '/odom']) == ['/camera/a']
    assert len(calls) == len(set(calls)) == 5  # each pattern tried once on each topic it had to decide


RULE_TEXTS = [  # (text, (absolute, path, op, value)) as the regular expression parsed them
    ('twist.twist.linear.x > 2.0', (False, [('twist', None), ('twist', None), ('linear', None), ('x', None)],
                                    '>', 2.0)),
    ('  abs( twist.angular.z )>=1.5 ', (True, [('twist', None), ('angular', None), ('z', None)], '>=', 1.5)),
    ('status_list[0].status == 4', (False, [('status_list', 0), ('status', None)], '==', 4.0)),
    ("status[2].text != 'ok'", (False, [('status', 2), ('text', None)], '!=', 'ok')),
    ('data<=-.5e3', (False, [('data', None)], '<=', -500.0)),
    ('data == false', (False, [('data', None)], '==', False)),
]


@pytest.mark.parametrize('text, expected', RULE_TEXTS)
def test_conditions_are_read_by_the_tokenizer_as_before(text, expected):
    from cc_log.triggers.rule import Condition
    condition = Condition(text)
    assert (condition.absolute, condition.path, condition.op_text, condition.value) == expected


@pytest.mark.parametrize('text', ['x > ' + ' ' * 100000 + 'y', 'x == "' + 'a' * 100000 + '"',
                                  'a.' * 50000 + 'b > 1', 'abs(' + ' ' * 100000, 'x[1234567890] > 1', 'x = 1',
                                  'abs(x) > nan', '1x > 2', 'x..y > 1', 'x > 1e'], ids=range(10))
def test_long_or_malformed_conditions_are_refused_with_one_line(text):
    from cc_log.triggers.rule import Condition
    with pytest.raises(ValueError) as error:
        Condition(text, 'r: when')
    assert one_line(error).startswith('r: when: ')


# -- 15: smaller ----------------------------------------------------------------------------------------------

def test_an_all_nan_odometry_stream_fires_a_nan_rule():
    nav_msgs = pytest.importorskip('nav_msgs.msg')
    from cc_log.triggers import RuleTrigger
    from cc_log.base.records import Record
    rule = RuleTrigger('odom_nan', '/odom', when='twist.twist.linear.x == nan', type='nav_msgs/Odometry')
    rule.check(nav_msgs.Odometry)
    fires = []
    for index in range(100):
        msg = nav_msgs.Odometry()
        msg.twist.twist.linear.x = float('nan') if index >= 50 else 0.5
        fires += rule.on_record(Record(index * 0.02, '/odom', msg))
    assert len(fires) == 1 and fires[0].reason.startswith('twist.twist.linear.x == nan (nan)')
    assert not RuleTrigger('ok', '/odom', when='twist.twist.linear.x != nan').condition.holds(msg)[0]


def test_a_silent_topic_rule_gives_a_topic_time_at_start_up():
    from cc_log.triggers import RuleTrigger
    from cc_log.triggers.rule import STARTUP_GRACE
    from cc_log.base.records import Record
    for rule in (RuleTrigger('dead', '/scan', silent='1s'), RuleTrigger('slow', '/scan', min_rate=5, over='1s')):
        fired = []
        for tick in range(0, int((STARTUP_GRACE - 1) * 10)):  # the topic's first message comes late
            fired += rule.on_time(100.0 + tick / 10.0)
        assert fired == [], rule.name
        for tick in range(int((STARTUP_GRACE - 1) * 10), int((STARTUP_GRACE + 5) * 10)):  # 10 Hz from then on
            rule.on_record(Record(100.0 + tick / 10.0, '/scan', None))
            fired += rule.on_time(100.0 + tick / 10.0)
        assert fired == [], rule.name
        fired += rule.on_time(100.0 + STARTUP_GRACE + 7)  # then it stops
        assert len(fired) == 1, rule.name
    never = RuleTrigger('never', '/scan', silent='1s')
    fired = [fire for tick in range(0, 100) for fire in never.on_time(100.0 + tick / 10.0)]
    assert len(fired) == 1  # a topic that never comes is still caught, after the grace


def test_info_and_stats_print_topic_names_without_terminal_escapes(tmp_path, real_bag):
    import os
    import subprocess
    import sys
    rosbag = pytest.importorskip('rosbag')
    from cc_log.storage import log_format
    from cc_log.base.records import LogWindow, Record, Trigger
    hostile = '/odom\x1b]0;owned\x07\x1b[2J\u202e'
    with rosbag.Bag(real_bag('husky_outdoor_2015.bag')) as bag:
        records = [Record(m.header.stamp.to_sec(), hostile, m) for topic, m, _ in
                   bag.read_messages(topics=['/husky_velocity_controller/odom'])][:20]
    log_format.write_window(LogWindow(records, [Trigger(records[0].stamp, 'reason \x1b[31m', -1.0)]),
                            str(tmp_path), 'json-xz')
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    for command in (['info', str(tmp_path)], ['stats', str(tmp_path), '--odom', hostile]):
        result = subprocess.run([sys.executable, os.path.join(root, 'scripts', 'cclog')] + command,
                                capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, result.stderr[-2000:]
        assert '\x1b' not in result.stdout and '\x07' not in result.stdout and '\u202e' not in result.stdout
    info = subprocess.run([sys.executable, os.path.join(root, 'scripts', 'cclog'), 'info', str(tmp_path)],
                          capture_output=True, text=True, timeout=300).stdout
    assert '/odom\\x1b]0;owned\\x07\\x1b[2J\\u202e 20' in info and 'reason \\x1b[31m' in info


def test_a_trigger_window_reason_is_logged_with_its_terminal_escapes_shown(tmp_path):
    """Issue 42 item 20: the reason of ~trigger_window (a service caller's text) reaches the node's log, its
    AnomalyEvent and /diagnostics through smart_events.reason_text, which shows its terminal escapes."""
    from cc_log.base import event_kinds
    from cc_log.logger import smart_events
    from cc_log.logger.smart import SmartLogger
    from test_heavy_windows import ODOM, feed, stream
    logger = SmartLogger(None, str(tmp_path), 'bag-lz4', '1s', '1s', driving_topic=ODOM, background=False)
    events = []
    logger.on_event(events.append)
    feed(logger, stream(1, camera_hz=1))
    ok, message = logger.trigger_now('door \x1b]0;owned\x07\x1b[2J\u202e')
    assert ok, message
    assert logger.close(30)
    opened = [event for event in events if event.kind == event_kinds.OPENED]
    assert [smart_events.reason_text(event) for event in opened] == ['door \\x1b]0;owned\\x07\\x1b[2J\\u202e']


@pytest.mark.parametrize('value', ['9' * 400 + 'GB', '9' * 5000 + 'x', 'r' * 10 ** 6], ids=['huge', 'digits', 'long'])
def test_collect_rotation_sizes_are_bounded_one_line(value):
    from cc_log.logger.collector import Rotation
    with pytest.raises(ValueError) as error:
        Rotation.parse(value, 'collect.rotate')
    assert one_line(error).startswith('collect.rotate: ')


def test_the_intake_overflow_message_says_which_bound_and_what_to_raise():
    from cc_log.nodes.intake import IntakeQueue, overflow_text
    queue = IntakeQueue(3, 1000)
    assert not queue.put('huge', 5000, topic='/camera')  # larger than the whole queue: never fits
    text = overflow_text(queue, '/camera', 5000)
    assert 'larger than the whole intake queue' in text and '~intake_max_mb' in text and 'queue full' not in text
    for _ in range(3):
        assert queue.put('small', 10, topic='/odom')
    assert not queue.put('small', 10, topic='/odom')
    text = overflow_text(queue, '/odom', 10)
    assert text.startswith('intake queue full (3 of at most 3 messages') and 'falls behind' in text
    assert '2 in all so far' in text and '\n' not in text


def test_a_json_xz_document_declares_no_more_messages_than_its_bytes_pay_for():
    import json
    import lzma
    from cc_log.storage.formats import json_xz
    assert json_xz.message_cap(None) == json_xz.MAX_DOCUMENT_MESSAGES
    assert json_xz.message_cap(1600) == 100 + json_xz.FREE_MESSAGES
    assert json_xz.message_cap(1 << 30) == json_xz.MAX_DOCUMENT_MESSAGES
    doc = {'metadata': {'layout': 2}, 'topics': [{'topic': '/a', 'count': 6000}, {'topic': '/b', 'count': 6000}]}
    data = lzma.compress(json.dumps(doc).encode())
    with pytest.raises(ValueError) as error:
        json_xz.decode(data, 'w.json.xz')
    assert str(error.value).startswith('w.json.xz: the topic sections declare 12000 messages, more than the 10')
    doc['topics'][1]['count'] = 4000  # within the cap: read on (and refused for what the sections lack)
    with pytest.raises(ValueError) as error:
        json_xz.decode(lzma.compress(json.dumps(doc).encode()), 'w.json.xz')
    assert 'declare' not in str(error.value)
