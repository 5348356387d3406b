"""Shared pytest fixtures: where the real robot bags are."""
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REAL_DATA = os.path.normpath(os.path.join(ROOT, '..', 'shared', 'data', 'real'))

try:
    import cc_log  # noqa: F401  (a sourced workspace also provides the generated cc_log.msg)
except ImportError:
    # without a sourced workspace: this tree's package, here and in the commands tests run (cclog)
    sys.path.insert(0, os.path.join(ROOT, 'src'))
    os.environ['PYTHONPATH'] = os.pathsep.join(
        [os.path.join(ROOT, 'src')] + [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p])


def real_data(name):
    """The path of a real bag in ../shared/data/real by file name; fail when it is missing (module-scoped
    fixtures call it; tests take the ``real_bag`` fixture)."""
    path = os.path.join(REAL_DATA, name)
    if not os.path.exists(path):
        pytest.fail('real data missing: %s (tests read ../shared/data/real/)' % path)
    return path


def cclog(*args):
    """Run ``cclog ARGS`` of this tree with no roscore reachable; the CompletedProcess (text stdout, stderr)."""
    env = dict(os.environ, ROS_MASTER_URI='http://127.0.0.1:1')
    return subprocess.run([sys.executable, os.path.join(ROOT, 'scripts', 'cclog')] + [str(a) for a in args],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, env=env, timeout=300)


def assert_rosbag_spans(expected):
    """Assert that rosbag says each bag of ``expected`` ({path: (first, last) stamp of its messages}) spans just
    that: its ``Bag``'s get_start_time and get_end_time, ``rosbag info --yaml``'s start, end and duration (each to
    a microsecond: bag times are nanoseconds, floats of today's seconds hold about 0.2 us) and plain ``rosbag
    info``'s duration (to the 0.1 s it prints; whole seconds past a minute)."""
    import re
    import rosbag
    import yaml
    paths = sorted(expected)
    for path in paths:
        first, last = expected[path]
        with rosbag.Bag(path) as bag:
            assert (bag.get_start_time(), bag.get_end_time()) == pytest.approx((first, last), abs=1e-6), path
    command = ['rosbag', 'info']
    said = subprocess.run(command + ['--yaml'] + paths, stdout=subprocess.PIPE, universal_newlines=True, check=True,
                          timeout=300).stdout
    infos = [info for info in yaml.safe_load_all(said) if info]
    assert [info['path'] for info in infos] == paths
    for info in infos:
        first, last = expected[info['path']]
        assert (info['start'], info['end']) == pytest.approx((first, last), abs=1e-6), info['path']
        assert info['duration'] == pytest.approx(last - first, abs=1e-6), info['path']
    text = subprocess.run(command + paths, stdout=subprocess.PIPE, universal_newlines=True, check=True,
                          timeout=300).stdout
    durations = [float(re.findall(r'([0-9.]+)s', line)[-1]) for line in text.splitlines()
                 if line.startswith('duration:')]
    assert len(durations) == len(paths)
    for path, duration in zip(paths, durations):
        first, last = expected[path]
        assert duration == pytest.approx(last - first, abs=0.05 + 1e-6 if last - first < 60 else 0.5), path


@pytest.fixture
def real_bag():
    """Return ``real_data``: the path of a real bag by file name."""
    return real_data


@pytest.fixture
def small_tmpfs(tmp_path):
    """``mount(size)`` mounts a tmpfs of ``size`` (``'2m'``) at a fresh directory and returns its path: a real
    disk that fills up. Mounting needs root: without it (or when mount fails) the test is skipped, saying why.
    Every mount is undone at the end."""
    import subprocess
    mounted = []

    def mount(size='2m'):
        if os.geteuid() != 0:
            pytest.skip('a small tmpfs (a real full disk) can only be mounted by root; running as uid %d'
                        % os.geteuid())
        path = tmp_path / ('tmpfs%d' % len(mounted))
        path.mkdir()
        result = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=%s,mode=0775' % size, 'tmpfs', str(path)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True)
        if result.returncode:
            pytest.skip('mount -t tmpfs failed: %s' % (result.stderr.strip() or result.returncode))
        mounted.append(path)
        return str(path)
    yield mount
    for path in mounted:
        subprocess.call(['umount', '-l', str(path)])


def fill_disk(path):
    """Create ``path`` and write zeros into it until the file system is full (ENOSPC); return its size."""
    import errno
    written = 0
    with open(path, 'wb', buffering=0) as stream:
        block = b'\0' * 65536
        while True:
            try:
                written += stream.write(block)
            except OSError as error:
                if error.errno != errno.ENOSPC:
                    raise
                block = block[:len(block) // 2]
                if not block:
                    return written
