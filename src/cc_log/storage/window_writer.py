"""The one writer behind smart and collect mode (live and offline): every file they write goes through it.

``WindowWriter(directory, fmt, ...)`` takes ``Job``s, a LogWindow to write as a window file
(``log_format.write_window``) or another file such as a feature vector (a function that writes it), and
writes them in order, on a background thread (``background=True``) or in the calling thread:

- a job that fails for a reason that may pass (disk full, quota, permissions, a missing or read-only
  directory: ``disk_guard.is_retryable``) or that the free-space floor (``min_free_mb``) stops is *held*
  in memory, in order, and retried every ``retry_period`` seconds; later jobs wait behind it. Held jobs are
  bounded (``max_held_messages``, a non-window job counting as one message): beyond, the oldest is lost.
- with a quota (``max_disk_mb``): when a write fails for lack of space or the floor stops it, the quota
  first makes room by deleting the oldest cc_log window files (by time written) until the files plus the
  expected size of the job fit, and the write is tried again at once; after each window file is written,
  the oldest files beyond the quota are deleted (never the file just written).
- ``give_up_after`` (offline commands): a job still failing that many seconds after its first failure is
  lost instead of held. ``close`` writes what is queued, then retries held jobs for up to ``close_retry``
  seconds; what is still unwritten then is lost.
- ``split_mb`` (0: off): a window written a part at a time (a format with a ``WindowStream``) goes on in a new
  file at the first part after its file reached that size (``log_format.WindowFile``), as ``rosbag record
  --split --size`` does; each file finished so before the window's end is a SPLIT event and counts against the
  quota as a window file does. A window written at once (json-xz, a window never handed on in parts) is one file.
- every outcome is an event ``WriterEvent(kind, job, path, bytes, error, kept)``, its kind one of
  ``base.event_kinds``: WRITTEN, FAILED (``kept`` True: held and retried, said once per job; False: lost for
  good, always said), SPLIT (a file of a window finished at ``split_mb``: ``path``, ``bytes``; the job of the part
  that began the next file) and DELETED (a window file deleted by the quota: ``path``, ``bytes``; ``error`` says
  why, and ``FOREIGN_NOTE`` for a file this writer did not write); and a counter in ``stats()``.

Pure: no rospy.
"""
import collections
import queue
import threading
import time

from cc_log.storage import disk_guard
from cc_log.storage import log_format
from cc_log.base.event_kinds import DELETED, FAILED, SPLIT, WRITTEN
from cc_log.base.records import LogWindow
from cc_log.base.spans import megabytes, seconds

__all__ = ['WindowWriter', 'Job', 'WriterEvent', 'DEFAULT_RETRY_PERIOD',
           'DEFAULT_MAX_HELD_MESSAGES', 'OFFLINE_RETRY_SECONDS', 'OFFLINE_RETRY_PERIOD', 'WINDOW', 'CONTEXT']

FOREIGN_NOTE = ', a file not written by this run'  # said of a file the quota deleted that an earlier run left
WINDOW = 'window'  # Job.what of a window file
CONTEXT = 'context'  # Job.what of a closed context-track file (counted in the quota like a window)
ROUTE = 'route'  # Job.what of a route's file of a window (base.routes): the window is counted once, by its own

DEFAULT_RETRY_PERIOD = 2.0         # seconds between attempts to write held jobs
DEFAULT_MAX_HELD_MESSAGES = 50000  # messages of unwritten windows kept in memory; beyond, the oldest go
OFFLINE_RETRY_SECONDS = 5.0        # offline commands: how long a failing write is retried before they fail
OFFLINE_RETRY_PERIOD = 0.5         # offline commands: seconds between those attempts

WriterEvent = collections.namedtuple('WriterEvent', 'kind job path bytes error kept')
WriterEvent.__doc__ = """What happened to a job (WRITTEN, FAILED) or to an old window file (DELETED, job None).

path, bytes: the file written or deleted ('' and 0 for FAILED); error: why the job failed, with what happens
next; kept: for FAILED, True when the job is held in memory and retried, False when it is lost.
"""


