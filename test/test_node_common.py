"""Parameters of every node, read through one typed helper (a dict stands in for the parameter server): each
wrong type or value is one ConfigError line naming the parameter, never a TypeError or OverflowError, and
nothing is created from a value of the wrong type. The real nodes are checked in smart_window.test."""
import os

import pytest

pytest.importorskip('rospy')
from cc_log.nodes import node_common  # noqa: E402
from cc_log.nodes.node_common import ConfigError, Params  # noqa: E402
from cc_log.base.spans import Span  # noqa: E402


def params(**values):
    logged = []
    return Params(get=values.get, log=lambda text, *args: logged.append(text % args)), logged


def error_of(read):
    with pytest.raises(ConfigError) as error:
        read()
    text = str(error.value)
    assert '\n' not in text
    return text


def test_values_of_the_right_type_are_read_and_logged_once():
    p, logged = params(model='m.json', pre='2s', post=100, enabled='yes', max_disk_mb=5, topics='a, b a',
                       format='bag-lz4', stride='7', rotate=6000)
    assert p.option('model') == 'm.json' and p.text('model', '') == 'm.json'
    assert p.option('pre') == Span.duration(2.0) and p.option('post') == Span.messages(100)
    assert p.option('enabled') is True
    assert p.option('max_disk_mb') == 5.0
    assert p.option('stride') == 7
    assert p.option('topics') == ['a', 'b']
    assert p.option('format') == 'bag-lz4'
    assert str(p.option('rotate')) == '6000'
    assert p.option('directory') == '' and p.option('max_window') == Span.messages(100000)  # the defaults
    assert '~directory: none (default)' in logged and '~model: m.json' in logged and len(logged) == 12
    assert p.configuration('collect') == {'topics': ['a', 'b'], 'format': 'bag-lz4', 'max_disk_mb': 5.0,
                                          'rotate': p.option('rotate'), 'stride': 7}


@pytest.mark.parametrize('name, value, expected', [
    ('model', [1], "~model: [1] is not a string"),
    ('directory', [1, 2], "~directory: [1, 2] is not a string"),
    ('post', [1], "~post: [1] is not a message count"),
    ('post', '99999999999999999999999999999999999e999', '~post:'),
    ('pre', True, '~pre: True is not a message count'),
    ('pre', '-3', '~pre:'),
    ('max_disk_mb', 'lots', "~max_disk_mb: 'lots' is not a size (MB as a number"),
    ('max_disk_mb', -1, '~max_disk_mb: -1 is outside 1e-06..1e+09 MB (or 0: off)'),
    ('max_disk_mb', float('nan'), '~max_disk_mb:'),
    ('max_disk_mb', '-2GB', "~max_disk_mb: '-2GB' is outside 1e-06..1e+09 MB (or 0: off)"),
    ('max_buffer_mb', '64 furlongs', "~max_buffer_mb: '64 furlongs'"),
    ('intake_max_mb', '10B', "~intake_max_mb: '10B' is outside 0.001..1e+06 MB"),
    ('min_free_mb', True, '~min_free_mb: True is not a size'),
    ('diagnostic_period', True, '~diagnostic_period: True'),
    ('diagnostic_period', 1e308, '~diagnostic_period: 1e+308 is outside 0.01..3600 s (or 0: off)'),
    ('intake_max_messages', 2.5, '~intake_max_messages: 2.5 is not a whole number'),
    ('intake_max_messages', 1e400, '~intake_max_messages: inf'),
    ('enabled', [True], '~enabled: [True] is not true or false'),
    ('topics', 5, '~topics: 5 is not a list of topic names'),
    ('topics', ['a', 3], '~topics: 3 is not a topic name'),
    ('format', ['json-xz'], "~format: ['json-xz'] is not one of"),
    ('retrigger', 'sometimes', "~retrigger: 'sometimes' is not one of: every, onset"),
    ('rotate', {'a': 1}, "~rotate: {'a': 1} is not a message count"),
    ('context_rotate', '0s', "~context_rotate: '0s' is outside 1..86400 s"),
])
def test_a_wrong_type_or_value_is_one_line_naming_the_parameter(name, value, expected):
    p, _ = params(**{name: value})
    assert error_of(lambda: p.option(name)).startswith(expected)


def test_an_integer_rospy_cannot_send_is_refused_before_init_node():
    """rospy.init_node sends ``_name:=value`` to the parameter server over XML-RPC (32-bit integers): an
    OverflowError traceback before any node code runs, unless the command line is checked first."""
    for argv in (['node', '_post:=99999999999999999999'], ['node', '_topics:=[1, 99999999999]'],
                 ['node', '_seed:=-2147483649']):
        text = error_of(lambda: node_common.check_command_line(argv))
        assert text.startswith('~' + argv[1][1:argv[1].index(':')] + ': ') and 'too large' in text
    assert error_of(lambda: node_common.check_command_line(['node', '_pre:=[1'])).startswith('invalid command-line')
    node_common.check_command_line(['node', '_post:=2147483647', '_pre:=2s', 'odom:=/x', '__name:=n'])
    assert node_common.node_name('smart_logger', ['node', '__name:=renamed']) == '/renamed'


def test_an_unusable_directory_falls_back_with_a_warning_naming_the_one_in_use(tmp_path, monkeypatch):
    blocker = tmp_path / 'a_file'
    blocker.write_text('x')
    home = tmp_path / 'home'
    monkeypatch.setenv('HOME', str(home))
    path, warning = node_common.resolve_directory(str(blocker / 'logs'))
    assert path == str(home / '.ros' / 'cc_log') and os.path.isdir(path)
    assert warning.startswith('~directory %s cannot be used (' % (blocker / 'logs')) and warning.endswith(path)
    path, warning = node_common.resolve_directory(str(tmp_path / 'fine'))
    assert path == str(tmp_path / 'fine') and warning == ''


