"""rosrun cc_log record: rosbag record's flags mapped onto the nodes' parameters."""
import os
import subprocess
import sys

import pytest

from cc_log.nodes import record_main
from cc_log.nodes.record_main import parse, parse_duration, parse_size


def test_sizes_and_durations_as_rosbag_writes_them():
    assert parse_size('1G') == 1 << 30 and parse_size('500M') == 500 << 20 and parse_size('100k') == 100 << 10
    assert parse_size('2048') == 2048
    assert parse_duration('30') == 30 and parse_duration('5m') == 300 and parse_duration('2h') == 7200
    for bad in ('lots', '-1G'):
        with pytest.raises(ValueError, match='^min-space: '):
            parse_size(bad)
    with pytest.raises(ValueError, match='^duration: '):
        parse_duration('0')


def test_rosbag_record_flags_map_onto_the_node_parameters(tmp_path):
    model = tmp_path / 'model.json'
    model.write_text('{}')
    module, params, note, stop, publish, said = parse(['-a', '-x', '/camera/.*', '-o', str(tmp_path) + '/', '--lz4',
                                                       '--split', '--duration', '5m', '-L', '2G', '-b', '0',
                                                       '--model', str(model), '--context', 'odom:1', '-p'])
    assert module == 'smart_node' and note == '' and stop == {} and publish is True and said == ()
    assert 'name_prefix' not in params  # -o DIRECTORY/: cc_log_<UTC>_<reason>.bag in it
    assert params['topics'] == ['*', '!re:/camera/.*']
    assert params['directory'] == str(tmp_path) and params['format'] == 'bag-lz4'
    assert params['rotate'] == '300s' and params['context_rotate'] == 300.0
    assert params['min_free_mb'] == pytest.approx(2 * 2 ** 30 / 1e6)
    assert params['intake_max_mb'] == record_main.UNLIMITED_MB and params['model'] == str(model)


def test_split_size_is_rosbags_mb_and_splits_smart_windows(tmp_path):
    model = tmp_path / 'model.json'
    model.write_text('{}')
    module, params, _, stop, _, _ = parse(['/odom', '/camera/image_raw', '--split', '--size', '100', '--model',
                                           str(model)])
    assert module == 'smart_node' and stop == {} and 'rotate' not in params and 'context_rotate' not in params
    assert params['split_mb'] == pytest.approx(100 * 2 ** 20 / 1e6)  # rosbag record's MB: 1048576 bytes
    for size, megabytes in (('1G', 2 ** 30 / 1e6), ('500MB', 500.0), ('2.5', 2.5 * 2 ** 20 / 1e6)):
        assert record_main.parse_split_size(size) == pytest.approx(megabytes)
    _, params, _, _, _, _ = parse(['/odom', '--split', '--size', '64', '--duration', '10m', '--context', 'odom:1',
                                   '--model', str(model)])
    assert params['split_mb'] == pytest.approx(64 * 2 ** 20 / 1e6) and params['context_rotate'] == 600.0
    from cc_log.logger import options  # the node reads it as its own option
    assert options.get('split_mb').parse(params['split_mb']) == pytest.approx(params['split_mb'])
    assert 'split_mb' in [option.name for option in options.for_node('smart')]


def test_without_a_model_it_collects_and_says_why(tmp_path):
    module, params, note, stop, publish, _ = parse(['-e', '/scan.*', '/imu/.*', '-o', 'out/', '--duration', '20',
                                                    '--model', str(tmp_path / 'none.json'), '--context',
                                                    'odom:1 amcl_pose'])
    assert publish is False
    assert module == 'collect_node' and 'no model yet' in note
    assert params['topics'] == ['re:/scan.*', 're:/imu/.*'] and 'rotate' not in params
    assert stop == {'seconds': 20.0}  # --duration without --split: stop after it, as rosbag
    assert params['directory'] == os.path.abspath('out') and params['context_topics'] == 'odom:1 amcl_pose'
    assert params['min_free_mb'] == pytest.approx(2 ** 30 / 1e6)  # rosbag's default -L 1G


