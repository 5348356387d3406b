"""Nothing is written or deleted outside its root: the one path guard (``safe_files.inside``) and what goes through
it; the quota counts what a file holds on disk, never follows a link and says when it deletes a file its writer did
not write.

The guard is checked for any name (hypothesis); ``cclog replay`` and ``cclog collect`` run as real processes on a
real bag (a link named ``...bag`` in a directory of bags: the bag itself is never copied).
"""
import os

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from cc_log.base import safe_files
from cc_log.offline import fleet
from cc_log.storage import disk_guard
from cc_log.storage.disk_guard import DiskGuard
from cc_log.storage.log_format import Format, write_window
from cc_log.base.event_kinds import DELETED
from cc_log.storage.window_writer import FOREIGN_NOTE, Job, WindowWriter

pytest.importorskip('rosbag')
from test_cli import run  # noqa: E402
from test_reliability import window  # noqa: E402

SMALL = 'sequor_N2_anomalous_jerky_driving.bag'  # 486 kB, /odom among its topics
PRECIOUS = 'cc_log_20150101T000000.000Z_precious.bag'  # a window of another run, beside the output directory
TIB = 2 ** 40


def is_inside(path, root):
    """Whether ``path`` names something strictly below ``root`` (both resolved)."""
    real, base = os.path.realpath(path), os.path.realpath(root)
    return real != base and os.path.commonpath([real, base]) == base


def tree(root):
    """Every file and directory below ``root``, as paths relative to it, sorted."""
    found = []
    for folder, folders, files in os.walk(str(root)):
        found.extend(os.path.relpath(os.path.join(folder, name), str(root)) for name in folders + files)
    return sorted(found)


# -- the guard -------------------------------------------------------------------------------------------------

def test_plain_names_are_joined_under_the_root(tmp_path):
    root = str(tmp_path)
    assert safe_files.inside(root, 'nominal') == os.path.join(root, 'nominal')
    assert safe_files.inside(root, 'features/motion/nominal') == os.path.join(root, 'features', 'motion', 'nominal')
    assert safe_files.inside(root, '...bag') == os.path.join(root, '...bag')
    assert safe_files.inside(root, '..x') == os.path.join(root, '..x')


@pytest.mark.parametrize('name', ['..', '.', '', '../OUT', 'a/../../b', 'a/..', '/etc/passwd', 'a//b', 'a/',
                                  'nul\0name', '\udcff\ud800'])
def test_names_that_leave_the_root_or_name_it_are_refused_in_one_line(tmp_path, name):
    with pytest.raises(ValueError) as error:
        safe_files.inside(str(tmp_path), name, 'bag')
    text = str(error.value)
    assert text.startswith('bag: ') and text.endswith(' is outside %s' % tmp_path) and '\n' not in text


def test_a_link_inside_the_root_is_never_followed_but_the_root_may_be_one(tmp_path):
    """A link as a directory of the path is refused; at its last part it is a name (writers replace a link there,
    never write through it; a deletion removes the link itself)."""
    elsewhere = tmp_path / 'elsewhere'
    elsewhere.mkdir()
    root = tmp_path / 'root'
    root.mkdir()
    (root / 'robot1').symlink_to(elsewhere)
    for name in ('robot1/nominal', 'robot1/nominal/1.json'):
        with pytest.raises(ValueError, match='^label: .* is outside '):
            safe_files.inside(str(root), name, 'label')
    assert safe_files.inside(str(root), 'robot1') == os.path.join(str(root), 'robot1')
    with pytest.raises(ValueError, match='^bag: .* is outside '):  # a directory to write in: not a link either
        safe_files.inside(str(root), 'robot1', 'bag', directory=True)
    with pytest.raises(ValueError, match='^bag: .* is outside '):
        fleet.output_dirs(str(root), [str(tmp_path / 'bags' / 'robot1.bag')])
    linked = tmp_path / 'linked_root'
    linked.symlink_to(root)
    assert safe_files.inside(str(linked), 'nominal') == os.path.join(str(linked), 'nominal')


NAMES = st.one_of(st.text(), st.text(alphabet='./a\0', max_size=12),
                  st.lists(st.sampled_from(['..', '.', '', 'a', '...', '..bag', '/']), max_size=6).map('/'.join))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=NAMES)
def test_any_name_gives_a_path_inside_the_root_or_a_value_error(tmp_path, name):
    root = str(tmp_path / 'root')
    os.makedirs(root, exist_ok=True)
    try:
        path = safe_files.inside(root, name, 'name')
    except ValueError as error:
        assert str(error).startswith('name: ')
        return
    assert is_inside(path, root) and os.path.normpath(path) == path
    assert safe_files.inside(root, name, 'name', directory=True) == path  # (no link in root)


# -- item 3: files written and deleted outside --out ---------------------------------------------------------

def test_bags_named_dots_get_output_directories_inside_out(tmp_path):
    bags = [str(tmp_path / name) for name in ('...bag', '..bag', '.bag', 'run.bag')]
    assert fleet.output_names(bags) == ['...bag', '..bag', '.bag', 'run']
    out = str(tmp_path / 'OUT')
    assert all(is_inside(path, out) for path in fleet.output_dirs(out, bags))


@pytest.fixture
def dotted(real_bag, tmp_path):
    """A directory of bags holding one named ``...bag`` (a link to a real bag) and a ``parent`` directory holding a
    window of another run."""
    bags = tmp_path / 'bags'
    bags.mkdir()
    (bags / '...bag').symlink_to(real_bag(SMALL))
    parent = tmp_path / 'parent'
    parent.mkdir()
    (parent / PRECIOUS).write_bytes(b'precious: must never be deleted\n' * 1000)
    return bags, parent