class Job(object):
    """One file for the writer: ``window`` (a LogWindow) with ``metadata`` for ``log_format.write_window``, or
    ``write``, a function that writes another file and returns its path. ``what`` names the kind of file
    (``'window'`` for windows; e.g. ``'vector'``); ``tag``: anything the owner wants back in events. ``fmt`` and
    ``route``: the window's file of a route (``base.routes``) in that format, named ``<name>+<route>``; ``name``:
    the window's ``log_format.WindowName``, shared by the jobs of all its files (its parts, its routes) and reserved
    at the first one's write (None: a name of its own, or for a part (``LogWindow.key``) its first part's);
    ``last``: the window's last job (its name's reservation is released once it is done). A copy route's file
    (``metadata['copy']``) counts no messages or memory: its window's own file does."""

    __slots__ = ('window', 'metadata', 'write', 'what', 'tag', 'messages', 'bytes', 'failed_at', 'reported', 'whole',
                 'fmt', 'route', 'name', 'last')

    def __init__(self, window=None, metadata=None, write=None, what=None, tag=None, fmt=None, route=None,
                 name=None, last=True):
        if (window is None) == (write is None):
            raise ValueError('job: give either a window or a write function')
        self.window = window
        self.metadata = metadata
        self.write = write
        self.what = what or (WINDOW if window is not None else 'file')
        self.tag = tag
        counted = window is not None and not (metadata or {}).get('copy')  # a copy route's: counted by its window's
        self.messages = len(window) if counted else 0
        self.bytes = sum(record.cost for record in window.records) if counted else 0  # memory held
        self.whole = None       # a window written a part at a time, as a whole, once its file is finished
        self.failed_at = None   # clock of the first failure
        self.reported = False   # a FAILED (kept) event was sent
        self.fmt, self.route = fmt, route
        self.name, self.last = name, last

    @property
    def stream_key(self):
        """The window file this job's part belongs to: the window's key and the route."""
        return (self.window.key, self.route)

    @property
    def weight(self):
        """What the job counts against max_held_messages."""
        return max(1, self.messages)


