"""The upload hook: a command run, detached, after each window or context file is closed, with the file's path.

``UploadHook(command)``: ``command`` is an argument list (``['rsync', '-a', '--remove-source-files']``, or a
string split like a shell would split words, ``shlex.split``, but never run by a shell: no variables, no
pipes, no globbing). After each closed file the hook starts ``command + [path]`` in a session of its own
(like bwi_logging's ``setsid bwi bags``: it survives the logger's shutdown and its signals), stdin from
/dev/null, and a thread waits for it: an exit status other than 0, a signal or a command that cannot be started
is counted and said in ``last_error`` (with the last line of its stderr, of which only the last STDERR_TAIL
bytes are kept), for the node's /diagnostics.

At most ``max_running`` commands (MAX_RUNNING) run at a time; the paths of files closed meanwhile wait in a
queue of at most ``max_queued`` (MAX_QUEUED), started in order as commands end. A file closed while the queue
is full is not uploaded: it is counted as ``dropped`` (the file stays on disk). A slow uploader thus makes
the queue grow, never the number of processes or threads.

``on_event(WriterEvent)`` hooks it to a ``WindowWriter``: WRITTEN and SPLIT events of window files (every piece:
routes too) and context files start it (not feature vectors). Pure (subprocess, threading).
"""
import collections
import os
import select
import shlex
import subprocess
import threading

from cc_log.base import event_kinds
from cc_log.storage import window_writer
from cc_log.base.safe_input import brief

__all__ = ['UploadHook', 'parse_command']

STDERR_TAIL = 4096  # bytes of a failing command's stderr kept for its error line
MAX_RUNNING = 2     # upload commands running at a time
MAX_QUEUED = 1000   # paths waiting for a command; more are dropped (counted)
POLL_SECONDS = 0.2  # how often a waiting thread looks whether its command has ended


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

    Counters in ``stats()``: started, succeeded, failed, running, queued, dropped; last_error, last_path."""

    def __init__(self, command, popen=subprocess.Popen, max_running=MAX_RUNNING, max_queued=MAX_QUEUED):
        self.command = parse_command(command)
        self._popen = popen
        self.max_running = max(1, int(max_running))
        self.max_queued = max(0, int(max_queued))
        self._lock = threading.Lock()
        self._queue = collections.deque()
        self._counts = {'started': 0, 'succeeded': 0, 'failed': 0, 'running': 0, 'dropped': 0}
        self.last_error = ''
        self.last_path = ''

    @property
    def enabled(self):
        """Whether a command is set."""
        return bool(self.command)

    def on_event(self, event):
        """A WindowWriter event: run the command for each window or context file written (every piece of a
        window: its own file, its route files, each file of a window split at split_mb)."""
        if event.kind in (event_kinds.WRITTEN, event_kinds.SPLIT) and event.job is not None and event.path and \
                event.job.what in (window_writer.WINDOW, window_writer.ROUTE, window_writer.CONTEXT):
            self.run(event.path)

    def run(self, path):
        """Start the command for ``path`` now when fewer than ``max_running`` run, else queue it (or drop it,
        counted, when the queue is full). Returns at once; a thread waits for each command."""
        if not self.command:
            return
        with self._lock:
            if self._counts['running'] >= self.max_running:
                if len(self._queue) >= self.max_queued:
                    self._counts['dropped'] += 1
                    self.last_error = 'upload queue full (%d waiting): not uploaded: %s' % (len(self._queue), path)
                else:
                    self._queue.append(str(path))
                return
            self._counts['running'] += 1
        self._start(str(path))

    def _start(self, path):
        """Start the command for ``path`` (counted as running already) and a thread that waits for it; when
        it cannot be started, the next queued path instead."""
        while path is not None:
            argv = self.command + [path]
            with self._lock:
                self._counts['started'] += 1
                self.last_path = path
            try:
                process = self._popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.PIPE, start_new_session=True, close_fds=True)
            except (OSError, ValueError) as error:
                path = self._done(path, 'cannot run %s: %s' % (argv[0], error))
                continue
            waiter = threading.Thread(target=self._wait, args=(process, path), name='cc_log upload')
            waiter.daemon = True
            waiter.start()
            return

    def _wait(self, process, path):
        """Wait for the command to end, keeping the last STDERR_TAIL bytes of its stderr; a process it left
        behind holding stderr open (an ssh master) does not hold the slot."""
        tail, stream, reading = bytearray(), process.stderr, True
        while True:
            status = process.poll()
            if reading:
                readable = select.select([stream], [], [], 0 if status is not None else POLL_SECONDS)[0]
                while readable:
                    chunk = os.read(stream.fileno(), 65536)
                    if not chunk:  # closed: nothing more to read
                        reading = False
                        break
                    tail += chunk
                    del tail[:-STDERR_TAIL]
                    readable = select.select([stream], [], [], 0)[0]
            if status is not None:
                break
            if not reading:
                status = process.wait()
                break
        stream.close()
        error = None
        if status != 0:
            lines = bytes(tail).decode('utf-8', 'replace').strip().splitlines()
            how = 'exit status %d' % status if status > 0 else 'signal %d' % -status
            error = '%s %s: %s%s' % (self.command[0], path, how, (': ' + lines[-1][:200]) if lines else '')
        self._start(self._done(path, error))

    def _done(self, path, error):
        """Count the end of the command for ``path``; the queued path to run in its place, or None."""
        with self._lock:
            self._counts['failed' if error else 'succeeded'] += 1
            if error:
                self.last_error = error
            following = self._queue.popleft() if self._queue else None
            if following is None:
                self._counts['running'] -= 1
        return following

    def stats(self):
        """Counters and the last error."""
        with self._lock:
            result = dict(self._counts, queued=len(self._queue))
            result.update(last_error=self.last_error, last_path=self.last_path)
        return result