def test_a_read_only_directory_falls_back_with_a_warning(small_tmpfs, tmp_path, monkeypatch):
    import subprocess
    disk = small_tmpfs('1m')
    assert subprocess.call(['mount', '-o', 'remount,ro', disk]) == 0
    monkeypatch.setenv('HOME', str(tmp_path / 'home'))
    path, warning = node_common.resolve_directory(disk)
    assert path != disk and 'Read-only file system' in warning and path in warning


@pytest.mark.parametrize('value, megabytes', [
    (64, 64.0), ('64', 64.0), (0.5, 0.5), ('64MB', 64.0), ('2GB', 2000.0), ('500kB', 0.5), ('500 KB', 0.5),
    ('1.5GiB', 1.5 * 1024 ** 3 / 1e6), ('512MiB', 512 * 1024 ** 2 / 1e6), ('100B', 1e-4), ('0', 0.0),
])
def test_a_size_is_a_number_of_mb_or_has_a_unit(value, megabytes):
    p, logged = params(max_disk_mb=value)
    assert p.option('max_disk_mb') == pytest.approx(megabytes)
    assert logged == ['~max_disk_mb: %s' % (value,)]


def test_topic_rates_are_messages_per_second_of_wall_time_between_calls():
    now = [100.0]
    rates = node_common.TopicRates(clock=lambda: now[0])
    now[0] = 102.0
    assert rates.values({'/odom': 100, '/imu': 0}) == [('rate /imu Hz', '0.00'), ('rate /odom Hz', '50.00')]
    now[0] = 102.5  # a topic subscribed since: counted from 0
    assert rates.values({'/odom': 105, '/imu': 0, '/scan': 1}) == [
        ('rate /imu Hz', '0.00'), ('rate /odom Hz', '10.00'), ('rate /scan Hz', '2.00')]
    assert rates.values({'/odom': 110}) == [('rate /odom Hz', '0.00')]  # no time passed: no division by zero
    now[0] = 104.5
    assert rates.values({'/camera': 60}, {'/camera': 120 * 10 ** 6}) == [
        ('rate /camera Hz', '30.00'), ('MB/s /camera', '60.000')]  # bytes too: MB/s (10^6 bytes)


def test_the_status_has_the_nodes_level_message_values_and_topic_rates():
    from diagnostic_msgs.msg import DiagnosticStatus
    from diagnostic_updater import DiagnosticStatusWrapper
    counts = {'/odom': 0}
    diagnostics = node_common.Diagnostics('cc_log: smart_logger', 0, lambda: (
        DiagnosticStatus.WARN, 'low disk space', [('windows saved', 3), ('enabled', True)]), lambda: dict(counts))
    assert diagnostics.updater is None  # period 0: off
    counts['/odom'] = 40
    stat = diagnostics._run(DiagnosticStatusWrapper())
    assert (stat.level, stat.message) == (DiagnosticStatus.WARN, 'low disk space')
    values = [(kv.key, kv.value) for kv in stat.values]
    assert values[:2] == [('windows saved', '3'), ('enabled', 'True')]
    assert [key for key, _ in values[2:]] == ['rate /odom Hz'] and float(values[2][1]) > 0
    diagnostics.publish()  # off: nothing, no error
    diagnostics.stop()


REUSE_PROBE = r'''
import queue, resource, sys, threading
sys.path[:0] = %r
if sys.argv[1] == 'reuse':
    from cc_log.nodes import node_common
    assert node_common.reuse_freed_memory()
# As a node does: a subscriber thread receives camera frames, another thread frees them once written; the page
# faults of receiving the last of four such bursts.
bursts, freed, faults = queue.Queue(), queue.Queue(), []
def receive():
    for _ in range(4):
        freed.get()
        before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        burst = [bytearray(921600) for _ in range(40)]
        faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
        bursts.put(burst)
        del burst
receiver = threading.Thread(target=receive)
receiver.start()
freed.put(None)
for _ in range(4):
    del bursts.get()[:]
    freed.put(None)
receiver.join()
print(faults[-1])
'''


def test_freed_message_buffers_are_reused_instead_of_mapped_again():
    import subprocess
    import sys

    def faults(mode):
        out = subprocess.run([sys.executable, '-c', REUSE_PROBE % (sys.path,), mode], stdout=subprocess.PIPE,
                             universal_newlines=True, check=True).stdout
        return int(out.split()[-1])
    pages = 40 * 921600 // 4096  # the burst's buffers in 4 kB pages
    default, reused = faults('default'), faults('reuse')
    assert default > pages / 2  # glibc hands the burst back and maps it again: a fault per page
    assert reused < pages / 10


def test_an_unknown_parameter_is_warned_with_the_nearest_known_name():
    p = Params(get={}.get, log=lambda *args: None,
               names=lambda: ['formt', 'model', 'triggers', 'windows', 'xyzzy', 'max_bufer_mb', 'topics'])
    assert p.unknown() == ['unknown parameter ~formt (did you mean ~format?)',
                           'unknown parameter ~max_bufer_mb (did you mean ~max_buffer_mb?)',
                           'unknown parameter ~xyzzy']
    assert Params(get={}.get, names=lambda: ['model', 'pre', 'json_xz', 'limits']).unknown() == []


def test_record_settings_are_the_parameters_checked_for_unknown_names():
    node_common.read_settings_only({'formt': 'json-xz', 'directory': '/tmp/x'})
    try:
        assert Params().unknown() == ['unknown parameter ~formt (did you mean ~format?)']
    finally:
        node_common._SETTINGS[:] = []
