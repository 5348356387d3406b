"""record.launch as bwi_logging's: the parameters it gives the node, with no arguments and with BWI's."""
import os
import re
import shutil
import signal
import subprocess

import pytest
import yaml

LAUNCH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'launch', 'record.launch')


def params(*args, **kwargs):
    """The parameters a launch file (``launch``: record.launch) sets, run from ``cwd`` (a shell's $PWD) with the
    environment variables ``env`` (``{name: value}``, None: unset)."""
    if shutil.which('roslaunch') is None:
        pytest.skip('roslaunch is not on PATH (source the workspace)')
    launch = os.path.join(os.path.dirname(LAUNCH), kwargs.get('launch', 'record.launch'))
    cwd = kwargs.get('cwd', os.getcwd())
    out = subprocess.run(['roslaunch', '--dump-params', launch] + list(args), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, universal_newlines=True, timeout=120, cwd=cwd,
                         env=environment(kwargs.get('env', {}), PWD=cwd))
    assert out.returncode == 0, out.stderr
    return yaml.safe_load(out.stdout)


def environment(changes, **more):
    """os.environ with ``changes`` and ``more`` (None: unset)."""
    env = dict(os.environ, **more)
    for name, value in changes.items():
        env.pop(name, None)
        if value is not None:
            env[name] = value
    return env


def test_no_arguments_gives_bwis_defaults():
    got = params(env={'ROS_HOME': None})
    assert got['/cc_log/context_topics'] == 'odom_1hz amcl_pose /diagnostics'  # BWI's topics, always recorded
    assert got['/cc_log/topics'] == ''  # extra_topics false: none
    assert got['/cc_log/directory'] == '' and got['/cc_log/model'].endswith('/.ros/cc_log/model.json')


def test_bwi_arguments_keep_their_meaning():
    got = params('directory:=/data/logs', 'topics:=odom_1hz scan', 'extra_topics:=imu/data camera/image',
                 'extra_prefix:=heavy')
    assert got['/cc_log/directory'] == '/data/logs'
    assert got['/cc_log/context_topics'] == 'odom_1hz scan' and got['/cc_log/topics'] == 'imu/data camera/image'


def test_the_default_model_follows_ros_home(tmp_path):
    got = params(env={'ROS_HOME': str(tmp_path / 'ros_home')})
    assert got['/cc_log/model'] == str(tmp_path / 'ros_home' / 'cc_log' / 'model.json')


@pytest.mark.parametrize('value, topics', [('true', '*'), ('True', '*'), ('false', ''), ('False', ''),
                                           ('scan', 'scan')])
def test_extra_topics_true_is_every_topic_false_none(value, topics):
    assert params('extra_topics:=' + value)['/cc_log/topics'] == topics


@pytest.mark.parametrize('launch, node', [('record.launch', '/cc_log'), ('smart.launch', '/smart_logger'),
                                          ('collect.launch', '/collect_logger')])
def test_relative_paths_are_the_caller_s(tmp_path, launch, node):
    """roslaunch runs nodes in ~/.ros: a relative model, config or directory is resolved where the user is."""
    args = ['config:=robot.yaml', 'directory:=logs'] + (['model:=model.json'] if launch != 'collect.launch' else [])
    got = params(*args, launch=launch, cwd=str(tmp_path))
    assert got[node + '/config'] == str(tmp_path / 'robot.yaml') and got[node + '/directory'] == str(tmp_path / 'logs')
    if launch != 'collect.launch':
        assert got[node + '/model'] == str(tmp_path / 'model.json')


def test_smart_launch_has_the_context_upload_and_quota_args():
    got = params('context_topics:=odom_1hz /diagnostics', 'upload_command:=rsync -a', 'max_disk_mb:=2GB',
                 launch='smart.launch')
    assert got['/smart_logger/context_topics'] == 'odom_1hz /diagnostics'
    assert got['/smart_logger/upload_command'] == 'rsync -a' and got['/smart_logger/max_disk_mb'] == '2GB'


def test_collect_launch_window_is_a_duration():
    assert params(launch='collect.launch')['/collect_logger/window'] == '2s'


def test_smart_launch_passes_the_buffer_split_and_classify_args():
    got = params('max_buffer_mb:=512MB', 'split_mb:=1GB', 'classify_every:=100ms', launch='smart.launch')
    assert (got['/smart_logger/max_buffer_mb'], got['/smart_logger/split_mb'],
            got['/smart_logger/classify_every']) == ('512MB', '1GB', '100ms')
    empty = params(launch='smart.launch')  # not given: the configuration's value holds
    assert (empty['/smart_logger/max_buffer_mb'], empty['/smart_logger/split_mb'],
            empty['/smart_logger/classify_every']) == ('', '', '')
    got = params('max_buffer_mb:=512MB', 'split_mb:=1GB')
    assert (got['/cc_log/max_buffer_mb'], got['/cc_log/split_mb']) == ('512MB', '1GB')


ANSI = re.compile(r'\x1b\[[0-9;]*m|\x1b\][^\x07]*\x07')
LAUNCH_EXIT = 90.0  # seconds: a node that cannot start ends its launch within this (a few seconds unloaded)


@pytest.mark.parametrize('launch, args, error', [
    ('smart.launch', ['model:=/nonexistent/model.json'], '/nonexistent/model.json: cannot read'),
    ('record.launch', ['mode:=smart', 'model:=/nonexistent/model.json'], '/nonexistent/model.json: cannot read'),
    ('collect.launch', ['stride:=0'], "~stride: '0' is outside 1..1e+06 messages"),
])
def test_a_logger_that_cannot_start_ends_the_launch_with_its_error_last(tmp_path, launch, args, error):
    """The logger is required: roslaunch (here with a master of its own) shuts down when it exits, and the
    node's one line is the last thing printed before roslaunch's shutdown notice. (roslaunch exits 0 even
    then: it has no exit status for a required node that died.)"""
    if shutil.which('roslaunch') is None or subprocess.run(
            ['rospack', 'find', 'cc_log'], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode:
        pytest.skip('cc_log is not on ROS_PACKAGE_PATH: source .catkin_ws/devel/setup.bash first')
    from cc_log.offline.demo import free_port
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI='http://127.0.0.1:%d' % port, ROS_HOSTNAME='127.0.0.1',
               ROS_HOME=str(tmp_path / 'ros_home'), PWD=str(tmp_path),
               PYTHONUNBUFFERED='1')  # every line as soon as it is written, in order, as on a terminal
    launched = subprocess.Popen(['roslaunch', '-p', str(port), 'cc_log', launch] + args, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, universal_newlines=True, cwd=str(tmp_path), env=env,
                                start_new_session=True)
    try:
        printed, _ = launched.communicate(timeout=LAUNCH_EXIT)
    except subprocess.TimeoutExpired:
        os.killpg(launched.pid, signal.SIGINT)  # roslaunch ends its master and nodes
        printed, _ = launched.communicate()
        pytest.fail('roslaunch %s went on without its logger:\n%s' % (launch, printed))
    lines = [line.strip() for line in ANSI.sub('\n', printed).splitlines() if line.strip()]
    notice = next(i for i, line in enumerate(lines) if 'REQUIRED process [' in line)
    assert error in lines[notice - 1] and lines[notice - 1].startswith('/'), printed
    assert sum(error in line for line in lines) == 1, printed  # one line, said once
