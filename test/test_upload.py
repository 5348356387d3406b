"""The upload hook (real processes) and record.launch's mode choice."""
import os
import sys
import time

import pytest

from cc_log.nodes import launcher
from cc_log.base import event_kinds
from cc_log.storage import window_writer
from cc_log.storage.upload import UploadHook, parse_command


def wait_for(condition, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, 'timed out'
        time.sleep(0.01)


def event(kind, what, path):
    job = window_writer.Job(write=lambda: path, what=what)
    return window_writer.WriterEvent(kind, job, path, 0, '', False)


def test_parse_command_is_a_word_list_never_a_shell():
    assert parse_command('rsync -a "my dir/" host:') == ['rsync', '-a', 'my dir/', 'host:']
    assert parse_command(['a b', 'c']) == ['a b', 'c']
    assert parse_command('') == [] and parse_command(None) == []
    for bad in ('"unclosed', [1, 2], 5):
        with pytest.raises(ValueError, match='^upload_command: '):
            parse_command(bad)


def test_runs_once_per_window_or_context_file_with_the_path(tmp_path):
    listing = tmp_path / 'list'
    script = 'import sys; open(sys.argv[1], "a").write(sys.argv[2] + "\\n")'
    hook = UploadHook([sys.executable, '-c', script, str(listing)])
    hook.on_event(event(event_kinds.WRITTEN, window_writer.WINDOW, '/w/a.json.xz'))
    hook.on_event(event(event_kinds.WRITTEN, window_writer.ROUTE, '/w/a+numeric.json.xz'))  # a piece of it
    hook.on_event(event(event_kinds.WRITTEN, window_writer.CONTEXT, '/w/context/c.bag'))
    hook.on_event(event(event_kinds.WRITTEN, 'vector', '/w/features/v.json'))  # not a closed log file
    hook.on_event(event(event_kinds.FAILED, window_writer.WINDOW, ''))
    wait_for(lambda: hook.stats()['running'] == 0)
    assert sorted(listing.read_text().split()) == ['/w/a+numeric.json.xz', '/w/a.json.xz', '/w/context/c.bag']
    assert hook.stats()['succeeded'] == 3 and hook.stats()['failed'] == 0


def test_failures_are_counted_with_the_stderr_line(tmp_path):
    hook = UploadHook([sys.executable, '-c', 'import sys; sys.stderr.write("no route to host\\n"); sys.exit(2)'])
    hook.run('/w/a.bag')
    wait_for(lambda: hook.stats()['running'] == 0)
    stats = hook.stats()
    assert stats['failed'] == 1 and 'exit status 2' in stats['last_error'] and 'no route to host' in stats['last_error']
    missing = UploadHook([str(tmp_path / 'no-such-program')])
    missing.run('/w/a.bag')
    assert missing.stats()['failed'] == 1 and 'cannot run' in missing.stats()['last_error']


def test_the_command_runs_detached_in_its_own_session(tmp_path):
    out = tmp_path / 'sid'
    hook = UploadHook([sys.executable, '-c', 'import os, sys; open(sys.argv[1], "w").write(str(os.getsid(0)))',
                       str(out)])
    hook.run('x')
    wait_for(lambda: hook.stats()['running'] == 0)
    assert int(out.read_text()) != os.getsid(0)


def test_record_launch_mode_choice(tmp_path):
    model = tmp_path / 'model.json'
    module, note = launcher.choose('auto', str(model))
    assert module == 'collect_node' and 'no model yet' in note and str(model) in note
    model.write_text('{}')
    assert launcher.choose('auto', str(model)) == ('smart_node', '')
    assert launcher.choose('collect', str(model)) == ('collect_node', '')
    assert launcher.choose('smart', '') == ('smart_node', '')
    with pytest.raises(ValueError, match='^mode: '):
        launcher.choose('fast', '')


BLOCKING = ('import os, sys, time\n'
            'folder, path = sys.argv[1], sys.argv[2]\n'
            'open(os.path.join(folder, "started-%d" % os.getpid()), "w").close()\n'
            'while not os.path.exists(os.path.join(folder, "release")):\n'
            '    time.sleep(0.01)\n'
            'open(os.path.join(folder, "done-%d" % os.getpid()), "w").close()\n')


def test_a_slow_uploader_runs_two_at_a_time_and_queues_the_rest(tmp_path):
    hook = UploadHook([sys.executable, '-c', BLOCKING, str(tmp_path)])
    for index in range(40):
        hook.run('/w/%d.bag' % index)
    started = lambda: [name for name in os.listdir(str(tmp_path)) if name.startswith('started-')]  # noqa: E731
    wait_for(lambda: len(started()) == 2)
    stats = hook.stats()
    assert (stats['running'], stats['queued'], stats['started']) == (2, 38, 2)
    assert len(started()) == 2
    (tmp_path / 'release').write_text('')
    wait_for(lambda: hook.stats()['succeeded'] == 40, timeout=60)
    stats = hook.stats()
    assert (stats['running'], stats['queued'], stats['dropped'], stats['started']) == (0, 0, 0, 40)


def test_a_full_queue_drops_and_counts(tmp_path):
    hook = UploadHook([sys.executable, '-c', BLOCKING, str(tmp_path)], max_running=1, max_queued=3)
    for index in range(10):
        hook.run('/w/%d.bag' % index)
    stats = hook.stats()
    assert (stats['running'], stats['queued'], stats['dropped']) == (1, 3, 6)
    assert stats['last_error'] == 'upload queue full (3 waiting): not uploaded: /w/9.bag'
    (tmp_path / 'release').write_text('')
    wait_for(lambda: hook.stats()['succeeded'] == 4)
    wait_for(lambda: hook.stats()['running'] == 0)


def test_a_program_that_cannot_start_lets_the_queue_run_on(tmp_path):
    hook = UploadHook([str(tmp_path / 'no-such-program')], max_running=1)
    hook.run('/w/a.bag')
    assert hook.stats()['failed'] == 1 and hook.stats()['running'] == 0


def test_only_the_tail_of_a_failing_commands_stderr_is_kept():
    import tracemalloc
    noisy = ('import sys\n'
             'for _ in range(400):\n'
             '    sys.stderr.write("x" * 99999 + "\\n")\n'
             'sys.stderr.write("the last line\\n")\n'
             'sys.exit(4)\n')
    hook = UploadHook([sys.executable, '-c', noisy])
    tracemalloc.start()
    try:
        hook.run('/w/a.bag')
        wait_for(lambda: hook.stats()['running'] == 0, timeout=60)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    stats = hook.stats()
    assert stats['failed'] == 1 and stats['last_error'].endswith('exit status 4: the last line')
    assert peak < 5 * 10 ** 6, peak  # 40 MB were written to stderr


def test_a_process_left_holding_stderr_does_not_hold_the_upload(tmp_path):
    pid_file = tmp_path / 'pid'
    script = ('import subprocess, sys\n'
              'left = subprocess.Popen(["sleep", "60"])\n'  # inherits stderr, like an ssh master
              'open(sys.argv[1], "w").write(str(left.pid))\n'
              'sys.stderr.write("connection kept\\n")\n'
              'sys.exit(5)\n')
    hook = UploadHook([sys.executable, '-c', script, str(pid_file)])
    try:
        hook.run('/w/a.bag')
        wait_for(lambda: hook.stats()['running'] == 0)
        assert hook.stats()['last_error'].endswith('exit status 5: connection kept')
    finally:
        wait_for(lambda: pid_file.exists() and pid_file.read_text())
        os.kill(int(pid_file.read_text()), 9)
