"""One configuration (YAML) for smart and collect mode, live and offline; cclog replay/collect --config."""
import json
import os
import re
import subprocess
import sys

import pytest

from cc_log.logger import config
from cc_log.learning import learning
from cc_log.storage import log_format
from cc_log.logger.config import Config
from cc_log.base.raw_message import installed_class
from cc_log.features import FeatureConfig
from cc_log.learning.model import AnomalyModel
from cc_log.triggers import ClassifierTrigger, RuleTrigger

bagio = pytest.importorskip('cc_log.storage.bag.bagio')  # needs rosbag (a sourced ROS environment)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HUSKY = 'husky_outdoor_2015.bag'
HUSKY_ODOM = '/husky_velocity_controller/odom'

EXAMPLE = """
topics: [imu/data]
driving_topic: husky_velocity_controller/odom
format: bag-lz4
windows: {pre: 1s, post: 2s, max: 5000}
limits: {max_disk_mb: 50, min_free_mb: 0, max_buffer_mb: 64}
collect: {rotate: 30s, label: drive, stride: 10}
triggers:
  - {name: motion, kind: classifier, model: MODEL, topics: [husky_velocity_controller/odom],
     classify_every: '1', retrigger: onset}
  - {name: too_fast, kind: rule, topic: husky_velocity_controller/odom, type: nav_msgs/Odometry,
     when: 'abs(twist.twist.angular.z) > 0.4', hold_off: 3s}
  - {name: motors, kind: rule, level: ERROR, status: 'motor*'}
"""


def cclog(*args):
    return subprocess.run([sys.executable, os.path.join(ROOT, 'scripts', 'cclog')] + [str(a) for a in args],
                          capture_output=True, text=True, timeout=600)


@pytest.fixture
def real_bag_path(real_bag):
    return real_bag(HUSKY)


