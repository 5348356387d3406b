"""Smart mode: keep only the messages around anomalous behaviour.

``SmartLogger`` is the one implementation behind the live node (``smart_node``) and offline replay
(``replay``, used by ``cclog replay``). Feed it every message with ``on_message``:

- the driving topic (nav_msgs/Odometry) becomes a feature row; once the feature window is full, the window
  is turned into a vector and scored by the model, and an anomalous score opens (or extends) a logging
  window of ``pre`` messages before and ``post`` after;
- other topics are buffered by time and saved in the windows whose time span holds them.

Completed windows go through a queue to a background writer thread that calls
``log_format.write_window``, so compression and disk writes never run on the message path and no message
is lost while a window is written. ``stats()`` feeds the node's diagnostics; ``on_event`` callbacks hear
when a window opens, is written or fails to be written.

Pure: no rospy (``replay`` imports ``bagio``, and so rosbag, only when called).
"""
import collections
import math
import queue
import threading
import time

from . import disk_guard
from . import features as features_mod
from . import log_format
from . import msg_codec
from .spans import Span
from .window_buffer import DEFAULT_MAX_WINDOW, DEFAULT_POST, DEFAULT_PRE, Record, WindowBuffer

__all__ = ['SmartLogger', 'Event', 'OPENED', 'WRITTEN', 'FAILED', 'DELETED', 'replay',
           'DEFAULT_FORMAT', 'DEFAULT_PRE', 'DEFAULT_POST', 'DEFAULT_MAX_WINDOW', 'DEFAULT_DRIVING_TOPIC',
           'RETRIGGER_MODES', 'DEFAULT_RETRIGGER', 'DEFAULT_CLASSIFY_EVERY']

DEFAULT_FORMAT = 'json-xz'
DEFAULT_DRIVING_TOPIC = 'odom'

# Which anomalous scores trigger (open or extend a logging window):
# - 'every': every driving message scored anomalous (the paper's rule). A feature window of W messages keeps
#   scoring anomalous for up to W messages after the anomaly itself ended, so windows grow by that tail.
# - 'onset': only the onset, i.e. a message scored anomalous after a message scored nominal (or the first
#   score since the start / a restart): hysteresis at the threshold. While the score stays below the
#   threshold nothing extends the window; a new crossing (the score went back above, then below again)
#   triggers again.
RETRIGGER_MODES = ('every', 'onset')
DEFAULT_RETRIGGER = 'every'

# How often the classifier scores the feature window (a Span): '1' = every driving message (the paper's rule),
# 'N' = every N-th message, a duration such as '50ms' = at most one decision per 50 ms of message time (20
# decisions/s: every 5th message at 100 Hz, every message at 10 Hz). Skipping saves the window vector and the
# model on the skipped messages; an anomaly is still triggered at the message where it is detected (at most
# one period late), and the window's pre part keeps the skipped messages before it.
DEFAULT_CLASSIFY_EVERY = '50ms'
_CLASSIFY_SLACK = 1e-5  # seconds: stamps 10 ms apart add up to 50 ms give or take float rounding

PROGRESS_EVERY = 1000  # replay: messages between progress callbacks

OPENED = 'opened'
WRITTEN = 'written'
FAILED = 'failed'
DELETED = 'deleted'  # an old window file deleted to stay within max_disk_mb (path, bytes)

DEFAULT_RETRY_PERIOD = 2.0         # seconds between attempts to write windows held after a failure
DEFAULT_MAX_HELD_MESSAGES = 50000  # messages of unwritten windows kept in memory; beyond, the oldest go

Event = collections.namedtuple('Event', 'kind stamp reason score threshold start end messages path bytes error')
Event.__doc__ = """What happened to a logging window.

kind: OPENED (the classifier or a manual trigger opened a window), WRITTEN (the window file is on disk),
FAILED (writing it failed; ``error`` says why: once when a disk problem first keeps the window in memory to
be retried, or when it is lost for good) or DELETED (``path``, an old window file, was deleted to stay within
max_disk_mb; stamp, start and end are None). stamp: of the message that triggered (the first trigger of
the window for WRITTEN and FAILED). reason: the first trigger's reason ('classifier',
'manual'); score: the lowest classifier score of the window's triggers (NaN for manual triggers);
threshold: the model's. start, end: header stamps (float s) of the first and last message (end is None for
OPENED). messages, path, bytes: the window's message count (all topics), file and size on disk (0, '' and 0
until WRITTEN).
"""


