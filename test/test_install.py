"""The install space works: `catkin_make install` into a scratch prefix, then, with only that install space
sourced (no devel space, no source tree on any path), rosrun finds every script, `cclog --help` runs, the
smart logger without a model says so and exits 1, and `roslaunch cc_log smart.launch` brings the node up."""
import os
import shutil
import subprocess
import time

import pytest

from cc_log.offline.demo import Processes, free_port, wait_for_master

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
NOT_SOURCES = ('.catkin_ws', '.git', '__pycache__', '.hypothesis', '.pytest_cache', 'out')
NODE_TIMEOUT = 60.0


@pytest.fixture(scope='module')
def installed(tmp_path_factory):
    """A catkin workspace holding a copy of the package, built and installed into <tmp>/install."""
    top = tmp_path_factory.mktemp('install')
    shutil.copytree(ROOT, str(top / 'ws' / 'src' / 'cc_log'), symlinks=True,
                    ignore=shutil.ignore_patterns(*NOT_SOURCES))
    prefix = top / 'install'
    result = subprocess.run(
        ['catkin_make', 'install', '-DCMAKE_INSTALL_PREFIX=%s' % prefix, '-DPYTHON_EXECUTABLE=/usr/bin/python3',
         '-DCATKIN_ENABLE_TESTING=OFF'],
        cwd=str(top / 'ws'), env=clean_env(top), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        universal_newlines=True, timeout=900)
    assert result.returncode == 0, result.stdout[-4000:]
    return top, prefix


def clean_env(top, **extra):
    """The environment of a fresh shell: nothing of a sourced workspace, no make jobserver of a caller."""
    env = {'PATH': '/usr/bin:/bin', 'HOME': str(top), 'ROS_HOME': str(top / 'ros_home'), 'LANG': 'C.UTF-8'}
    env.update(extra)
    return env


def in_install_space(installed, command, timeout=120, **env):
    """Run a shell command with only the install space sourced."""
    top, prefix = installed
    return subprocess.run(['bash', '-c', 'source "%s/setup.bash" && %s' % (prefix, command)],
                          cwd=str(top), env=clean_env(top, **env), stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, universal_newlines=True, timeout=timeout)


def test_the_install_space_holds_every_script_and_is_what_ros_finds(installed):
    top, prefix = installed
    for name in sorted(os.listdir(os.path.join(ROOT, 'scripts'))):
        path = prefix / 'lib' / 'cc_log' / name
        assert path.is_file() and os.access(str(path), os.X_OK), 'scripts/%s is not installed' % name
    found = in_install_space(installed, 'rospack find cc_log')
    assert found.returncode == 0 and found.stdout.strip() == str(prefix / 'share' / 'cc_log'), found
    assert (prefix / 'share' / 'cc_log' / 'launch' / 'smart.launch').is_file()
    assert (prefix / 'share' / 'cc_log' / 'msg' / 'AnomalyEvent.msg').is_file()


def test_rosrun_cclog_help(installed):
    result = in_install_space(installed, 'rosrun cc_log cclog --help')
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith('usage: cclog') and 'simulate' in result.stdout


def test_smart_logger_and_smart_launch_from_the_install_space(installed):
    top, prefix = installed
    uri = 'http://127.0.0.1:%d' % free_port()
    ros = {'ROS_MASTER_URI': uri, 'ROS_HOSTNAME': '127.0.0.1', 'ROS_LOG_DIR': str(top / 'ros_log')}
    model = top / 'model.json'
    learned = in_install_space(
        installed, 'rosrun cc_log cclog simulate --minutes 2 --anomalies 0 --seed 3 nominal.bag && '
                   'rosrun cc_log cclog collect nominal.bag --topic /odom --out vectors --window 1s --stride 10 && '
                   'rosrun cc_log cclog learn --train vectors --model %s' % model, timeout=300)
    assert learned.returncode == 0 and model.is_file(), learned.stderr[-3000:]
    processes = Processes()
    try:
        port = uri.rsplit(':', 1)[1]
        processes.start(['bash', '-c', 'source "%s/setup.bash" && exec roscore -p %s' % (prefix, port)],
                        clean_env(top, **ros), str(top / 'roscore.log'))
        wait_for_master(uri)
        no_model = in_install_space(installed, 'rosrun cc_log smart_logger.py', timeout=NODE_TIMEOUT, **ros)
        assert no_model.returncode == 1, no_model
        assert '~model' in no_model.stderr and 'Traceback' not in no_model.stderr, no_model.stderr

        launch = processes.start(
            ['bash', '-c', 'source "%s/setup.bash" && exec roslaunch cc_log smart.launch model:=%s directory:=%s '
             'diagnostic_period:=0.2' % (prefix, model, top / 'windows')],
            clean_env(top, **ros), str(top / 'roslaunch.log'))
        import rosgraph
        master = rosgraph.Master('/test_install', master_uri=uri)
        wanted = {('/diagnostics', '/smart_logger'), ('/smart_logger/anomalies', '/smart_logger')}
        deadline = time.time() + NODE_TIMEOUT
        published = set()
        while time.time() < deadline and launch.poll() is None and not wanted <= published:
            publishers, _, _ = master.getSystemState()
            published = {(topic, node) for topic, nodes in publishers for node in nodes}
            time.sleep(0.2)
        log = (top / 'roslaunch.log').read_text()
        assert wanted <= published, 'smart.launch did not bring the node up (%s):\n%s' % (published, log[-3000:])
        assert launch.poll() is None, log[-3000:]
    finally:
        processes.stop()