class WindowWriter(object):
    """Writes jobs in order with hold, retry, quota and free-space floor (see the module docstring).

    directory: where window files go; fmt: their format; max_disk_mb, min_free_mb: ``disk_guard`` limits
    (0: off); retry_period: seconds between attempts for held jobs; max_held_messages: bound of held
    jobs; background: write on a thread (True) or in the caller's (False: ``submit`` writes, and with
    ``give_up_after`` it waits for a failing job to be written or lost); give_up_after: seconds after which
    a failing job is lost (None: held until ``close``); close_retry: seconds ``close`` keeps retrying;
    split_mb: the size at which a window written a part at a time goes on in a new file (0: never);
    max_files: the quota in files (``disk_guard``; 0: none); prefix: what file names begin with
    (``log_format.file_prefix``).

    Thread-safe: ``submit``, ``stats`` and ``close`` may be called from any thread. Bad values raise
    ``ValueError('<parameter>: ...')``.
    """

    def __init__(self, directory, fmt=log_format.Format.JSON_XZ, max_disk_mb=0, min_free_mb=0,
                 retry_period=DEFAULT_RETRY_PERIOD, max_held_messages=DEFAULT_MAX_HELD_MESSAGES, background=True,
                 give_up_after=None, close_retry=0.0, split_mb=0, name='cc_log window writer', max_files=0,
                 prefix=log_format.PREFIX):
        self.directory = str(directory)
        self.format = log_format.Format.check(fmt)
        self.prefix = prefix
        self.guard = disk_guard.DiskGuard(self.directory, max_disk_mb, min_free_mb, max_files=max_files,
                                          prefix=prefix)
        self.retry_period = seconds(retry_period, 'retry_period', positive=True)
        self.give_up_after = None if give_up_after is None else seconds(give_up_after, 'give_up_after')
        self.close_retry = seconds(close_retry, 'close_retry')
        self.split_bytes = int(megabytes(split_mb, 'split_mb') * disk_guard.MB)
        self.max_held_messages = int(max_held_messages)
        self._held = collections.deque()  # jobs that failed, oldest first (writer thread only)
        self._held_weight = 0
        self._next_retry = 0.0            # monotonic clock of the next attempt at held jobs
        self._callbacks = []
        self._lock = threading.Lock()
        self._drained = threading.Condition(self._lock)  # notified when queued jobs are written or lost
        self._counts = collections.Counter()
        self._written = collections.Counter()  # files written by Job.what
        self.last_error = ''
        self.last_deleted = ''
        self._closed = False
        self.cpu_seconds = 0.0            # CPU time of the writer thread writing (decoding, compressing, disk)
        self._streams = {}                # (window key, route) -> its log_format.WindowFile being written
        self._triggers_said = {}          # (window key, route) -> its triggers in the files of its parts so far
        self._names = set()               # the WindowNames reserved and not yet released
        self._part_names = {}             # window key -> WindowName of a window in parts whose jobs bring none
        self._queue = queue.Queue()
        self._thread = None
        if background:
            self._thread = threading.Thread(target=self._loop, name=name)
            self._thread.daemon = True
            self._thread.start()

    # -- public API -----------------------------------------------------------------------------------

    def on_event(self, callback):
        """Call ``callback(WriterEvent)`` from the writing thread after each outcome; it must not raise."""
        self._callbacks.append(callback)

    @property
    def bytes_queued(self):
        """Memory of the records of the jobs waiting or held (cheap: one counter)."""
        return self._counts['bytes_queued']

    @property
    def lost(self):
        """Jobs lost so far (an offline command stops at the first)."""
        return self._counts['jobs_lost']

    def wait_for_room(self, limit):
        """Wait until the jobs waiting or held take at most ``limit`` bytes (``bytes_queued``; at most 0 for a
        ``limit`` below it), or no writer thread is left to write them (at once without one: ``submit`` writes).
        Offline, reading waits so for the writer instead of thinning windows (``SmartLogger``'s
        ``wait_for_writer``)."""
        thread = self._thread
        if self._counts['bytes_queued'] <= max(0, limit):
            return
        with self._drained:
            while self._counts['bytes_queued'] > max(0, limit) and thread is not None and thread.is_alive():
                self._drained.wait(1.0)

    def submit(self, job):
        """Queue a job (write it now without a background thread)."""
        with self._lock:
            if self._closed:
                raise ValueError('submit: the writer is closed')
            self._counts['jobs_queued'] += 1
            self._counts['messages_queued'] += job.messages
            self._counts['bytes_queued'] += job.bytes
        if self._thread is not None:
            self._queue.put(job)
        else:
            self._write(job)

    def close(self, timeout=None):
        """Write every queued job, retry held ones up to ``close_retry`` s, lose what is still unwritten.

        Idempotent. Returns True when that finished within ``timeout`` seconds (None: wait)."""
        with self._lock:
            first = not self._closed
            self._closed = True
        if first:
            if self._thread is not None:
                self._queue.put(None)
            else:
                self._finish()
        if self._thread is not None:
            self._thread.join(timeout)
            return not self._thread.is_alive()
        return True

    def stats(self):
        """Counters (a dict): jobs_queued, messages_queued, bytes_queued (waiting, held included: the memory their
        records take), windows_saved,
        messages_kept, stored_bytes, written ({what: files}), split_files (finished at split_mb), jobs_lost,
        messages_lost, write_errors, write_retries, last_error, jobs_held, messages_held, disk_paused,
        windows_deleted, bytes_deleted, last_deleted, queue_depth."""
        with self._lock:
            result = {key: self._counts[key] for key in (
                'jobs_queued', 'messages_queued', 'bytes_queued', 'messages_kept', 'stored_bytes', 'jobs_lost',
                'messages_lost', 'write_errors', 'write_retries', 'jobs_held', 'messages_held', 'windows_deleted')}
            result['written'] = dict(self._written)
            result['windows_saved'] = self._written[WINDOW]
            result['split_files'] = self._counts['split_files']
            result['last_error'] = self.last_error
            result['last_deleted'] = self.last_deleted
        result['bytes_deleted'] = self.guard.deleted_bytes
        result['disk_paused'] = self.guard.paused
        result['queue_depth'] = self._queue.qsize() if self._thread is not None else 0
        return result

    # -- writing (the writer thread, or the caller's without one) ---------------------------------------

    def _loop(self):
        while True:
            try:
                job = self._queue.get(timeout=max(0.0, self._next_retry - time.monotonic()) if self._held else None)
            except queue.Empty:
                self._retry_held()
                continue
            started = time.thread_time()
            try:
                if job is None:
                    self._finish()
                    return
                self._write(job)
            finally:
                self.cpu_seconds += time.thread_time() - started
                self._queue.task_done()

    def _write(self, job):
        self._retry_held()
        if self._held or not self._attempt(job):  # older jobs still wait: keep the order
            self._hold(job)
        if self._thread is None and self.give_up_after is not None:
            self._wait_held(self.give_up_after + self.retry_period)

    def _finish(self):
        self._wait_held(self.close_retry)
        self._retry_held(final=True)
        for (key, route), stream in list(self._streams.items()):  # a window whose last part never came
            self._write(Job(LogWindow([], stream.triggers, 1, True, key), stream.metadata, fmt=stream.format,
                            route=route, name=log_format.WindowName(name=stream.name.name)))
        for name in list(self._names):  # windows whose last job never came
            self._release(name)

    def _wait_held(self, seconds):
        """Retry held jobs every retry_period for up to ``seconds`` or until none is held."""
        deadline = time.monotonic() + seconds
        self._retry_held()
        while self._held and time.monotonic() < deadline:
            time.sleep(max(0.0, min(self._next_retry, deadline) - time.monotonic()))
            self._retry_held()

    def _retry_held(self, final=False):
        """Write held jobs, oldest first, until one fails again (then they wait for the next period). Held
        jobs are tried at most once per retry_period (a window may be costly to encode), except ``final``."""
        if self._held and not final and time.monotonic() < self._next_retry:
            return
        while self._held:
            job = self._held[0]
            if not self._attempt(job, final):
                return
            self._held.popleft()
            self._held_weight -= job.weight
            with self._lock:
                self._counts['jobs_held'] -= 1
                self._counts['messages_held'] -= job.messages

    def _hold(self, job):
        """Keep an unwritten job in memory; beyond max_held_messages the oldest held jobs are lost."""
        self._held.append(job)
        self._held_weight += job.weight
        with self._lock:
            self._counts['jobs_held'] += 1
            self._counts['messages_held'] += job.messages
        while len(self._held) > 1 and self._held_weight > self.max_held_messages:
            old = self._held.popleft()
            self._held_weight -= old.weight
            with self._lock:
                self._counts['jobs_held'] -= 1
                self._counts['messages_held'] -= old.messages
            self._lose(old, 'more than %d messages held in memory: the oldest unwritten %s (%d messages) was '
                       'dropped' % (self.max_held_messages, old.what, old.messages))

    def _attempt(self, job, final=False):
        """Try to write a job once (making room first when space is short); True when it is done: written,
        or lost (not retryable, given up, or ``final``)."""
        failure = self._try(job)
        if failure is None:
            return True
        error, retryable, attempted = failure
        now = time.monotonic()
        if job.failed_at is None:
            job.failed_at = now
        self._next_retry = now + self.retry_period
        with self._lock:
            if attempted:  # a write that failed (not one the free-space floor held back)
                self._counts['write_retries' if job.reported else 'write_errors'] += 1
            self.last_error = error
        expired = self.give_up_after is not None and now - job.failed_at >= self.give_up_after
        if retryable and not final and not expired:
            if attempted and not job.reported:
                job.reported = True
                self._emit(WriterEvent(FAILED, job, '', 0, '%s (kept in memory; retrying every %g s)'
                                       % (error, self.retry_period), True))
            return False
        if retryable and final:
            error = '%s (still failing at close%s)' % (
                error, ', after retrying for %g s' % self.close_retry if self.close_retry else '')
        elif retryable:
            error = '%s (given up after retrying for %.1f s)' % (error, now - job.failed_at)
        self._lose(job, error)
        return True

    def _try(self, job):
        """Write once; None when written, else ``(error, retryable, attempted)`` (attempted: the write itself
        failed, as opposed to the free-space floor stopping it). On lack of space the quota makes room and
        the write is tried once more."""
        made_room = False
        while True:
            allowed, why = self.guard.check()
            if allowed:
                try:
                    path, nbytes = self._write_file(job)
                except Exception as failure:  # OSError, ValueError, rosbag's exceptions: the writer must go on
                    error, retryable = str(failure) or type(failure).__name__, disk_guard.is_retryable(failure)
                    short = disk_guard.is_out_of_space(failure)
                else:
                    self._written_file(job, path, nbytes)
                    return None
            else:
                error, retryable, short = why, True, True
            if made_room or not short or not self._make_room(job):
                return error, retryable, allowed
            made_room = True

    def _write_file(self, job):
        """Write a job: ``(path, bytes)``; ``(None, 0)`` for a part appended to a window file not yet finished."""
        window = job.window
        if window is None:
            return job.write(), 0
        fmt, key, name = job.fmt or self.format, job.stream_key, self._take_name(job)
        if window.part and window.key is not None and log_format.streams(fmt):
            stream = self._streams.get(key)
            if stream is None:
                if not window.records:  # a route none of whose topics came yet: no file
                    return None, 0
                stream = self._streams[key] = log_format.WindowFile(
                    self.directory, fmt, job.route, name, self.split_bytes, self.prefix)
            try:
                if not window.final:
                    stream.append(window, job.metadata)
                    return None, 0
                path, nbytes = stream.finish(window, job.metadata)
            finally:
                for closed in stream.take_closed():
                    self._split_file(job, *closed)
            del self._streams[key]
            job.whole = stream.summary
            return path, nbytes
        parted = bool(window.part) and window.key is not None
        if not window.records:  # the end of a window written as files of its parts: nothing more to write
            if parted and window.final:
                self._triggers_said.pop(key, None)
            return None, 0
        # a part's file says the triggers that came since the part before it (a part's window holds all of them)
        triggers = window.triggers[self._triggers_said.get(key, 0):] if parted else None
        left_out = collections.Counter()  # messages that could not be decoded (json-xz): lost, not kept
        base = log_format.piece_name(name, job.route, window.part if parted else 0)
        path, nbytes = log_format.write_window(window, self.directory, fmt, job.metadata, left_out=left_out,
                                               triggers=triggers, base=base, prefix=self.prefix)
        if parted and window.final:
            self._triggers_said.pop(key, None)
        elif parted:
            self._triggers_said[key] = len(window.triggers)
        if left_out:
            with self._lock:
                self._counts['messages_lost'] += sum(left_out.values())
                self._counts['messages_kept'] -= sum(left_out.values())
                self.last_error = '%s: %d messages left out, their bytes cannot be decoded (per topic in its ' \
                    'metadata)' % (path, sum(left_out.values()))
        return path, nbytes

    def window_name(self, window):
        """A ``log_format.WindowName`` for the jobs of all the files of ``window`` (its parts, its routes): its
        ``base_name`` with this writer's prefix, reserved at the first one's write."""
        return log_format.WindowName(log_format.base_name(window, self.prefix), prefix=self.prefix)

    def _take_name(self, job):
        """The name of the job's window, reserved at its first piece (OSError: the directory cannot be written)."""
        if job.name is None:
            window = job.window
            if window.part and window.key is not None:  # every part of a window takes its first part's name
                job.name = self._part_names.pop(window.key, None) or log_format.WindowName(prefix=self.prefix)
                job.last = window.final
                if not window.final:
                    self._part_names[window.key] = job.name
            else:
                job.name = log_format.WindowName(prefix=self.prefix)
        if job.name.name is None:
            job.name.take(self.directory, job.window)
            self._names.add(job.name)
        return job.name.name

    def _release(self, name):
        name.release()
        self._names.discard(name)

    def _written_file(self, job, path, nbytes):
        if job.last and job.name is not None:
            self._release(job.name)
        with self._lock:
            self._counts['jobs_queued'] -= 1
            self._counts['messages_queued'] -= job.messages
            self._counts['bytes_queued'] -= job.bytes
            self._drained.notify_all()
            self._counts['messages_kept'] += job.messages
            self._counts['stored_bytes'] += nbytes
            if path is not None:
                self._written[job.what] += 1
        if path is None:  # a part appended to its window's file
            return
        if job.whole is not None:  # a window written a part at a time: said as a whole
            job = Job(job.whole, job.metadata, what=job.what, tag=job.tag)
        self._emit(WriterEvent(WRITTEN, job, path, nbytes, '', False))
        if job.window is not None or job.what == CONTEXT:
            self._quota(keep=path)

    def _split_file(self, job, path, nbytes):
        """A file of a window finished at split_mb: counted, said (SPLIT) and within the quota."""
        with self._lock:
            self._counts['stored_bytes'] += nbytes
            self._counts['split_files'] += 1
        self._emit(WriterEvent(SPLIT, job, path, nbytes, '', False))
        self._quota(keep=path)

    def _make_room(self, job):
        """Lack of space: delete the oldest window files beyond the quota, with room for ``job``; whether any
        was deleted."""
        with self._lock:
            kept, stored = self._counts['messages_kept'], self._counts['stored_bytes']
        expected = job.messages * stored // kept if kept else 0
        return bool(self._quota(reserve=expected))

    def _quota(self, keep=(), reserve=0):
        if not self.guard.has_quota:
            return []
        deleted = []
        for path in self.guard.enforce_quota(keep=keep, reserve=reserve):
            with self._lock:
                self._counts['windows_deleted'] += 1
                self.last_deleted = path
            deleted.append(path)
            foreign = FOREIGN_NOTE if path in self.guard.last_foreign else ''
            self._emit(WriterEvent(DELETED, None, path, 0, 'deleted to stay within %s%s' % (
                self.guard.quota_text(), foreign), False))
        return deleted

    def _lose(self, job, error):
        window = job.window
        if job.last and job.name is not None:
            self._release(job.name)
        stream = self._streams.get(job.stream_key) if window is not None and window.key is not None else None
        if stream is not None:
            stream.lose(window, job.metadata)
            if window.final:  # what was written stays in its temporary file, for recovery at the next start
                del self._streams[job.stream_key]
                stream.abandon()
        with self._lock:
            self._counts['jobs_queued'] -= 1
            self._counts['bytes_queued'] -= job.bytes
            self._drained.notify_all()
            self._counts['messages_queued'] -= job.messages
            self._counts['jobs_lost'] += 1
            self._counts['messages_lost'] += job.messages
            self.last_error = error
        self._emit(WriterEvent(FAILED, job, '', 0, error, False))

    def _emit(self, event):
        for callback in self._callbacks:
            callback(event)
