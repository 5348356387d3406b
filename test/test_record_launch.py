"""record.launch as bwi_logging's: the parameters it gives the node, with no arguments and with BWI's."""
import os
import shutil
import subprocess

import pytest
import yaml

LAUNCH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'launch', 'record.launch')


def params(*args, **kwargs):
    """The parameters a launch file (``launch``: record.launch) sets, run from ``cwd`` (a shell's $PWD)."""
    if shutil.which('roslaunch') is None:
        pytest.skip('roslaunch is not on PATH (source the workspace)')
    launch = os.path.join(os.path.dirname(LAUNCH), kwargs.get('launch', 'record.launch'))
    cwd = kwargs.get('cwd', os.getcwd())
    out = subprocess.run(['roslaunch', '--dump-params', launch] + list(args), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, universal_newlines=True, timeout=120, cwd=cwd,
                         env=dict(os.environ, PWD=cwd))
    assert out.returncode == 0, out.stderr
    return yaml.safe_load(out.stdout)


def test_no_arguments_gives_bwis_defaults():
    got = params()
    assert got['/cc_log/context_topics'] == 'odom_1hz amcl_pose /diagnostics'  # BWI's topics, always recorded
    assert got['/cc_log/topics'] == ''  # extra_topics false: none
    assert got['/cc_log/directory'] == '' and got['/cc_log/model'].endswith('/.ros/cc_log/model.json')


def test_bwi_arguments_keep_their_meaning():
    got = params('directory:=/data/logs', 'topics:=odom_1hz scan', 'extra_topics:=imu/data camera/image',
                 'extra_prefix:=heavy')
    assert got['/cc_log/directory'] == '/data/logs'
    assert got['/cc_log/context_topics'] == 'odom_1hz scan' and got['/cc_log/topics'] == 'imu/data camera/image'


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