@pytest.mark.parametrize('argv, message', [
    ([], 'no topics given'),
    (['/odom', '--split'], '--split needs --duration'),
    (['/odom', '--bogus'], 'unrecognized arguments: --bogus'),
    (['/odom', '-o', '/data/run', '-O', 'run.bag'], 'argument -O/--output-name: not allowed with argument -o'),
    (['/odom', '-o', '/data/.run'], "-o: '.run' must be a plain part of a file name"),
    (['/odom', '-o', '/data/ru\x01n'], "-o: 'ru\\x01n' must be a plain part of a file name"),
    (['/odom', '-O', '/data/'], "-O: '/data/' names a directory, not a file"),
    (['/odom', '--max-splits', '0'], '--max-splits: 0 must be a number of files >= 1'),
    (['/odom', '--chunksize', '0'], '--chunksize: 0 must be a number of KB >= 1'),
    (['/odom', '--size', '0'], '--size: 0 must be a size > 0'),
    (['/odom', '--split', '--size', '20'], '--size: collect mode rotates its files with --split --duration'),
    (['/odom', '--split', '--size', '0', '--mode', 'smart'], '--size: 0 must be a size > 0'),
    (['/odom', '--split', '--size', 'big', '--mode', 'smart'], '--size: '),
    (['/odom', '--split', '--duration', '5', '--mode', 'smart'], '--split --duration: smart mode writes one file per'),
    (['/odom', '--udp'], '--udp: not supported: rospy subscribes over TCPROS only'),
    (['/odom', '--repeat-latched'], '--repeat-latched: not supported'),
    (['-a', '-l', '5'], '--limit: needs the topics named'),
    (['/odom', '-l', '0'], '--limit: 0 must be'),
    (['/odom', '-L', 'much'], 'min-space'),
    (['/odom', '--mode', 'fast'], 'invalid choice'),
])
def test_bad_flags_are_one_line(argv, message, capsys):
    argv = argv + ['--model', '/nonexistent/model.json'] if '--mode' not in argv else argv
    assert record_main.main(['record'] + argv) == 2
    err = capsys.readouterr().err
    assert err.startswith('record: error: ') and message in err and len(err.strip().splitlines()) == 1


def test_private_arguments_are_settings_not_parameters():
    settings, rest = record_main.command_line_settings(['_pre:=2s', '_max_disk_mb:=500', '__name:=rec', 'odom:=/o'])
    assert settings == {'pre': '2s', 'max_disk_mb': 500} and rest == ['__name:=rec', 'odom:=/o']
    with pytest.raises(ValueError):
        record_main.command_line_settings(['_topics:=[unclosed'])


def test_the_default_name_is_anonymous_as_rosbag_s():
    first, second = record_main.anonymous_name(), record_main.anonymous_name()
    assert first.startswith('record_%d_' % os.getpid()) and second.startswith('record_')


def test_limit_and_node_flags(tmp_path):
    plan = parse(['/odom', 'imu/data', '-l', '100', '--model', str(tmp_path / 'none.json')])
    assert plan.stop == {'limit': 100, 'topics': ['/odom', 'imu/data']}
    plan = parse(['--node', '/move_base', '--model', str(tmp_path / 'none.json')],
                 {'/move_base': ['/odom', '/scan']}.get)
    assert plan.params['topics'] == ['/odom', '/scan']
    with pytest.raises(ValueError, match='^--node: /nobody subscribes to no topic'):
        parse(['--node', '/nobody'], {}.get)
    plan = parse(['-e', 'cam.*', '--node', '/move_base', '--model', str(tmp_path / 'none.json')],
                 {'/move_base': ['/odom', '/a.b']}.get)  # with -e, NODE's topics as patterns of their exact names
    from cc_log.base.topic_select import TopicSelection
    selection = TopicSelection.parse(plan.params['topics'], 'topics')
    assert [selection.matches(topic) for topic in ('/odom', '/a.b', '/axb', '/odom\n', 'camera')] == [
        True, True, False, False, True]


def test_help_is_plain_text(capsys):
    with pytest.raises(SystemExit) as leaving:
        record_main.main(['record', '--help'])
    out = capsys.readouterr().out
    assert leaving.value.code == 0 and 'usage: rosrun cc_log record' in out and '``' not in out
    assert '--duration' in out and '-O NAME, --output-name NAME' in out and '--udp (rospy has no UDPROS)' in out


