"""record.launch as bwi_logging's: the parameters it gives the node, with no arguments and with BWI's."""
import os
import shutil
import subprocess

import pytest
import yaml

LAUNCH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'launch', 'record.launch')


def params(*args):
    if shutil.which('roslaunch') is None:
        pytest.skip('roslaunch is not on PATH (source the workspace)')
    out = subprocess.run(['roslaunch', '--dump-params', LAUNCH] + list(args), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, universal_newlines=True, timeout=120)
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