def test_a_replay_of_a_bag_named_dots_writes_only_inside_out_and_its_quota_deletes_nothing_beside(dotted, tmp_path):
    bags, parent = dotted
    config = tmp_path / 'fast.yaml'
    config.write_text("triggers: [{name: fast, kind: rule, topic: /odom, type: nav_msgs/Odometry, "
                      "when: 'twist.twist.linear.x > 0.3'}]\nlimits: {max_files: 1}\n")
    result = run('replay', bags, '--config', config, '--out', parent / 'OUT', '--pre', '1s', '--post', '1s',
                 '--workers', 0)
    assert result.returncode == 0, result.stderr[-2000:]
    assert sorted(os.listdir(str(parent))) == sorted([PRECIOUS, 'OUT'])
    assert (parent / PRECIOUS).read_bytes() == b'precious: must never be deleted\n' * 1000
    written = tree(parent / 'OUT')
    assert written[0] == '...bag' and any(name.endswith('.bag') for name in written[1:])
    assert all(name.startswith('...bag' + os.sep) for name in written[1:])


def test_a_collect_of_a_bag_named_dots_makes_no_directory_beside_out(dotted):
    bags, parent = dotted
    (parent / 'OUT').mkdir()  # (else OUT/.. cannot be reached)
    result = run('collect', bags, '--topic', '/odom', '--out', parent / 'OUT', '--window', '20', '--stride', '5',
                 '--workers', 0)
    assert result.returncode == 0, result.stderr[-2000:]
    assert sorted(os.listdir(str(parent))) == sorted([PRECIOUS, 'OUT'])
    assert os.listdir(str(parent / 'OUT' / '...bag' / 'nominal'))


# -- item 4: the quota counts what files hold, never follows a link, says what it deleted of others -------------

def windows_in(directory, count=3):
    return [write_window(window(300, start=1000 * k), str(directory), Format.JSON_XZ)[0] for k in range(count)]


def test_a_sparse_terabyte_of_cc_log_names_deletes_no_real_window(tmp_path):
    real = windows_in(tmp_path)
    sparse = tmp_path / 'cc_log_29991231T235959.000Z_classifier.bag'
    with open(str(sparse), 'wb') as stream:
        stream.truncate(TIB)
    guard = DiskGuard(str(tmp_path), max_disk_mb=1)
    assert guard.enforce_quota(keep=real[-1]) == []
    assert all(os.path.exists(path) for path in real) and os.path.getsize(str(sparse)) == TIB
    assert guard.usage() < disk_guard.MB


def test_a_link_to_a_big_file_is_neither_counted_nor_deleted_nor_followed(tmp_path):
    logs = tmp_path / 'logs'
    logs.mkdir()
    real = windows_in(logs)
    big = tmp_path / 'big.bag'
    big.write_bytes(b'\1' * (3 * disk_guard.MB))
    link = logs / 'cc_log_20000101T000000.000Z_classifier.bag'
    link.symlink_to(big)
    guard = DiskGuard(str(logs), max_disk_mb=1)
    assert [path for path, _ in guard.window_files()] == real
    assert guard.enforce_quota(keep=real[-1]) == []
    assert os.path.islink(str(link)) and big.read_bytes() == b'\1' * (3 * disk_guard.MB)


def test_a_quota_deleting_a_file_its_writer_did_not_write_says_so(tmp_path):
    directory = str(tmp_path)
    foreign = write_window(window(300, start=0), directory, Format.JSON_XZ)[0]  # another run's
    os.utime(foreign, ns=(1, 1))  # the oldest
    writer = WindowWriter(directory, Format.JSON_XZ, background=False, max_files=2)
    said = []
    writer.on_event(lambda event: said.append((event.path, event.error)) if event.kind == DELETED else None)
    for k in range(1, 5):
        writer.submit(Job(window(300, start=1000 * k), {}))
    writer.close()
    assert [path for path, _ in said][0] == foreign and len(said) == 3
    assert said[0][1] == 'deleted to stay within max_files 2' + FOREIGN_NOTE
    assert [error for _, error in said[1:]] == ['deleted to stay within max_files 2'] * 2
    assert writer.guard.foreign_deleted == 1 and writer.guard.deleted == 3


def test_two_writers_sharing_one_quota_delete_each_others_files_as_their_own(tmp_path):
    """The context track's writer and the windows' share one quota (``DiskGuard.share``): a file of either, deleted
    by the other, is not said to be another run's."""
    windows, context = tmp_path / 'logs', tmp_path / 'logs' / 'context'
    context.mkdir(parents=True)
    guard, context_guard = DiskGuard(str(windows), max_files=1), DiskGuard(str(context), max_files=1)
    context_guard.share(guard)
    first = windows_in(windows, 1)[0]
    assert guard.enforce_quota(keep=first) == []
    os.utime(first, ns=(1, 1))
    second = windows_in(context, 1)[0]
    assert context_guard.enforce_quota(keep=second) == [first]
    assert context_guard.last_foreign == [] and context_guard.foreign_deleted == 0
    foreign = windows_in(windows, 1)[0]  # written by neither writer
    os.utime(foreign, ns=(1, 1))
    assert guard.enforce_quota() == [foreign] and guard.last_foreign == [foreign] and guard.foreign_deleted == 1
