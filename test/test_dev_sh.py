"""dev.sh installs what package.xml declares: each rosdep key maps to Debian packages in one place, a new key
needs no second edit when a rule covers it, and a key nothing covers stops setup with a line naming it."""
import os
import re
import shutil
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))


def packages(tmp_path, extra_keys=()):
    """``dev.sh packages`` run on a copy of dev.sh and package.xml with ``extra_keys`` declared."""
    shutil.copy(os.path.join(ROOT, 'dev.sh'), str(tmp_path / 'dev.sh'))
    with open(os.path.join(ROOT, 'package.xml')) as stream:
        manifest = stream.read()
    lines = ''.join('  <exec_depend>%s</exec_depend>\n' % key for key in extra_keys)
    (tmp_path / 'package.xml').write_text(manifest.replace('</package>', lines + '</package>'))
    return subprocess.run(['bash', str(tmp_path / 'dev.sh'), 'packages'], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, universal_newlines=True, timeout=60)


def declared_keys():
    with open(os.path.join(ROOT, 'package.xml')) as stream:
        text = re.sub(r'<!--.*?-->', '', stream.read(), flags=re.S)
    return set(re.findall(r'<(?:\w+_)?depend>\s*([^<\s]+)\s*</', text))


def test_every_declared_key_and_the_toolchain_are_installed(tmp_path):
    result = packages(tmp_path)
    assert result.returncode == 0, result.stderr
    names = result.stdout.split()
    assert {'g++', 'make', 'cmake'} <= set(names)
    assert {'rosbash', 'rosout', 'python3-roslaunch', 'python3-rosgraph', 'python3-psutil', 'catkin-lint',
            'ros-nav-msgs', 'python3-nav-msgs', 'python3-rostest', 'xz-utils', 'jq'} <= set(names)
    assert not {'python3-lz4', 'ros-core'} & set(names)  # optional, or not needed whole
    assert 'python3-zstandard' in names  # an optional extra (MCAP zstd chunks), installed for the tests
    assert {'rosbash', 'python3-psutil', 'python3-catkin-lint'} <= declared_keys()


def test_a_new_key_needs_no_second_edit(tmp_path):
    result = packages(tmp_path, ['python3-yaml', 'geometry_msgs', 'rostopic'])
    assert result.returncode == 0, result.stderr
    wanted = {'python3-yaml', 'ros-geometry-msgs', 'python3-geometry-msgs', 'python3-rostopic'}
    assert wanted <= set(result.stdout.split())


def test_a_key_without_a_debian_package_stops_setup_with_its_name(tmp_path):
    result = packages(tmp_path, ['no_such_key'])
    assert result.returncode == 1
    assert result.stderr.strip() == ('[dev.sh] package.xml: no Debian package known for rosdep key(s) no_such_key: '
                                     'add them to debian_packages_of in dev.sh')


def imported_ros_packages():
    """The ROS packages (message packages, rospy, rosbag, ...) that the library and scripts import."""
    found = set()
    for top in ('src', 'scripts'):
        for folder, _, names in os.walk(os.path.join(ROOT, top)):
            for name in names:
                path = os.path.join(folder, name)
                if not (name.endswith('.py') or top == 'scripts'):
                    continue
                with open(path, encoding='utf-8', errors='replace') as stream:
                    modules = re.findall(r'^\s*(?:from|import)\s+([A-Za-z0-9_]+)', stream.read(), flags=re.M)
                found.update(m for m in modules if m.endswith(('_msgs', '_srvs')) or m.startswith('ros')
                             or m == 'genpy')
    return found


def test_every_ros_package_the_code_imports_is_declared():
    imported = imported_ros_packages()
    assert {'rospy', 'nav_msgs', 'geometry_msgs'} <= imported  # (the scan finds them)
    assert imported - declared_keys() == set()


def test_the_ros_command_lines_the_docs_give_are_installed(tmp_path):
    """``rosservice call`` (a manual window) and ``rostopic`` are declared, and dev.sh installs them."""
    assert {'rosservice', 'rostopic'} <= declared_keys()
    assert {'python3-rosservice', 'python3-rostopic'} <= set(packages(tmp_path).stdout.split())
