"""LoggingDirectory: the explicit path, then $ROS_HOME/cc_log (~/.ros/cc_log), then /tmp/cc_log."""
import os

import pytest

from cc_log.storage import directory as directory_module
from cc_log.storage.directory import LoggingDirectory


@pytest.fixture
def defaults(tmp_path, monkeypatch):
    """Point the two default directories into tmp_path; return them."""
    home = tmp_path / 'home' / '.ros' / 'cc_log'
    tmp = tmp_path / 'tmp' / 'cc_log'
    monkeypatch.setenv('ROS_HOME', str(home.parent))
    monkeypatch.setattr(directory_module, 'TMP_DIRECTORY', str(tmp))
    return str(home), str(tmp)


def blocked(tmp_path, name):
    """A path that can never be a directory (under a regular file), whoever runs the test (even root)."""
    blocker = tmp_path / ('file-' + name)
    blocker.write_text('x')
    return str(blocker / 'logs')


def test_explicit_path_is_created_and_used(tmp_path, defaults):
    wanted = tmp_path / 'a' / 'b' / 'logs'
    chosen = LoggingDirectory(str(wanted))
    assert chosen.path == str(wanted) and os.path.isdir(chosen.path)
    assert chosen.tried == [] and chosen.fallback is False
    assert os.stat(chosen.path).st_mode & 0o002 == 0
    assert os.listdir(chosen.path) == []  # the write probe is removed
    assert os.fspath(chosen) == str(wanted) and str(chosen) == str(wanted)


def test_user_path_is_expanded(tmp_path, defaults, monkeypatch):
    monkeypatch.setenv('HOME', str(tmp_path / 'someone'))
    chosen = LoggingDirectory('~/logs')
    assert chosen.path == str(tmp_path / 'someone' / 'logs')


def test_no_explicit_path_uses_home_ros(defaults):
    home, _ = defaults
    for value in (None, ''):
        chosen = LoggingDirectory(value)
        assert chosen.path == home and chosen.fallback is False and chosen.tried == []


def test_the_default_is_in_ros_home_when_it_is_set(tmp_path, monkeypatch):
    """ROS_HOME moves ROS's home (its logs, roslaunch's working directory): cc_log's files follow it."""
    monkeypatch.setenv('HOME', str(tmp_path / 'someone'))
    monkeypatch.setenv('ROS_HOME', str(tmp_path / 'ros_home'))
    assert directory_module.ros_home() == str(tmp_path / 'ros_home')
    assert LoggingDirectory(None).path == str(tmp_path / 'ros_home' / 'cc_log')
    assert directory_module.cc_log_home('model.json') == str(tmp_path / 'ros_home' / 'cc_log' / 'model.json')
    for unset in ('', None):  # set empty or not set: ~/.ros, as ROS has it
        if unset is None:
            monkeypatch.delenv('ROS_HOME')
        else:
            monkeypatch.setenv('ROS_HOME', unset)
        assert LoggingDirectory(None).path == str(tmp_path / 'someone' / '.ros' / 'cc_log')


def test_unwritable_explicit_path_falls_back_to_home_then_tmp(tmp_path, defaults, monkeypatch):
    home, tmp = defaults
    bad = blocked(tmp_path, 'explicit')
    chosen = LoggingDirectory(bad)
    assert chosen.path == home and chosen.fallback is True
    assert [path for path, _ in chosen.tried] == [bad]
    monkeypatch.setenv('ROS_HOME', os.path.dirname(blocked(tmp_path, 'home')))  # its cc_log under a file
    chosen = LoggingDirectory(bad)
    assert chosen.path == tmp and chosen.fallback is True
    assert len(chosen.tried) == 2 and all(reason for _, reason in chosen.tried)


def test_nothing_writable_names_every_path(tmp_path, monkeypatch):
    paths = [blocked(tmp_path, name) for name in ('explicit', 'home', 'tmp')]
    paths[1] = os.path.join(os.path.dirname(paths[1]), 'cc_log')  # $ROS_HOME/cc_log under a file
    monkeypatch.setenv('ROS_HOME', os.path.dirname(paths[1]))
    monkeypatch.setattr(directory_module, 'TMP_DIRECTORY', paths[2])
    with pytest.raises(OSError) as error:
        LoggingDirectory(paths[0])
    for path in paths:
        assert path in str(error.value)


def test_existing_directory_is_kept(tmp_path, defaults):
    existing = tmp_path / 'existing'
    existing.mkdir()
    (existing / 'cc_log_old.json.xz').write_bytes(b'x')
    chosen = LoggingDirectory(str(existing))
    assert chosen.path == str(existing)
    assert os.listdir(chosen.path) == ['cc_log_old.json.xz']