@pytest.mark.parametrize('script', ['smart_logger.py', 'collect_logger.py', 'sim_bwibot.py', 'record_node.py'])
def test_node_scripts_print_help_without_starting(script):
    """--help prints the node's documentation and exits 0, with no master to reach (it would wait for one)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, ROS_MASTER_URI='http://127.0.0.1:9')  # nothing listens there
    done = subprocess.run([sys.executable, os.path.join(root, 'scripts', script), '--help'], env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, timeout=20)
    assert done.returncode == 0, done.stderr[-500:]
    assert done.stdout.startswith('usage: rosrun cc_log %s ' % script) and '``' not in done.stdout
    assert 'Parameters' in done.stdout or 'parameters' in done.stdout


def test_a_configuration_with_its_own_triggers_gets_no_default_model(tmp_path):
    config = tmp_path / 'periodic.yaml'
    config.write_text('driving_topic: odom\ntriggers: [{name: every2s, kind: periodic, every: 2s}]\n')
    module, params, _, _, _, _ = parse(['/odom', '--mode', 'smart', '--config', str(config)])
    assert module == 'smart_node' and 'model' not in params  # (the default model would add a classifier)
    module, params, _, _, _, _ = parse(['/odom', '--model', str(tmp_path / 'none.json')])
    assert params['model'] == str(tmp_path / 'none.json')


def test_the_default_model_is_in_ros_home(tmp_path, monkeypatch):
    monkeypatch.setenv('ROS_HOME', str(tmp_path / 'ros_home'))
    model = tmp_path / 'ros_home' / 'cc_log' / 'model.json'
    model.parent.mkdir(parents=True)
    model.write_text('{}')
    plan = parse(['/odom'])
    assert plan.module == 'smart_node' and plan.params['model'] == str(model)


def test_output_prefix_and_name_as_rosbag_record_names_its_bags(tmp_path, monkeypatch):
    """-o /data/run: /data/run_<UTC>_<reason>.bag (rosbag: run_<date>.bag); -o DIRECTORY/: a directory; -O NAME:
    NAME's stem as the prefix, said in one line at start."""
    none = ['--model', str(tmp_path / 'none.json')]
    plan = parse(['/odom', '-o', '/data/run'] + none)
    assert plan.params['directory'] == '/data' and plan.params['name_prefix'] == 'run' and plan.said == ()
    monkeypatch.chdir(tmp_path)
    plan = parse(['/odom', '-o', 'lab.run-2'] + none)  # no directory: the current one, as rosbag
    assert plan.params['directory'] == str(tmp_path) and plan.params['name_prefix'] == 'lab.run-2'
    plan = parse(['/odom', '-o', '/data/'] + none)
    assert plan.params['directory'] == '/data' and 'name_prefix' not in plan.params
    plan = parse(['/odom', '-O', '/data/run.bag'] + none)
    assert plan.params['directory'] == '/data' and plan.params['name_prefix'] == 'run'
    assert plan.said == ((False, '-O /data/run.bag: cc_log writes one file per window: '
                                 '/data/run_<UTC>_<reason>.bag'),)
    from cc_log.logger import options  # the node reads it as its own option
    assert options.get('name_prefix').parse(plan.params['name_prefix']) == 'run'


def test_max_splits_size_chunksize_tcpnodelay_quiet_and_bz2(tmp_path):
    none = ['--model', str(tmp_path / 'none.json')]
    plan = parse(['/odom', '--split', '--duration', '1m', '--max-splits', '5', '--chunksize', '256', '--tcpnodelay',
                  '-q', '-j'] + none)
    assert plan.module == 'collect_node' and plan.params['max_files'] == 5 and plan.params['chunk_kb'] == 256
    assert plan.params['tcp_nodelay'] is True and plan.params['quiet'] is True
    assert plan.params['format'] == 'bag-lz4' and plan.said == ((True, record_main.BZ2_NOTE),)
    plan = parse(['/odom', '--max-splits', '3', '--mode', 'smart'])  # smart mode: every window is a file
    assert plan.params['max_files'] == 3 and 'tcp_nodelay' not in plan.params and 'quiet' not in plan.params
    plan = parse(['/odom', '--size', '100'] + none)  # rosbag stops at SIZE; cc_log keeps within it
    assert plan.params['max_disk_mb'] == pytest.approx(100 * 2 ** 20 / 1e6) and 'split_mb' not in plan.params
    assert plan.stop == {}
    from cc_log.logger import options
    for key in ('max_files', 'chunk_kb', 'tcp_nodelay', 'quiet', 'max_disk_mb'):
        assert key in [option.name for option in options.for_node('collect')]
        assert key in [option.name for option in options.for_node('smart')]


def test_warnings_said_at_start_even_when_quiet(tmp_path, capsys, monkeypatch):
    """-j is said (a warning, also with -q); -O's line is left out by -q. The node itself is not started here."""
    monkeypatch.setattr(record_main.launcher, 'run', lambda module, argv, note: 0)
    monkeypatch.setattr('cc_log.nodes.node_common.read_settings_only', lambda settings: None)  # settings kept
    none = ['--model', str(tmp_path / 'none.json')]
    assert record_main.main(['record', '/odom', '-j', '-O', str(tmp_path / 'run.bag')] + none) == 0
    err = capsys.readouterr().err.splitlines()
    assert err == ['record: warning: ' + record_main.BZ2_NOTE,
                   'record: -O %s: cc_log writes one file per window: %s_<UTC>_<reason>.bag'
                   % (tmp_path / 'run.bag', tmp_path / 'run')]
    assert record_main.main(['record', '/odom', '-j', '-q', '-O', str(tmp_path / 'run.bag')] + none) == 0
    assert capsys.readouterr().err.splitlines() == ['record: warning: ' + record_main.BZ2_NOTE]
