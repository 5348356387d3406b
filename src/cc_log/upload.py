"""The upload hook: a command run, detached, after each window or context file is closed, with the file's path.

``UploadHook(command)``: ``command`` is an argument list (``['rsync', '-a', '--remove-source-files']``, or a
string split like a shell would split words, ``shlex.split``, but never run by a shell: no variables, no
pipes, no globbing). After each closed file the hook starts ``command + [path]`` in a session of its own
(like bwi_logging's ``setsid bwi bags``: it survives the logger's shutdown and its signals), stdin from
/dev/null, and a thread waits for it: an exit status other than 0, a signal or a command that cannot be started
is counted and said in ``last_error`` (with the last line of its stderr), for the node's /diagnostics.

``on_event(WriterEvent)`` hooks it to a ``WindowWriter``: WRITTEN events of window and context files start
it (not feature vectors). Pure (subprocess, threading).
"""
import shlex
import subprocess
import threading

from . import window_writer
from .safe_input import brief

__all__ = ['UploadHook', 'parse_command']

STDERR_TAIL = 4096  # bytes of a failing command's stderr kept for its error line


def parse_command(value, name='upload_command'):
    """The argument list of ``value`` (a list of strings, or a string split into words); [] for empty;
    ValueError('<name>: ...')."""
    if value is None or value == '':
        return []
    if isinstance(value, str):
        try:
            words = shlex.split(value)
        except ValueError as error:
            raise ValueError('%s: %s cannot be split into arguments: %s' % (name, brief(value), error))
    elif isinstance(value, (list, tuple)) and all(isinstance(word, str) for word in value):
        words = list(value)
    else:
        raise ValueError('%s: %s is not an argument list' % (name, brief(value)))
    if words and not words[0].strip():
        raise ValueError('%s: %s has no program' % (name, brief(value)))
    return words


class UploadHook(object):
    """Runs ``command + [path]`` detached after each closed file (see the module docstring). Thread-safe.

    Counters in ``stats()``: started, succeeded, failed, running; last_error, last_path."""

    def __init__(self, command, popen=subprocess.Popen):
        self.command = parse_command(command)
        self._popen = popen
        self._lock = threading.Lock()
        self._counts = {'started': 0, 'succeeded': 0, 'failed': 0, 'running': 0}
        self.last_error = ''
        self.last_path = ''

    @property
    def enabled(self):
        """Whether a command is set."""
        return bool(self.command)

    def on_event(self, event):
        """A WindowWriter event: run the command for each window or context file written."""
        if event.kind == window_writer.WRITTEN and event.job is not None and event.path and \
                event.job.what in (window_writer.WINDOW, window_writer.CONTEXT):
            self.run(event.path)

    def run(self, path):
        """Start the command for ``path`` (returns at once; a thread waits for it)."""
        if not self.command:
            return
        argv = self.command + [str(path)]
        with self._lock:
            self._counts['started'] += 1
            self._counts['running'] += 1
            self.last_path = str(path)
        try:
            process = self._popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                  start_new_session=True, close_fds=True)
        except (OSError, ValueError) as error:
            self._done(path, 'cannot run %s: %s' % (argv[0], error))
            return
        waiter = threading.Thread(target=self._wait, args=(process, path), name='cc_log upload')
        waiter.daemon = True
        waiter.start()

    def _wait(self, process, path):
        _, stderr = process.communicate()
        status = process.returncode
        if status == 0:
            self._done(path, None)
            return
        tail = (stderr or b'')[-STDERR_TAIL:].decode('utf-8', 'replace').strip().splitlines()
        how = 'exit status %d' % status if status > 0 else 'signal %d' % -status
        self._done(path, '%s %s: %s%s' % (self.command[0], path, how, (': ' + tail[-1]) if tail else ''))

    def _done(self, path, error):
        with self._lock:
            self._counts['running'] -= 1
            self._counts['failed' if error else 'succeeded'] += 1
            if error:
                self.last_error = error

    def stats(self):
        """Counters and the last error."""
        with self._lock:
            result = dict(self._counts)
            result.update(last_error=self.last_error, last_path=self.last_path)
        return result