@pytest.fixture(scope='module')
def model_path(tmp_path_factory):
    """A motion model (2 s window) trained on the first half of the Husky odometry."""
    from conftest import REAL_DATA
    config_ = FeatureConfig('motion', '2s')
    _, X = bagio.feature_vectors(os.path.join(REAL_DATA, HUSKY), HUSKY_ODOM, config_, 5)  # missing: fails
    model, _ = learning.train(X[:len(X) // 2], config=config_)
    path = str(tmp_path_factory.mktemp('model') / 'motion.json')
    model.save(path)
    return path


def write(tmp_path, text, name='robot.yaml'):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_a_configuration_file_is_checked_and_builds_every_trigger(tmp_path, model_path):
    data = config.load_file(write(tmp_path, EXAMPLE.replace('MODEL', model_path)))
    cfg = Config.from_dict(data, 'robot.yaml')
    assert (str(cfg.pre), str(cfg.post), str(cfg.max_window), cfg.format) == ('1s', '2s', '5000', 'bag-lz4')
    assert (cfg.max_disk_mb, cfg.max_buffer_mb, cfg.rotate, cfg.label, cfg.stride) == (50.0, 64.0, '30s', 'drive', 10)
    triggers = cfg.build_triggers(AnomalyModel.load, installed_class)
    assert [type(t) for t in triggers] == [ClassifierTrigger, RuleTrigger, RuleTrigger]
    motion, fast, motors = triggers
    assert motion.topic == HUSKY_ODOM and str(motion.classify_every) == '1' and motion.retrigger == 'onset'
    assert fast.topic == HUSKY_ODOM and fast.hold_off == 3.0 and motors.topic == '/diagnostics'
    options = cfg.logger_options(triggers)
    assert options['driving_topic'] == HUSKY_ODOM and options['side_topics'] == ['/imu/data']
    assert [name for name, _, _ in cfg.feature_specs(AnomalyModel.load)] == ['motion']
    assert cfg.feature_specs(AnomalyModel.load)[0][1] == FeatureConfig('motion', '2s')  # the model's


@pytest.mark.parametrize('text, message', [
    ('windows: {pre: 1s, psot: 2s}', "windows: unknown key 'psot' (did you mean 'post'? known: pre, post"),
    ('topic: [a]', "unknown key 'topic' (did you mean 'topics'? known: topics, topic_limits, driving_topic"),
    ('zzz: 1', "unknown key 'zzz' (known: topics,"),  # nothing near: no suggestion
    ('triggers: [{name: x, kind: alarm}]', "triggers[0] (x): kind: 'alarm' is not one of classifier, rule, "
                                           'manual'),
    ('triggers: [{kind: classifier, feature_set: pixels}]', "triggers[0] (classifier): feature_set: 'pixels' is "
                                                            'not one of motion, raw, imu, command, progress, dynamics'),
    ('triggers: [{name: r, kind: rule, topic: odom, whenn: "a > 1"}]',
     "triggers[0] (r): unknown key 'whenn' (did you mean 'when'?"),
    ('triggers: [{name: r, kind: rule, topic: odom, arrival: true}, {name: r, kind: manual}]',
     "triggers[1]: name 'r' is used twice"),
    ('format: zip', "format: 'zip' is not one of: bag-lz4, json-xz"),
    ("json_xz: {precision: {'pose.*': 0}}", "json_xz.precision: pose.*: step 0 is not a number > 0"),
    ("json_xz: {precision: [1e-4]}", "json_xz.precision: a mapping of field patterns to steps"),
    ("json_xz: {level: 3}", "json_xz: unknown key 'level'"),
    ("format: bag-lz4\njson_xz: {precision: {'pose.*': 1e-4}}", "json_xz.precision: rounds json-xz windows only"),
    ("json_xz: {precision: 'pose.*: 1e-4'}", "json_xz.precision: 'pose.*: 1e-4' is not \"pattern=step"),
    ('limits: {max_disk_mb: -1}', 'limits.max_disk_mb: -1 is outside 1e-06..1e+09 MB (or 0: off)'),
    ('limits: {max_buffer_mb: 2XB}', "limits.max_buffer_mb: '2XB' is not a size (MB as a number, or 64MB"),
    ('collect: {label: "../x"}', "label: '../x' must be letters"),
    ('windows: {pre: soon}', "windows.pre: 'soon' is not a message count"),
    ('[1, 2]', 'a configuration is a mapping of topics'),
    ('topics: {a: 1', 'not YAML'),
    ('!!python/object/apply:os.system ["touch /tmp/cc_log_yaml_pwned"]', 'not YAML'),
])
def test_a_bad_configuration_fails_at_start_with_one_line_naming_what(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(ValueError) as error:
        Config.from_dict(config.load_file(path), path)
    assert message in str(error.value) and '\n' not in str(error.value), str(error.value)
    assert str(error.value).startswith(path + ': ')
    assert not os.path.exists('/tmp/cc_log_yaml_pwned')


@pytest.mark.parametrize('trigger, message', [
    ('{name: r, kind: rule, topic: odom, type: nav_msgs/Odometry, when: "twist.linear.x > 1"}',
     "triggers[0] (r): when: nav_msgs/Odometry.twist has no field 'linear'"),
    ('{name: r, kind: rule, topic: odom, type: nav_msgs/Odometree, when: "a > 1"}',
     "triggers[0] (r): type: unknown message type 'nav_msgs/Odometree' (not installed)"),
    ('{name: r, kind: rule, topic: odom, when: "a >> 1"}', 'triggers[0] (r): when: '),
    ('{name: c, kind: classifier}', 'triggers[0] (c): model: required'),
    ('{name: c, kind: classifier, model: /nonexistent/m.json}', 'triggers[0] (c): model: /nonexistent/m.json: '),
    ('{name: c, kind: classifier, model: MODEL, window: "3s"}', "triggers[0] (c): window: 3s does not match"),
    ('{name: c, kind: classifier, model: MODEL, topics: [a, b]}', 'triggers[0] (c): topics: the motion feature '
                                                                  'set reads 1 topic(s)'),
    ('{name: c, kind: classifier, model: MODEL, recent: 5}', 'triggers[0] (c): recent: 5 must be a positive '
                                                             'duration like the feature window 2s'),
    ('{name: c, kind: classifier, model: MODEL, recent: 3s}', 'triggers[0] (c): recent: 3s is longer than the '
                                                              'feature window 2s'),
    ('{name: c, kind: classifier, model: MODEL, recent: soon}', 'triggers[0] (c): recent: '),
])
def test_triggers_that_cannot_be_built_fail_naming_the_trigger(tmp_path, model_path, trigger, message):
    cfg = Config.from_dict(config.load_file(write(tmp_path, 'triggers: [%s]' % trigger.replace('MODEL', model_path))),
                           'robot.yaml')
    with pytest.raises(ValueError) as error:
        cfg.build_triggers(AnomalyModel.load, installed_class)
    assert str(error.value).startswith('robot.yaml: ' + message) and '\n' not in str(error.value), str(error.value)


def test_parameters_override_the_file_and_the_single_classifier_joins_it(tmp_path, model_path):
    data = config.load_file(write(tmp_path, EXAMPLE.replace('MODEL', model_path)))
    data = config.merge(data, {'windows': {'post': '5s'}, 'topics': ['scan']})  # `rosparam load`-ed keys
    data = config.with_flat(data, {'pre': '300', 'format': None, 'max_buffer_mb': 0.0})
    data = config.with_classifier(data, model=model_path, classify_every='100ms', retrigger='every', recent='0.3s')
    cfg = Config.from_dict(data)
    assert (str(cfg.pre), str(cfg.post), cfg.format, cfg.max_buffer_mb, cfg.topics) == \
        ('300', '5s', 'bag-lz4', 0.0, ['scan'])
    triggers = cfg.build_triggers(AnomalyModel.load, installed_class)
    assert [t.name for t in triggers] == ['classifier', 'motion', 'too_fast', 'motors']
    assert triggers[0].topic == '/odom'  # the motion set's role name, resolved as a global name
    assert [(str(t.classify_every), t.retrigger, str(t.recent)) for t in triggers[:2]] == \
        [('0.1s', 'every', '0.3s')] * 2
    resolved = cfg.build_triggers(AnomalyModel.load, installed_class, resolve=lambda t: '/robot1/' + t.lstrip('/'))
    assert resolved[1].topic == '/robot1/husky_velocity_controller/odom'


def test_the_model_file_decides_the_default_trigger_an_envelope_or_the_classifier(tmp_path, model_path):
    """Where a model enters as the default trigger (``with_classifier``: ~model, cclog replay --model), an
    envelope file builds the envelope trigger on its odometry topic, a model file the classifier; any other file
    is one line naming it."""
    import numpy as np
    from cc_log.learning import envelope
    from cc_log.features.envelope import ENVELOPE_COLUMNS
    from cc_log.triggers.envelope import EnvelopeTrigger
    rng = np.random.default_rng(0)
    learned = envelope.learn([rng.uniform(0.1, 1.0, (200, len(ENVELOPE_COLUMNS)))], HUSKY_ODOM, 1.0, 0.25, 50.0)
    limits = str(tmp_path / 'envelope.json')
    learned.save(limits)
    assert (config.model_kind(limits), config.model_kind(model_path)) == ('envelope', 'classifier')
    for given, resolve, topic in (({}, config.global_name, HUSKY_ODOM),
                                  ({'topics': ['odom']}, lambda t: '/robot1/' + t.lstrip('/'), '/robot1/odom')):
        data = config.with_classifier({'triggers': [{'name': 'too_fast', 'kind': 'rule', 'topic': 'odom',
                                                     'arrival': True}]},
                                      model=limits, classify_every='100ms', retrigger='every', **given)
        triggers = Config.from_dict(data).build_triggers(AnomalyModel.load, installed_class, resolve=resolve)
        assert [(t.name, type(t)) for t in triggers] == [('envelope', EnvelopeTrigger), ('too_fast', RuleTrigger)]
        assert triggers[0].topic == topic and triggers[0].envelope == learned and triggers[0].joint is not None
    triggers = Config.from_dict(config.with_classifier({}, model=model_path)).build_triggers(
        AnomalyModel.load, installed_class)
    assert [(t.name, type(t)) for t in triggers] == [('classifier', ClassifierTrigger)]
    for path in (write(tmp_path, '{"kind": "notes"}', 'notes.json'), write(tmp_path, 'not json', 'text.json')):
        with pytest.raises(ValueError) as error:
            config.with_classifier({}, model=path)
        assert str(error.value) == '%s: not a cc_log model nor an envelope file (cclog learn or cclog ' \
            'learn-envelope writes one)' % path
    for extra, said in (({'window': '2s'}, 'window: %s is an envelope file (cclog learn-envelope): its' % limits),
                        ({'topics': ['a', 'b']}, 'topics: the envelope of %s reads one odometry topic' % limits)):
        with pytest.raises(ValueError, match='^' + re.escape(said)):
            config.with_classifier({}, model=limits, **extra)
    assert config.model_kind(str(tmp_path / 'missing.json')) == 'classifier'   # its reader says what is wrong


def test_cclog_replay_with_a_configuration_runs_every_trigger_and_sets_retrigger_and_classify_every(
        tmp_path, model_path, real_bag_path):
    text = EXAMPLE.replace('MODEL', model_path).replace('format: bag-lz4', 'format: json-xz')
    text = text.replace('  - {name: motors, kind: rule, level: ERROR, status: \'motor*\'}\n', '')
    path = write(tmp_path, text)
    result = cclog('replay', real_bag_path, '--config', path, '--out', tmp_path / 'logs', '--json')
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    names = set()
    for window in summary['windows']:
        metadata, records = log_format.read_window(window['path'])
        names.update(metadata['names'])
        assert metadata['pre'] == '1s' and metadata['post'] == '2s'
        assert {r.topic for r in records} <= {HUSKY_ODOM, '/imu/data'}
        for trigger in metadata['triggers']:
            assert trigger['name'] in ('motion', 'too_fast', 'manual')
    assert names == {'motion', 'too_fast'}
    # the same with the options that override the file: classify every 10th message, every anomalous score
    again = cclog('replay', real_bag_path, '--config', path, '--out', tmp_path / 'again', '--json',
                  '--classify-every', '10', '--retrigger', 'every', '--post', '0.5s')
    assert again.returncode == 0, again.stderr
    found = [log_format.read_window(w['path'])[0] for w in json.loads(again.stdout)['windows']]
    infos = [metadata['trigger_info']['motion'] for metadata in found if 'motion' in metadata['trigger_info']]
    assert infos and all((info['classify_every'], info['retrigger']) == ('10', 'every') for info in infos)
    assert all(metadata['post'] == '0.5s' for metadata in found)


def test_cclog_replay_needs_a_model_or_a_configuration(tmp_path, real_bag_path, model_path):
    result = cclog('replay', real_bag_path, '--out', tmp_path / 'logs')
    assert result.returncode == 1 and result.stderr.strip() == \
        'cclog replay: error: replay: give --model (and --topic), or --config (a configuration with triggers)'
    bad = write(tmp_path, 'triggers: [{name: r, kind: rule, topic: /odom, level: LOUD}]')
    result = cclog('replay', real_bag_path, '--config', bad, '--out', tmp_path / 'logs')
    assert result.returncode == 1 and result.stderr.count('\n') == 1
    assert "%s: triggers[0] (r): level: 'LOUD' is not one of" % bad in result.stderr


def test_cclog_collect_with_a_configuration_writes_vectors_of_every_classifier(tmp_path, real_bag_path):
    path = write(tmp_path, """
collect: {label: drive, stride: 20}
triggers:
  - {name: motion, kind: classifier, model: /nowhere/yet.json, window: 2s, topics: [husky_velocity_controller/odom]}
  - {name: progress, kind: classifier, feature_set: progress, window: 4s, topics: [husky_velocity_controller/odom]}
  - {name: shock, kind: classifier, feature_set: imu, window: 1s, topics: [imu/data]}
  - {name: too_fast, kind: rule, topic: odom, arrival: true}
""")
    result = cclog('collect', real_bag_path, '--config', path, '--out', tmp_path / 'vectors', '--json')
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert list(summary['sets']) == ['motion', 'progress', 'shock']
    for name, feature_set in (('motion', 'motion'), ('progress', 'progress'), ('shock', 'imu')):
        entry = summary['sets'][name]
        assert entry['directory'] == str(tmp_path / 'vectors' / name / 'drive') and entry['vectors'] > 10
        vectors, loaded = learning.load_vectors(str(tmp_path / 'vectors' / name))
        assert loaded.feature_set == feature_set and len(vectors['drive']) == entry['vectors']


def test_a_node_reads_the_file_then_its_structured_parameters_then_the_flat_ones(tmp_path, model_path):
    pytest.importorskip('rospy')
    from cc_log.nodes.node_common import ConfigError, Params, node_config
    path = write(tmp_path, EXAMPLE.replace('MODEL', model_path))
    values = {'config': path, 'windows': {'post': '3s'}, 'triggers': [
        {'name': 'bump', 'kind': 'rule', 'topic': 'bumper', 'arrival': True}]}
    cfg = node_config(Params(get=values.get, log=lambda *args: None), {'pre': '20', 'post': None},
                      {'model': model_path})
    assert (str(cfg.pre), str(cfg.post), cfg.format, cfg.label) == ('20', '3s', 'bag-lz4', 'drive')
    assert [t['name'] for t in cfg.triggers] == ['classifier', 'bump']  # ~triggers replaces the file's list
    values = {'config': str(tmp_path / 'missing.yaml')}
    with pytest.raises(ConfigError, match=r'^~config: .*missing.yaml: cannot read'):
        node_config(Params(get=values.get, log=lambda *args: None), {})
    values = {'config': path, 'windows': {'pre': 'never'}}
    with pytest.raises(ConfigError, match=r"^~config .*robot.yaml: windows.pre: 'never' is not"):
        node_config(Params(get=values.get, log=lambda *args: None), {})


def test_the_example_configuration_is_valid(tmp_path):
    cfg = Config.from_dict(config.load_file(os.path.join(ROOT, 'config', 'example.yaml')), 'example.yaml')
    assert [t['name'] for t in cfg.triggers] == ['motion', 'stuck', 'shock', 'motors', 'goal_aborted', 'too_fast',
                                                 'bumper', 'scan_dead']
    specs = cfg.feature_specs()
    assert [(name, c.feature_set, c.window, topics) for name, c, topics in specs] == [
        ('motion', 'motion', config.DEFAULT_WINDOW, ['/odom']), ('stuck', 'command', '2s', ['/odom', '/cmd_vel']),
        ('shock', 'imu', '1s', ['/imu/data'])]
    rules = Config.from_dict({'triggers': [dict((k, v) for k, v in t.items() if k != 'index')
                                           for t in cfg.triggers if t['kind'] == 'rule']})
    built = rules.build_triggers(AnomalyModel.load, installed_class)  # fields checked against installed types
    assert [t.topic for t in built] == ['/diagnostics', '/move_base/status', '/odom', '/bumper', '/scan']


def test_collect_mode_live_writes_the_same_vectors_of_every_classifier_as_cclog_collect(tmp_path, real_bag_path):
    """Collector with a configuration's classifiers (the collect node's path) against collect_bag (cclog
    collect --config): the same vector files, in features/<name>/<label>/."""
    from cc_log.logger.collector import Collector, collect_bag
    cfg = Config.from_dict({'triggers': [
        {'name': 'motion', 'kind': 'classifier', 'feature_set': 'motion', 'window': '2s', 'topics': [HUSKY_ODOM]},
        {'name': 'shock', 'kind': 'classifier', 'feature_set': 'imu', 'window': '1s', 'topics': ['/imu/data']}]})
    specs = cfg.feature_specs()
    collector = Collector(str(tmp_path / 'live'), rotate='1000', feature_specs=specs, driving_topic=None,
                          stride=20, side_topics=[])
    assert collector.driving_topic == HUSKY_ODOM and collector.side_topics == {'/imu/data'}
    for record in bagio.read_messages(real_bag_path, [HUSKY_ODOM, '/imu/data']):
        collector.on_message(record.topic, record.msg, record.stamp)
    assert collector.close(60)
    offline = collect_bag(real_bag_path, None, str(tmp_path / 'offline'), stride=20, feature_specs=specs)
    for name, _, _ in specs:
        live = sorted(os.listdir(str(tmp_path / 'live' / 'features' / name / 'nominal')))
        assert live and live == sorted(os.listdir(offline['sets'][name][1])), name
    assert collector.stats()['vectors_written'] == sum(count for count, _ in offline['sets'].values())


def test_json_xz_precision_from_the_file_and_from_cclog_replay(tmp_path, model_path, real_bag_path):
    """json_xz.precision (opt-in lossy) reaches the written windows: recorded in their metadata, every
    matching field within half a step of the bag's value; --precision overrides the file."""
    text = EXAMPLE.replace('MODEL', model_path).replace('format: bag-lz4', 'format: json-xz')
    text = text.replace('  - {name: motors, kind: rule, level: ERROR, status: \'motor*\'}\n', '')
    text += "json_xz: {precision: {'pose.pose.position.*': 1e-4}}\n"
    path = write(tmp_path, text)
    assert Config.from_dict(config.load_file(path)).format_options() == \
        {'precision': {'pose.pose.position.*': 1e-4}}
    bag = {}
    with __import__('rosbag').Bag(real_bag_path) as reader:
        for _, msg, _ in reader.read_messages(topics=[HUSKY_ODOM]):
            bag[msg.header.seq] = msg
    for extra, step in (((), 1e-4), (('--precision', 'pose.pose.position.*=1e-3, twist.twist.*=1e-5'), 1e-3)):
        out = tmp_path / ('logs%s' % step)
        result = cclog('replay', real_bag_path, '--config', path, '--out', out, '--json', *extra)
        assert result.returncode == 0, result.stderr
        windows = json.loads(result.stdout)['windows']
        assert windows
        for window in windows:
            metadata, records = log_format.read_window(window['path'])
            assert metadata['precision']['pose.pose.position.*'] == step
            for record in records:
                if record.topic != HUSKY_ODOM:
                    continue
                original = bag[record.msg.header.seq]
                for axis in 'xyz':
                    value = getattr(record.msg.pose.pose.position, axis)
                    assert abs(value - getattr(original.pose.pose.position, axis)) <= step / 2 * (1 + 1e-9)
                    assert abs(value / step - round(value / step)) < 1e-6
                if extra:
                    assert abs(record.msg.twist.twist.linear.x - original.twist.twist.linear.x) <= 0.5e-5 * 1.001
                else:
                    assert record.msg.twist.twist.linear.x == original.twist.twist.linear.x  # not rounded


def test_a_node_precision_parameter_overrides_the_file(tmp_path, model_path):
    pytest.importorskip('rospy')
    from cc_log.nodes.node_common import ConfigError, Params, node_config
    text = EXAMPLE.replace('MODEL', model_path).replace('format: bag-lz4', 'format: json-xz')
    path = write(tmp_path, text + "json_xz: {precision: {'pose.pose.position.*': 1e-4}}\n")
    params = Params(get={'config': path}.get, log=lambda *args: None)
    assert node_config(params, {'precision': None}).precision == {'pose.pose.position.*': 1e-4}
    cfg = node_config(params, {'precision': 'pose.pose.position.*=1e-3, twist.twist.*=1e-5'})
    assert cfg.logger_options([])['format_options'] == {'precision': {'pose.pose.position.*': 1e-3,
                                                                      'twist.twist.*': 1e-5}}
    with pytest.raises(ConfigError, match=r'json_xz.precision: pose.pose.position.\*: step -1.0 is not a number > 0'):
        node_config(params, {'precision': {'pose.pose.position.*': -1.0}})


def test_limits_take_a_number_of_mb_or_a_size_with_a_unit(tmp_path):
    path = write(tmp_path, 'limits: {max_disk_mb: 2GB, min_free_mb: 500kB, max_buffer_mb: 1.5GiB}')
    cfg = Config.from_dict(config.load_file(path), path)
    assert (cfg.max_disk_mb, cfg.min_free_mb) == (2000.0, 0.5)
    assert cfg.max_buffer_mb == pytest.approx(1.5 * 1024 ** 3 / 1e6)
    plain = Config.from_dict(config.load_file(write(tmp_path, 'limits: {max_disk_mb: 64}')), path)
    assert plain.max_disk_mb == 64.0


# -- a trigger's keep: the grammar of topics ----------------------------------------------------------------

@pytest.fixture(scope='module')
def imu_run(tmp_path_factory):
    """A simulated half minute with odometry, IMU and scans: the bag's path and topics."""
    from cc_log import sim
    from cc_log.storage.bag import bagio
    bag = str(tmp_path_factory.mktemp('keep') / 'run.bag')
    sim.simulate_to_bag(bag, sim.SimConfig(seed=3, minutes=0.5, anomalies=0, imu=True, scan=True))
    opened = bagio.open_bag(bag, skip_index=True)
    try:
        topics = set(bagio.topics_of(opened))
    finally:
        opened.close()
    assert topics == {'/odom', '/imu/data', '/scan'}
    return bag, topics


def kept_topics(tmp_path, bag, keep, topics=('*',)):
    """The topics of every window a periodic trigger with ``keep`` opened in a replay of ``bag``."""
    from cc_log import sim
    from cc_log.offline import replay
    cfg = Config.from_dict({'driving_topic': sim.ODOM_TOPIC, 'topics': list(topics), 'windows': {'pre': 2, 'post': 2},
                            'triggers': [{'name': 'every10s', 'kind': 'periodic', 'every': '10s', 'keep': keep}]})
    out = str(tmp_path / 'out')
    summary = replay.replay_one(bag, out, cfg)
    assert summary['windows']
    return [set(log_format.read_window_set(files)[0]['topics'])
            for files in log_format.window_sets(log_format.window_files(out))]


@pytest.mark.parametrize('keep, wanted', [(['re:/imu/.*'], {'/odom', '/imu/data'}),
                                          (['*'], {'/odom', '/imu/data', '/scan'}),
                                          (['*', '!/imu/data'], {'/odom', '/scan'}),
                                          ('scan', {'/odom', '/scan'})])
def test_keep_patterns_mean_what_they_mean_in_topics(tmp_path, imu_run, keep, wanted):
    bag, topics = imu_run
    kept = kept_topics(tmp_path, bag, keep)
    assert kept and all(window == wanted for window in kept), (kept, wanted)


@pytest.mark.parametrize('topics', [['*'], ['imu/data']])
def test_keep_names_a_topic_the_bag_lacks_and_replay_says_so(tmp_path, imu_run, topics):
    # topic names are case-sensitive: /IMU/data is not /imu/data; a window cannot keep a topic never read
    with pytest.raises(ValueError, match=r'topic /IMU/data is not in the bag; its topics: .*/imu/data'):
        kept_topics(tmp_path, imu_run[0], ['/IMU/data'], topics)


def test_keep_names_are_subscribed_like_topics():
    cfg = Config.from_dict({'driving_topic': 'odom', 'topics': ['scan'], 'triggers': [
        {'name': 'bumper', 'kind': 'rule', 'topic': 'bumper', 'arrival': True, 'keep': ['camera', 're:/imu/.*']}]})
    options = cfg.logger_options(cfg.build_triggers(None, lambda _: None))
    assert options['side_topics'] == ['/scan', '/camera']
    assert options['keep']['bumper'].matches('/imu/data') and not options['keep']['bumper'].matches('/scan')


def test_route_names_are_subscribed_like_topics():
    # a route's topic is listened to even when ``topics`` does not name it: else its file stays empty, silently
    cfg = Config.from_dict({'driving_topic': 'odom', 'topics': ['scan'], 'format': 'bag-lz4', 'routes': [
        {'name': 'numeric', 'topics': ['imu/data', 're:/joint_.*'], 'format': 'json-xz'}]})
    options = cfg.logger_options(cfg.build_triggers(None, lambda _: None))
    assert options['side_topics'] == ['/scan', '/imu/data']


def routed_topics(tmp_path, bag, route_topics, topics):
    """``[(topics of the window's own file, topics of its route file)]`` of a replay of ``bag`` whose route
    ``numeric`` takes ``route_topics`` (json-xz) while ``topics`` lists what else to keep."""
    from cc_log import sim
    from cc_log.offline import replay
    cfg = Config.from_dict({'driving_topic': sim.ODOM_TOPIC, 'topics': list(topics), 'windows': {'pre': 2, 'post': 2},
                            'format': 'bag-lz4', 'routes': [{'name': 'numeric', 'topics': route_topics,
                                                             'format': 'json-xz'}],
                            'triggers': [{'name': 'every10s', 'kind': 'periodic', 'every': '10s'}]})
    out = str(tmp_path / 'out')
    assert replay.replay_one(bag, out, cfg)['windows']
    found = []
    for files in log_format.window_sets(log_format.window_files(out)):
        metadatas = [log_format.read_window(path)[0] for path in files]
        by_route = dict((metadata.get('route'), set(metadata['topics'])) for metadata in metadatas)
        found.append((by_route.get(None, set()), by_route.get('numeric', set())))
    return found


def test_a_topic_named_only_by_a_route_is_kept_in_the_route_file(tmp_path, imu_run):
    found = routed_topics(tmp_path, imu_run[0], ['imu/data'], ['scan'])
    assert found and all(own == {'/odom', '/scan'} and routed == {'/imu/data'} for own, routed in found), found


def test_a_route_naming_a_topic_the_bag_lacks_routes_nothing_and_replay_says_so(tmp_path, imu_run, capsys):
    # a route is where a topic goes when it comes (the README's routes /diagnostics), not a topic a window needs:
    # the replay goes on, and its summary names what no message came on
    from cc_log.offline import cli
    found = routed_topics(tmp_path, imu_run[0], ['/IMU/data', 'imu/data'], ['scan'])
    assert found and all(routed == {'/imu/data'} for _, routed in found), found
    config = tmp_path / 'routes.yaml'
    config.write_text("driving_topic: odom\ntopics: [scan]\nformat: bag-lz4\n"
                      "routes: [{name: numeric, topics: [/IMU/data], format: json-xz}]\n"
                      "triggers: [{name: every10s, kind: periodic, every: 10s}]\n")
    capsys.readouterr()
    assert cli.main(['replay', imu_run[0], '--config', str(config), '--out', str(tmp_path / 'cli')]) == 0
    assert '  routes: /IMU/data is not in the bag; nothing was routed there' in capsys.readouterr().out.splitlines()


@pytest.mark.parametrize('keep', [['/imu/*'], ['regex:/imu/.*'], 'imu/data /IMU?', [''], ['re:(']])
def test_a_keep_entry_of_no_known_grammar_is_refused_in_one_line(keep):
    with pytest.raises(ValueError, match=r'^config: triggers\[0\] \(bumper\): keep: [^\n]+$'):
        Config.from_dict({'triggers': [{'name': 'bumper', 'kind': 'rule', 'topic': 'b', 'arrival': True,
                                        'keep': keep}]})
