"""The upload hook (real processes) and record.launch's mode choice."""
import os
import sys
import time

import pytest

from cc_log import launcher, window_writer
from cc_log.upload import UploadHook, parse_command


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
    hook.on_event(event(window_writer.WRITTEN, window_writer.WINDOW, '/w/a.json.xz'))
    hook.on_event(event(window_writer.WRITTEN, window_writer.CONTEXT, '/w/context/c.bag'))
    hook.on_event(event(window_writer.WRITTEN, 'vector', '/w/features/v.json'))  # not a closed log file
    hook.on_event(event(window_writer.FAILED, window_writer.WINDOW, ''))
    wait_for(lambda: hook.stats()['running'] == 0)
    assert sorted(listing.read_text().split()) == ['/w/a.json.xz', '/w/context/c.bag']
    assert hook.stats()['succeeded'] == 2 and hook.stats()['failed'] == 0


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