class _Stats(object):
    """Counters shared by the message path and the writer thread (guarded by one lock)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.messages_seen = 0
        self.messages_kept = 0       # in window files on disk
        self.messages_queued = 0     # in windows waiting for the writer
        self.messages_lost = 0       # in windows whose file could not be written
        self.raw_json_bytes = 0      # row-JSON bytes of every message seen
        self.stored_bytes = 0        # bytes of the window files written
        self.windows_opened = 0
        self.windows_saved = 0
        self.windows_queued = 0
        self.write_errors = 0
        self.last_error = ''
        self.classifier_calls = 0
        self.classifier_seconds = 0.0
        self.classifier_max = 0.0
        self.anomalous = 0           # driving messages the classifier called anomalous
        self.windows_held = 0        # windows kept in memory after a failed (or paused) write
        self.messages_held = 0
        self.write_retries = 0
        self.windows_deleted = 0     # oldest window files deleted by the max_disk_mb quota
        self.bytes_deleted = 0
        self.last_deleted = ''
        self.messages_refused = 0    # a message type other than the topic's (first seen / the model's)
        self.last_refused = ''


class SmartLogger(object):
    """Anomaly-triggered logging of one driving topic plus side topics.

    model: an ``AnomalyModel`` (its ``config`` says the feature set, feature window and topic type);
    directory: where window files go; fmt: ``'json-xz'`` or ``'bag-lz4'``; pre, post, max_window: counts
    (``'100'``) or durations (``'2s'``); driving_topic: the topic name ``on_message`` will be called with
    for the odometry; side_topics: other topic names to keep (messages of any topic not listed are ignored
    unless ``side_topics`` is None, which keeps every other topic); enabled: start enabled or paused;
    background: write windows on a writer thread (True) or inline in the calling thread (False);
    retrigger: ``'every'`` (default: every anomalous score triggers) or ``'onset'`` (only a crossing of the
    threshold from nominal to anomalous triggers; see RETRIGGER_MODES); max_disk_mb, min_free_mb: disk limits
    (0: off; see ``disk_guard``); retry_period: seconds between attempts to write windows that could not be
    written (disk full, unwritable directory, min_free_mb reached: they are kept in memory, in order, up to
    max_held_messages messages; beyond, the oldest are dropped and counted as lost); classify_every: score
    the feature window on every driving message (``'1'``), every N-th (``'N'``) or at most once per duration
    (``'50ms'``, the default: see DEFAULT_CLASSIFY_EVERY).

    Thread-safe: ``on_message``, ``trigger_now``, ``set_enabled``, ``stats`` and ``close`` may be called
    from different threads. Bad configuration raises ``ValueError('<parameter>: ...')``.
    """

    def __init__(self, model, directory, fmt=DEFAULT_FORMAT, pre=DEFAULT_PRE, post=DEFAULT_POST,
                 driving_topic=DEFAULT_DRIVING_TOPIC, side_topics=(), max_window=DEFAULT_MAX_WINDOW,
                 enabled=True, background=True, retrigger=DEFAULT_RETRIGGER, max_disk_mb=0, min_free_mb=0,
                 retry_period=DEFAULT_RETRY_PERIOD, max_held_messages=DEFAULT_MAX_HELD_MESSAGES,
                 classify_every=DEFAULT_CLASSIFY_EVERY):
        self.classify_every = Span.parse(classify_every, 'classify_every')
        if self.classify_every.count == 0:
            raise ValueError('classify_every: 0 messages; use 1 to classify every message')
        if retrigger not in RETRIGGER_MODES:
            raise ValueError('retrigger: %r is not one of %s' % (retrigger, ', '.join(RETRIGGER_MODES)))
        self.retrigger = retrigger
        self.model = model
        self.config = model.config
        self.threshold = float(model.threshold)
        self.directory = str(directory)
        self.format = log_format.Format.check(fmt)
        self.pre = Span.parse(pre, 'pre')
        self.post = Span.parse(post, 'post')
        self.max_window = Span.parse(max_window, 'max_window')
        self.window = self.config.span
        if not driving_topic:
            raise ValueError('driving_topic: must not be empty')
        self.driving_topic = driving_topic
        self.side_topics = None if side_topics is None else frozenset(side_topics) - {driving_topic}
        self.background = bool(background)
        # Disk limits and write failures: see disk_guard; unwritten windows wait in _held (writer only).
        self.guard = disk_guard.DiskGuard(self.directory, max_disk_mb, min_free_mb)
        self.retry_period = float(retry_period)
        if not self.retry_period > 0:
            raise ValueError('retry_period: %r must be > 0 seconds' % (retry_period,))
        self.max_held_messages = int(max_held_messages)
        self._held = collections.deque()  # [window, metadata, reported] oldest first
        self._types = {}  # side topic -> its message type (the first seen)
        self._lock = threading.RLock()
        self._stats = _Stats()
        self._raw = msg_codec.RowJsonCounter()
        self._callbacks = []
        self._enabled = bool(enabled)
        self._closed = False
        self._new_buffer()  # raises ValueError for a bad pre/post/max_window combination
        self._queue = queue.Queue()
        self._writer = None
        if self.background:
            self._writer = threading.Thread(target=self._write_loop, name='cc_log window writer')
            self._writer.daemon = True
            self._writer.start()

    # -- public API -----------------------------------------------------------------------------------

    def on_event(self, callback):
        """Call ``callback(Event)`` when a window opens, is written or fails to be written.

        OPENED is called from the thread that fed the triggering message, WRITTEN and FAILED from the
        writer thread; callbacks should be quick and must not raise.
        """
        self._callbacks.append(callback)

    @property
    def enabled(self):
        """True while messages are buffered and classified."""
        return self._enabled

    def on_message(self, topic, msg, stamp=None):
        """Feed one message of ``topic``; ``stamp`` (float s or a rospy/genpy Time) is its receipt or bag
        time, used when the message has no non-zero header stamp (the current time when None too)."""
        if topic != self.driving_topic and self.side_topics is not None and topic not in self.side_topics:
            return
        with self._lock:
            if self._closed:
                raise ValueError('on_message: the logger is closed')
            raw = self._raw.count(msg)  # == msg_codec.row_json_bytes(msg); its memo is not thread-safe
            with self._stats.lock:
                self._stats.messages_seen += 1
                self._stats.raw_json_bytes += raw
            if not self._enabled:
                return
            if not self._type_ok(topic, msg):
                return
            stamp = features_mod.stamp_of(msg, time.time() if stamp is None else stamp)
            record = Record(stamp, topic, msg)
            if topic != self.driving_topic:
                self._buffer.add_side(record)
                return
            self._add_driving(record)

    def trigger_now(self, reason='manual'):
        """Save a window around the newest driving message now (``post`` messages after it still follow).

        Returns ``(True, message)`` or ``(False, why not)``: disabled, closed or no driving message yet.
        """
        with self._lock:
            if self._closed:
                return False, 'the logger is closed'
            if not self._enabled:
                return False, 'the logger is disabled'
            if self._last_stamp is None:
                return False, 'no %s message received yet' % self.driving_topic
            self._trigger(reason, float('nan'))
            return True, 'window triggered at %.3f (%s)' % (self._last_stamp, reason)

    def set_enabled(self, flag):
        """Enable or pause the logger. Pausing completes any open window with what it holds; messages seen
        while paused are counted but neither buffered nor classified; enabling starts a fresh buffer."""
        with self._lock:
            flag = bool(flag)
            if flag == self._enabled:
                return
            if not flag:
                self._complete(self._buffer.flush())
            self._new_buffer()
            self._enabled = flag

    def flush(self):
        """Complete every window now (the open one with what it holds), as at the end of a stream."""
        with self._lock:
            self._complete(self._buffer.flush())

    def close(self, timeout=None):
        """Flush, then wait for the writer to write every queued window. Idempotent.

        Returns True when every queued window was handled within ``timeout`` seconds (None: wait).
        """
        with self._lock:
            if not self._closed:
                self._complete(self._buffer.flush())
                self._new_buffer()  # what the buffer still held was outside every window: dropped
                self._closed = True
                if self._writer is not None:
                    self._queue.put(None)
                else:
                    self._retry_held(final=True)
        if self._writer is not None:
            self._writer.join(timeout)
            return not self._writer.is_alive()
        return True

    def stats(self):
        """A snapshot of the counters (a dict; see the node's diagnostics for their meaning)."""
        with self._lock:
            buffered = self._buffer.buffered_messages
            resets = self._resets + self._buffer.resets
        s = self._stats
        with s.lock:
            calls = s.classifier_calls
            result = {
                'enabled': self._enabled,
                'messages_seen': s.messages_seen,
                'messages_kept': s.messages_kept,
                'messages_queued': s.messages_queued,
                'messages_buffered': buffered,
                'messages_lost': s.messages_lost,
                'raw_json_bytes': s.raw_json_bytes,
                'stored_bytes': s.stored_bytes,
                'windows_opened': s.windows_opened,
                'windows_saved': s.windows_saved,
                'windows_queued': s.windows_queued,
                'write_errors': s.write_errors,
                'last_error': s.last_error,
                'classifier_calls': calls,
                'classifier_mean_us': (s.classifier_seconds / calls * 1e6) if calls else 0.0,
                'classifier_max_us': s.classifier_max * 1e6,
                'anomalous_messages': s.anomalous,
                'time_resets': resets,
                'windows_held': s.windows_held,
                'messages_held': s.messages_held,
                'write_retries': s.write_retries,
                'disk_paused': self.guard.paused,
                'windows_deleted': s.windows_deleted,
                'bytes_deleted': s.bytes_deleted,
                'last_deleted': s.last_deleted,
                'messages_refused': s.messages_refused,
                'last_refused': s.last_refused,
            }
        # Not in any window (outside every anomaly, or seen while paused).
        result['messages_dropped'] = (result['messages_seen'] - result['messages_kept'] - result['messages_queued']
                                      - result['messages_buffered'] - result['messages_lost'])
        result['queue_depth'] = self._queue.qsize() if self._writer is not None else 0
        return result

    # -- message path ---------------------------------------------------------------------------------

    def _type_ok(self, topic, msg):
        """Whether ``msg`` has the type of its topic (the model's for the driving topic, else the first type
        seen there); other messages are counted as refused (one window file holds one type per topic)."""
        msg_type = getattr(msg, '_type', type(msg).__name__)
        if topic == self.driving_topic:
            expected = self.config.topic_type
        else:
            expected = self._types.setdefault(topic, msg_type)
        if msg_type == expected:
            return True
        with self._stats.lock:
            self._stats.messages_refused += 1
            self._stats.last_refused = '%s: %s message refused (the topic carries %s)' % (topic, msg_type, expected)
        return False

    def _new_buffer(self):
        buffer = WindowBuffer(window=self.window, pre=self.pre, post=self.post, max_window=self.max_window)
        if getattr(self, '_buffer', None) is not None:
            self._resets += self._buffer.resets
        else:
            self._resets = 0
        self._buffer = buffer
        self._features = features_mod.OdometryFeatures(self.config)
        self._window_rows = features_mod.FeatureWindow(self.config)  # the same rows as the buffer's window
        self._clock = None       # newest driving stamp since the buffer (re)started: as WindowBuffer's
        self._since_scored = None  # driving messages since the last score (None: score at the next chance)
        self._scored_at = None     # stamp of the last score
        self._recent = collections.deque()  # stamps of the newest driving message and the pre before it
        self._last_stamp = None
        self._armed = True  # 'onset': the next anomalous score triggers (no anomalous score since a nominal one)

    def _add_driving(self, record):
        buffer = self._buffer
        resets = buffer.resets
        stamp = record.stamp
        row = self._features.row_values(record.msg, stamp)
        done = buffer.add(record, row)
        if buffer.resets != resets:  # time jumped backwards: the buffer started over
            self._recent.clear()
            self._armed = True
            self._window_rows.clear()
            self._clock = None
            self._since_scored = self._scored_at = None
        # The ring-array window gets what WindowBuffer's feature window got: the row at the buffer's clock.
        self._clock = stamp if self._clock is None or stamp > self._clock else self._clock
        self._window_rows.add(self._clock, row)
        self._last_stamp = stamp
        self._note_recent(stamp)
        self._complete(done)
        if buffer.feature_window_full and self._features.covers(self.window, stamp):
            if not self._due(stamp):
                return
            started = time.perf_counter()
            vector = self._window_rows.vector()
            anomalous, score = self.model.is_anomalous(vector)
            elapsed = time.perf_counter() - started
            with self._stats.lock:
                self._stats.classifier_calls += 1
                self._stats.classifier_seconds += elapsed
                self._stats.classifier_max = max(self._stats.classifier_max, elapsed)
                if anomalous:
                    self._stats.anomalous += 1
            if anomalous and (self._armed or self.retrigger == 'every'):
                self._trigger('classifier', float(score))
            self._armed = not anomalous
        else:
            self._armed = True  # not scored (start, after a gap): the next anomalous score is an onset
            self._since_scored = self._scored_at = None  # score as soon as the window is whole again

    def _due(self, stamp):
        """Whether this driving message is scored (classify_every); counts the messages since the last."""
        every = self.classify_every
        if self._since_scored is not None:
            self._since_scored += 1
            if every.is_duration:
                if stamp - self._scored_at < every.seconds - _CLASSIFY_SLACK and stamp >= self._scored_at:
                    return False
            elif self._since_scored < every.count:
                return False
        self._since_scored = 0
        self._scored_at = stamp
        return True

    def _note_recent(self, stamp):
        recent = self._recent
        recent.append(stamp)
        if self.pre.is_duration:
            newest = max(recent[-1], stamp)
            while recent and recent[0] < newest - self.pre.seconds:
                recent.popleft()
        else:
            while len(recent) > self.pre.count + 1:
                recent.popleft()

    def _window_active(self):
        """Whether a window is open or complete but not yet written (a new trigger then joins it)."""
        buffer = self._buffer
        # WindowBuffer has no public view of its pending window yet; read it without changing it.
        pending = getattr(buffer, '_pending', None)
        return buffer.window_open or (pending is not None and bool(pending.records))

    def _trigger(self, reason, score):
        announce = not self._window_active()
        done = self._buffer.trigger(reason, score)
        if announce:
            with self._stats.lock:
                self._stats.windows_opened += 1
            start = self._recent[0] if self._recent else self._last_stamp
            self._emit(Event(OPENED, self._last_stamp, reason, score, self.threshold, start, None, 0, '', 0, ''))
        self._complete(done)

    def _complete(self, windows):
        """Hand completed windows to the writer."""
        for window in windows:
            metadata = self._metadata(window)
            with self._stats.lock:
                self._stats.windows_queued += 1
                self._stats.messages_queued += len(window)
            if self._writer is not None:
                self._queue.put((window, metadata))
            else:
                self._write(window, metadata)

    def _metadata(self, window):
        """Smart-mode metadata added to log_format's (which already holds triggers, part, counts)."""
        return {
            'reason': window.triggers[0].reason if window.triggers else '',
            'threshold': self.threshold,
            'driving_topic': self.driving_topic,
            'pre': str(self.pre),
            'post': str(self.post),
            'model': self.config.to_dict(),
        }

    # -- writer ---------------------------------------------------------------------------------------

    def _write_loop(self):
        while True:
            try:
                item = self._queue.get(timeout=self.retry_period if self._held else None)
            except queue.Empty:
                self._retry_held()
                continue
            try:
                if item is None:
                    self._retry_held(final=True)
                    return
                self._write(*item)
            finally:
                self._queue.task_done()

    def _write(self, window, metadata):
        """Write a completed window; on a disk problem keep it in memory (in order) to retry later."""
        self._retry_held()
        if self._held:  # older windows still wait: keep the order
            self._hold([window, metadata, False])
            return
        item = [window, metadata, False]
        if not self._attempt(item, final=False):
            self._hold(item)

    def _attempt(self, item, final):
        """Try to write a window once; True when it is on disk (or lost for good: bad content / final)."""
        window, metadata, reported = item
        scores = [t.score for t in window.triggers if t.score is not None and not math.isnan(t.score)]
        score = min(scores) if scores else float('nan')
        reason = metadata['reason']
        first = window.triggers[0].stamp if window.triggers else window.start
        allowed, why = self.guard.check()
        retryable = True
        if not allowed:
            error = why
        else:
            try:
                path, nbytes = log_format.write_window(window, self.directory, self.format, metadata)
            except Exception as failure:  # OSError, ValueError, rosbag's exceptions: the writer must go on
                error = str(failure) or type(failure).__name__
                retryable = disk_guard.is_retryable(failure)
            else:
                with self._stats.lock:
                    self._stats.windows_queued -= 1
                    self._stats.messages_queued -= len(window)
                    self._stats.windows_saved += 1
                    self._stats.messages_kept += len(window)
                    self._stats.stored_bytes += nbytes
                self._emit(Event(WRITTEN, first, reason, score, self.threshold, window.start, window.end,
                                 len(window), path, nbytes, ''))
                self._enforce_quota(path)
                return True
        if allowed:
            with self._stats.lock:
                if reported:
                    self._stats.write_retries += 1
                else:
                    self._stats.write_errors += 1
                self._stats.last_error = error
        if retryable and not final:
            if allowed and not reported:
                item[2] = True
                self._emit(Event(FAILED, first, reason, score, self.threshold, window.start, window.end,
                                 len(window), '', 0, '%s (kept in memory; retrying every %g s)'
                                 % (error, self.retry_period)))
            return False
        self._lose(item, error)
        return True

    def _lose(self, item, error):
        window, metadata, reported = item
        with self._stats.lock:
            self._stats.windows_queued -= 1
            self._stats.messages_queued -= len(window)
            self._stats.messages_lost += len(window)
            self._stats.last_error = error
        if not reported:
            scores = [t.score for t in window.triggers if t.score is not None and not math.isnan(t.score)]
            first = window.triggers[0].stamp if window.triggers else window.start
            self._emit(Event(FAILED, first, metadata['reason'], min(scores) if scores else float('nan'),
                             self.threshold, window.start, window.end, len(window), '', 0, error))

    def _hold(self, item):
        """Keep an unwritten window in memory; beyond max_held_messages the oldest held windows are lost."""
        self._held.append(item)
        with self._stats.lock:
            self._stats.windows_held += 1
            self._stats.messages_held += len(item[0])
        while len(self._held) > 1 and self._stats.messages_held > self.max_held_messages:
            old = self._held.popleft()
            with self._stats.lock:
                self._stats.windows_held -= 1
                self._stats.messages_held -= len(old[0])
            self._lose(old, 'more than %d messages held in memory: the oldest unwritten window (%d messages) '
                       'was dropped' % (self.max_held_messages, len(old[0])))

    def _retry_held(self, final=False):
        """Write held windows, oldest first, until one fails again (then they wait for the next period)."""
        while self._held:
            item = self._held[0]
            if not self._attempt(item, final):
                return
            self._held.popleft()
            with self._stats.lock:
                self._stats.windows_held -= 1
                self._stats.messages_held -= len(item[0])

    def _enforce_quota(self, path):
        if not self.guard.max_bytes:
            return
        for deleted in self.guard.enforce_quota(keep=path):
            with self._stats.lock:
                self._stats.windows_deleted += 1
                self._stats.last_deleted = deleted
            self._emit(Event(DELETED, None, 'max_disk_mb', float('nan'), self.threshold, None, None, 0, deleted, 0,
                             'deleted to stay within max_disk_mb %g' % (self.guard.max_bytes / float(disk_guard.MB))))
        with self._stats.lock:
            self._stats.bytes_deleted = self.guard.deleted_bytes

    def _emit(self, event):
        for callback in self._callbacks:
            callback(event)


def replay(bag_path, topic, model_path, out_dir, pre=DEFAULT_PRE, post=DEFAULT_POST, fmt=DEFAULT_FORMAT,
           side_topics=(), max_window=DEFAULT_MAX_WINDOW, progress=None, retrigger=DEFAULT_RETRIGGER,
           classify_every=DEFAULT_CLASSIFY_EVERY):
    """Run the smart logger over a bag as fast as it can be read; return a summary dict:

    ``{'input_messages', 'raw_json_bytes', 'stored_bytes', 'windows': [{'start', 'end', 'messages',
    'path'}]}`` with windows in start order (start/end: header stamps, float s, of the first and last
    message saved). ``progress``: optional ``callback(messages read)``, called every PROGRESS_EVERY messages and
    at the end. Raises ValueError for bad arguments, ModelError for a bad model, OSError when the bag
    cannot be read or a window cannot be written.
    """
    from . import bagio  # rosbag: imported here so the module stays pure
    from .model import AnomalyModel
    model = AnomalyModel.load(model_path)
    logger = SmartLogger(model, out_dir, fmt, pre, post, driving_topic=topic, side_topics=tuple(side_topics),
                         max_window=max_window, retrigger=retrigger, classify_every=classify_every)
    windows = []
    failures = []

    def collect(event):
        if event.kind == WRITTEN:
            windows.append({'start': event.start, 'end': event.end, 'messages': event.messages,
                            'path': event.path})
        elif event.kind == FAILED:
            failures.append(event.error)
    logger.on_event(collect)
    try:
        count = 0
        for record in bagio.read_messages(bag_path, [topic] + [t for t in side_topics if t != topic]):
            logger.on_message(record.topic, record.msg, record.stamp)
            count += 1
            if progress is not None and count % PROGRESS_EVERY == 0:
                progress(count)
        if progress is not None:
            progress(count)
    finally:
        logger.close()
    if failures:
        raise OSError('%s: %d window(s) could not be written: %s' % (out_dir, len(failures), failures[0]))
    stats = logger.stats()
    return {
        'input_messages': stats['messages_seen'],
        'raw_json_bytes': stats['raw_json_bytes'],
        'stored_bytes': stats['stored_bytes'],
        'windows': sorted(windows, key=lambda window: window['start']),
    }
