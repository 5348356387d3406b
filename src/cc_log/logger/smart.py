"""Smart mode: keep only the messages around what the triggers find.

``SmartLogger`` is the one implementation behind the live node (``smart_node``) and offline replay
(``offline.replay``, ``cclog replay``). Feed it every message with ``on_message``; it runs a list of
triggers (``triggers``: classifiers, rules, the manual trigger) over the records of their topics:

- a trigger's Fire opens (or extends) a logging window of ``pre`` messages before and ``post`` after the
  newest message of the driving topic (the topic whose messages count ``pre`` and ``post``, by default the
  first classifier's), or its own span; windows that touch or overlap merge into one file naming every
  trigger;
- other topics are buffered by time and saved in the windows whose time span holds them;
- the last message of each latched topic (connection header ``latching: '1'``: ``/tf_static``, maps) is
  written at the start of every window, as ``rosbag record`` keeps them.

Messages come decoded (``on_message``) or as their serialized bytes with their connection header (``on_records``, a
batch of them, what the live intake and offline replay hand over; ``on_raw``, one): the classifiers take a batch at
once (rows, vectors, one scoring call), then the window logic runs record by record with their Fires known.
Serialized messages are buffered as bytes and decoded only when a trigger reads a field (a feature set reads its
fixed layouts straight from the bytes) and, for json-xz, in the writer thread, only for the messages kept. The
row-JSON bytes of messages not decoded are estimated from a sample (``raw_json.RawJsonEstimate``) decoded when
``stats()`` is asked, not on the message path.

Completed windows go to the ``window_writer.WindowWriter`` (shared with collect mode), whose background
thread calls ``log_format.write_window``, so compression and disk writes never run on the message path and
no message is lost while a window is written; it holds and retries windows on a disk problem and keeps the
disk limits. All buffered messages together are bounded by ``max_buffer_mb`` (an open window is written
in parts at half of it). ``stats()`` feeds the node's diagnostics; ``on_event`` callbacks hear when a window
opens, is written or fails to be written, and when the quota deletes an old window file.

Pure: no rospy. Its parts: ``stamp_clock`` (the one clock of the stamps), ``window_prep`` (windows thinned under
overload, latched messages first), ``smart_events`` (Event), ``trigger_topics``, ``keep_budget``, ``fire_order`` (a
side record's Fire waits for the driving clock to reach its stamp).
"""
import collections
import itertools
import operator
import threading
import time

from cc_log.base import errors, msg_codec, raw_message, routes as routes_mod
from cc_log import features as features_mod
from cc_log.storage import log_format, window_writer
from cc_log.logger import fire_order, keep_budget, smart_events
from cc_log.buffer import window_prep
from cc_log.base.raw_json import RawJsonEstimate
from cc_log.base.event_kinds import OPENED
from cc_log.logger.smart_events import Event, Stats
from cc_log.base.stamp_clock import StampClock
from cc_log.logger.trigger_topics import TriggerViews, check_triggers, topic_types
from cc_log.base.spans import MAX_SECONDS, Span
from cc_log.triggers import (
    DEFAULT_CLASSIFY_EVERY, DEFAULT_RETRIGGER, RETRIGGER_MODES, ClassifierTrigger, ManualTrigger)
from cc_log.base.records import Record, records_of
from cc_log.buffer.window_buffer import (
    DEFAULT_MAX_BUFFER_MB, DEFAULT_MAX_WINDOW, DEFAULT_POST, DEFAULT_PRE, RAW_RECORD_OVERHEAD, MemoryCost, WindowBuffer)

__all__ = ['SmartLogger', 'Event', 'DEFAULT_FORMAT', 'DEFAULT_PRE',
           'DEFAULT_POST', 'DEFAULT_MAX_WINDOW', 'DEFAULT_DRIVING_TOPIC', 'RETRIGGER_MODES', 'DEFAULT_RETRIGGER',
           'DEFAULT_CLASSIFY_EVERY', 'DEFAULT_MAX_BUFFER_MB']

DEFAULT_FORMAT = log_format.formats.DEFAULT
DEFAULT_DRIVING_TOPIC = 'odom'

_TOPIC, _RAW, _CONNECTION, _STAMP = map(operator.attrgetter, ('topic', 'raw', 'connection', 'stamp'))
DEFAULT_STAMP_TOLERANCE = 5.0  # seconds a header stamp may differ from the message's arrival (else: its arrival)
DEFAULT_RETRY_PERIOD = window_writer.DEFAULT_RETRY_PERIOD        # seconds between attempts at held windows
DEFAULT_MAX_HELD_MESSAGES = window_writer.DEFAULT_MAX_HELD_MESSAGES  # unwritten messages kept in memory
WRITER_COUNTERS = ('messages_kept', 'messages_queued', 'messages_lost', 'stored_bytes', 'write_errors', 'last_error',
                   'messages_held', 'write_retries', 'disk_paused', 'windows_deleted', 'bytes_deleted',
                   'last_deleted', 'queue_depth', 'bytes_queued')  # the writer's counters in stats(), as it names them


class SmartLogger(object):
    """Triggered logging of a driving topic plus side topics.

    model: an ``AnomalyModel`` (its ``config`` says the feature set, feature window and topic type) for the
    classifier named ``'classifier'`` on ``driving_topic`` (and ``input_topics``, the topics of the set's other
    inputs: default their role names), with ``classify_every`` (score on every message ``'1'``, every N-th
    ``'N'``, or at most once per duration, ``'50ms'`` the default) and ``retrigger`` (``'every'`` anomalous
    score fires, or only the ``'onset'``); or None. triggers: more triggers (``triggers.Trigger``: other
    classifiers, rules; a ``manual`` trigger is added unless one is given); names must differ.
    directory: where window files go; fmt: ``'json-xz'`` or ``'bag-lz4'``; pre, post, max_window: counts
    (``'100'``) or durations (``'2s'``) of the driving topic; driving_topic: the topic whose messages count
    pre and post; side_topics: other topic names to keep (messages of any topic not listed, nor watched by
    a trigger, are ignored unless ``side_topics`` is None, which keeps every other topic); enabled: start
    enabled or paused; background: write windows on a writer thread (True) or inline in the calling thread
    (False); max_disk_mb, min_free_mb: disk limits (0: off; see ``disk_guard``); retry_period, max_held_messages
    (windows that could not be written are held in memory and retried), give_up_after, close_retry: see
    ``window_writer.WindowWriter`` (offline use: lose a window still failing after that many seconds; keep
    retrying that long at close); max_buffer_mb:
    memory budget of every buffered message together (MB; 0: none): an open window is written in parts at
    half of it, divided by the format's ``PART_FACTOR`` (what its writer and the process need per estimated
    byte of a part; see ``WindowBuffer``). format_options: keys added to every window's metadata that the format
    reads (json-xz: ``precision``); routes: ``base.routes.Route``s: topic sets written beside the window's own file
    in a format of their own; keep: ``{trigger name: topics}`` (``window_prep.selections``): a window only such
    triggers opened keeps only those; split_mb: a window written in parts goes on in a new file once its file holds
    that many MB (0: never); max_files, prefix: the writer's (``window_writer.WindowWriter``). wait_for_writer
    (offline): a message waits for room in the budget, never thinned for the writer.
    max_windows_per_hour: the keep budget (``keep_budget.KeepBudget``: past it, a Fire must be more anomalous; 0: off).

    Thread-safe: ``on_message``, ``on_raw``, ``on_records``, ``tick``, ``trigger_now``, ``set_enabled``, ``stats``
    and ``close`` may be called from different threads. Bad configuration raises ``ValueError('<parameter>: ...')``.
    """

    def __init__(self, model, directory, fmt=DEFAULT_FORMAT, pre=DEFAULT_PRE, post=DEFAULT_POST,
                 driving_topic=DEFAULT_DRIVING_TOPIC, side_topics=(), max_window=DEFAULT_MAX_WINDOW,
                 enabled=True, background=True, retrigger=DEFAULT_RETRIGGER, max_disk_mb=0, min_free_mb=0,
                 retry_period=DEFAULT_RETRY_PERIOD, max_held_messages=DEFAULT_MAX_HELD_MESSAGES,
                 classify_every=DEFAULT_CLASSIFY_EVERY, max_buffer_mb=DEFAULT_MAX_BUFFER_MB, give_up_after=None,
                 close_retry=0.0, triggers=(), input_topics=None, format_options=None, topic_limits=None, routes=(),
                 keep=None, split_mb=0, stamp_tolerance=DEFAULT_STAMP_TOLERANCE, wait_for_writer=False, max_files=0,
                 prefix=log_format.PREFIX, max_windows_per_hour=0):
        if not driving_topic:
            raise ValueError('driving_topic: must not be empty')
        self.driving_topic = driving_topic
        triggers = list(triggers)
        if model is not None:
            inputs = model.config.feature.inputs[1:]
            others = [role for role, _ in inputs] if input_topics is None else list(input_topics)
            triggers.insert(0, ClassifierTrigger('classifier', model, [driving_topic] + others,
                                                 classify_every=classify_every, retrigger=retrigger))
        if not any(isinstance(trigger, ManualTrigger) for trigger in triggers):
            triggers.append(ManualTrigger())
        self.triggers = check_triggers(triggers)
        self.classifiers = [t for t in self.triggers if isinstance(t, ClassifierTrigger)]
        self.manual = [t for t in self.triggers if isinstance(t, ManualTrigger)][0]
        primary = self.classifiers[0] if self.classifiers else None
        self.model = primary.model if primary else None
        self.config = primary.config if primary else None
        self.threshold = primary.threshold if primary else float('nan')
        self.window = self.config.span if primary else None
        self.classify_every = primary.classify_every if primary else Span.parse(classify_every, 'classify_every')
        self.retrigger = primary.retrigger if primary else retrigger
        self.directory = str(directory)
        self.format = log_format.Format.check(fmt)
        self.format_options = dict(format_options or {})  # e.g. json-xz precision: in every window's metadata
        self.pre = Span.parse(pre, 'pre')
        self.post = Span.parse(post, 'post')
        self.max_window = Span.parse(max_window, 'max_window')
        watched = set().union(*(trigger.topics for trigger in self.triggers))
        self.side_topics = None if side_topics is None else frozenset(side_topics).union(watched) - {driving_topic}
        self.max_buffer_mb = max_buffer_mb
        self.budget = keep_budget.KeepBudget(max_windows_per_hour, self.pre.seconds, self.post.seconds)
        self.topic_limits = dict(topic_limits or {})  # topic -> options.TopicLimits
        self.routes = list(routes)  # base.routes.Route: topic sets written in a format of their own, beside the window
        self._names = {}  # window key -> the log_format.WindowName of its files, while it is handed on in parts
        self.keep = window_prep.selections(keep)  # trigger name -> what its windows keep (window_prep.restrict)
        self.stamp_tolerance = float(stamp_tolerance)
        self.wait_for_writer = bool(wait_for_writer)
        if not self.stamp_tolerance > 0:
            raise ValueError('stamp_tolerance: %r must be a positive number of seconds' % (stamp_tolerance,))
        self._restamped = collections.Counter()  # topic -> messages whose header stamp was off the clock
        self._clock = StampClock(driving_topic, self.stamp_tolerance)
        self._shed = collections.Counter()       # topic -> messages of windows dropped under overload
        self.writer = None
        self._expected = topic_types(self.triggers)  # topic -> the type its triggers read
        self._types = {}  # other topics -> their message type (the first seen)
        self._trigger_views = TriggerViews(self.triggers)  # what the triggers of each topic see of its records
        self._by_topic = self._trigger_views.by_topic
        self._timed = [trigger for trigger in self.triggers if trigger.watches_time]
        self._batched = [trigger for trigger in self.triggers if trigger.batched and not trigger.watches_time]
        self._accepted = {}  # (id(connection), topic) -> connection: its messages are wanted and of the topic's type
        self._lock = threading.RLock()
        self._stats = Stats()
        self._raw = msg_codec.RowJsonCounter()
        self._raw_estimate = RawJsonEstimate()  # decodes its samples when stats() asks, not on the message path
        self._latched, self._unsaid = window_prep.Latched(), window_prep.CarriedDrops()
        self._cost = MemoryCost()
        self._callbacks = []
        self._enabled = bool(enabled)
        self._closed = False
        self._new_buffer()  # raises ValueError for a bad pre/post/max_window/max_buffer_mb
        # Writing, disk limits and write failures: see window_writer (and disk_guard).
        self.writer = window_writer.WindowWriter(
            self.directory, self.format, max_disk_mb, min_free_mb, retry_period=retry_period,
            max_held_messages=max_held_messages, background=background, give_up_after=give_up_after,
            close_retry=close_retry, split_mb=split_mb, max_files=max_files, prefix=prefix, name='cc_log window writer')
        self.guard = self.writer.guard
        self.retry_period = self.writer.retry_period
        self.writer.on_event(self._written)

    # -- public API -----------------------------------------------------------------------------------

    def on_event(self, callback):
        """Call ``callback(Event)`` when a window opens, is written or fails to be written.

        OPENED is called from the thread that fed the triggering message, WRITTEN, FAILED and DELETED from
        the writer thread; callbacks should be quick and must not raise.
        """
        self._callbacks.append(callback)

    @property
    def buffer_budget(self):
        """The memory budget of the buffer in bytes (0: none)."""
        return self._buffer.max_buffer_bytes

    @property
    def enabled(self):
        """True while messages are buffered and classified."""
        return self._enabled

    def wants(self, topic):
        """Whether messages of ``topic`` are kept or watched (the others are ignored)."""
        return topic == self.driving_topic or self.side_topics is None or topic in self.side_topics

    def on_message(self, topic, msg, stamp=None, size=None):
        """Feed one message of ``topic``; ``stamp`` (float s or a rospy/genpy Time) is its receipt or bag
        time, used when the message has no non-zero header stamp (the current time when None too); ``size``:
        its serialized length when known (it scales the memory estimate of messages of varying size)."""
        if not self.wants(topic):
            return
        with self._lock:
            self._check_open('on_message')
            raw = self._raw.count(msg)  # == msg_codec.row_json_bytes(msg); its memo is not thread-safe
            with self._stats.lock:
                self._stats.messages_seen += 1
                self._stats.raw_json_bytes += raw
            if not self._enabled or not self._type_ok(topic, getattr(msg, '_type', type(msg).__name__)):
                return
            if stamp is None:
                stamp = header = features_mod.stamp_of(msg, time.time())
            else:
                arrival = stamp.to_sec() if hasattr(stamp, 'to_sec') else float(stamp)
                header = features_mod.stamp_of(msg, arrival)
                stamp = self._on_clock([header], [arrival], [topic])[0]
            self._take_all([Record(stamp, topic, msg, self._cost(msg, size))], None, None,
                           None if stamp == header else [header])

    def on_raw(self, topic, raw, connection, stamp=None):
        """Feed one message of ``topic`` as its serialized bytes ``raw`` with its ``connection`` header (a
        dict with at least ``type``, ``md5sum`` and ``message_definition``); ``stamp`` as ``on_message``'s. It is
        buffered as bytes and decoded only when a trigger reads its fields; ValueError (and the errors of
        ``raw_message.decode``) when a trigger needs it decoded and it cannot be."""
        try:
            self.on_records([Record(time.time() if stamp is None else stamp, topic, None, 0, raw, connection)])
        except errors.UndecodableRecord as error:
            raise error.error from None

    def on_records(self, records):
        """Feed a batch of serialized messages, ``Record(stamp, topic, None, 0, raw, connection)`` in the order
        they came (``stamp``: receipt or bag time, float s, used when the message has no header stamp): the same
        as ``on_raw`` of each in turn, with less work per message (a classifier scores every vector of the
        batch in one call). A record a trigger must read that cannot be decoded raises
        ``errors.UndecodableRecord`` (its ``index`` in ``records``: those before it were taken)."""
        with self._lock:
            self._check_open('on_records')
            topics = list(map(_TOPIC, records))
            connections = list(map(_CONNECTION, records))
            pairs = set(zip(map(id, connections), topics))
            accepted = self._accepted
            if all(pair in accepted for pair in pairs):  # every record wanted and of its topic's type
                self._raw_estimate.count_all(list(map(_RAW, records)), connections)
                with self._stats.lock:
                    self._stats.messages_seen += len(records)
                if self._enabled:
                    self._take_raw(records, topics, connections, range(len(records)))
                return
            count = self._raw_estimate.count
            wanted = []
            for index, record in enumerate(records):
                if self.wants(record.topic) and self._header_ok(record):
                    count(record.raw, record.connection)
                    wanted.append(index)
            with self._stats.lock:
                self._stats.messages_seen += len(wanted)
            if not self._enabled:
                return
            places = []
            for index in wanted:
                record = records[index]
                if self._type_ok(record.topic, record.connection['type']):
                    accepted.setdefault((id(record.connection), record.topic), record.connection)
                    places.append(index)
            self._take_raw([records[index] for index in places], [topics[index] for index in places],
                           [connections[index] for index in places], places)

    def _take_raw(self, records, topics, connections, places):
        """``_take_all`` of serialized records, restamped with their header stamps (``_on_clock``) and costed by
        their length; ``places``: where each is in the batch fed (said by an ``UndecodableRecord``)."""
        raws = list(map(_RAW, records))
        arrivals = list(map(_STAMP, records))
        headers = raw_message.stamps(raws, connections, arrivals)
        stamps = self._on_clock(headers, arrivals, topics)
        taken = records_of(stamps, topics, itertools.repeat(None), map(RAW_RECORD_OVERHEAD.__add__, map(len, raws)),
                           raws, connections)
        try:  # the triggers see a message placed off its header stamp at that stamp (the buffer at its place)
            self._take_all(taken, topics, connections, None if stamps is headers else headers)
        except errors.UndecodableRecord as error:
            raise errors.UndecodableRecord(places[error.index], error.topic, error.error)

    def _on_clock(self, stamps, arrivals, topics):
        """The stamps that place messages in windows (``stamp_clock.StampClock``); those of messages whose header
        stamp is more than ``stamp_tolerance`` off the driving topic's clock are their arrival, and counted
        (``stats()['restamped_by_topic']``)."""
        stamps, restamped = self._clock.place(stamps, arrivals, topics)
        if restamped:
            with self._stats.lock:
                self._restamped.update(restamped)
        return stamps

    def _check_open(self, name):
        if self._closed:
            raise ValueError('%s: the logger is closed' % name)

    def _take_all(self, records, topics=None, connections=None, stamps=None):
        """Buffer records (each with its cost) and run the triggers of their topics: first every trigger that
        reads a batch (``batched``) over its records of the batch, then the buffer and the Fires of every trigger
        in order (those that read fields get the record decoded): by slices between the records that fire when all
        Fires are known ahead, else record by record. ``topics``, ``connections``: of the records, when known;
        ``stamps``: the stamps the triggers see, when not theirs."""
        topics = list(map(_TOPIC, records)) if topics is None else topics
        connections = list(map(_CONNECTION, records)) if connections is None else connections
        views, error = self._trigger_views.views(records, topics, connections, stamps)
        if error is not None:
            error = errors.UndecodableRecord(len(views), records[len(views)].topic, error)
            records, topics, connections = records[:len(views)], topics[:len(views)], connections[:len(views)]
        ahead = self._trigger_views.ahead(self._batched, views, topics)  # trigger -> its Fires of each of its records
        by_topic, fire, timed = self._by_topic, self._fire, self._timed
        latched, waits = window_prep.any_latched(connections), self.wait_for_writer and self._buffer.max_buffer_bytes
        plan = None if timed or latched else self._trigger_views.plan(ahead, topics)
        if plan is not None:  # every Fire known ahead: the buffer takes the records between two by slices
            start = 0
            for index, fired in plan + [(len(records) - 1, ())]:
                self._add_batch(records[start:index + 1], topics[start:index + 1], waits)
                for fires in fired:
                    fire(fires, records[index].stamp)
                start = index + 1
            records = ()
        for record, view, topic in zip(records, views, topics):
            if latched and raw_message.is_latched(record.connection):
                self._latched.note(topic, record)
            self._add_batch([record], [topic], waits)
            for trigger in by_topic.get(topic, ()):
                fires = ahead.get(trigger)
                fires = fires.popleft() if fires is not None else trigger.on_record(view)
                if fires:
                    fire(fires, record.stamp)
            for trigger in timed:
                fires = trigger.on_time(record.stamp)
                if fires:
                    fire(fires)
        if error is not None:
            raise error

    def _add_batch(self, records, topics, waits=0):
        """Buffer records in order (``WindowBuffer.add_batch``) and hand on the windows this completes; ``waits``
        (the buffer's budget): first the writer's queue leaves room for them beside the buffer (or is empty). The
        Fires held for the driving clock (``fire_order``) apply among them."""
        if self._held:
            self._held.add(records, topics, self._last_stamp, lambda part, kinds: self._add(part, kinds, waits),
                           self._fire)
        else:
            self._add(records, topics, waits)

    def _add(self, records, topics, waits):
        if waits:
            self.writer.wait_for_room(waits - self._buffer.buffered_bytes - sum(record.cost for record in records))
        self._complete(self._buffer.add_batch(records, topics, self.driving_topic))
        driving = list(itertools.compress(records, map(self.driving_topic.__eq__, topics)))
        self._last_stamp = driving[-1].stamp if driving else self._last_stamp

    def tick(self, stamp):
        """Message time has reached ``stamp`` (float s) although no message came: lets the triggers that watch
        for silence fire. The node calls it periodically."""
        with self._lock:
            if self._closed or not self._enabled:
                return
            for trigger in self._timed:
                self._fire(trigger.on_time(float(stamp)))

    def trigger_now(self, reason='manual', before=None, after=None):
        """Save a window around the newest driving message now, with the manual trigger: ``reason`` (text),
        ``before`` and ``after`` in seconds (None or 0: ``pre`` and ``post``; the past only as far as the logger
        holds it, at most ``pre``: the message says so when ``before`` was cut). Returns ``(True, message)`` or
        ``(False, why not)``: disabled, closed, no driving message yet, or a bad span."""
        with self._lock:
            if self._closed:
                return False, 'the logger is closed'
            if not self._enabled:
                return False, 'the logger is disabled'
            if self._last_stamp is None:
                return False, 'no %s message received yet' % self.driving_topic
            try:
                fire = self.manual.request(reason, before, after)
            except ValueError as error:
                return False, str(error)
            held = self._last_stamp - self._buffer.oldest()
            self._fire([fire])
            start = self._buffer.window_start
            cut = self.manual.cut_note(before, held, self.pre)
            return True, 'window triggered at %.3f (%s)%s%s' % (
                self._last_stamp, fire.reason, '' if start is None else ', from %.3f' % start, cut)

    def set_enabled(self, flag):
        """Enable or pause the logger. Pausing completes any open window with what it holds; messages seen
        while paused are counted but neither buffered nor classified; enabling starts a fresh buffer."""
        with self._lock:
            flag = bool(flag)
            if flag == self._enabled:
                return
            if not flag:
                self._flush()
            self._new_buffer()
            self._enabled = flag

    def flush(self):
        """Complete every window now (the open one with what it holds), as at the end of a stream."""
        with self._lock:
            self._flush()

    def _flush(self):
        self._fire(self._held.release())  # at the clock: what comes after is not taken
        self._complete(self._buffer.flush())

    def close(self, timeout=None):
        """Flush, then wait for the writer to write every queued window (see ``WindowWriter.close``).
        Idempotent. Returns True when every queued window was handled within ``timeout`` s (None: wait).
        """
        with self._lock:
            if not self._closed:
                self._flush()
                self._new_buffer()  # what the buffer still held was outside every window: dropped
                self._closed = True
        return self.writer.close(timeout)

    def stats(self):
        """A snapshot of the counters (a dict; see the node's diagnostics for their meaning); ``triggers``:
        ``{name: that trigger's counters}``."""
        with self._lock:
            buffered = self._buffer.buffered_messages
            buffered_bytes = self._buffer.buffered_bytes
            resets = self._resets + self._buffer.resets
            trimmed = self._trimmed + self._buffer.trimmed
            limited = self._limited + self._buffer.limited
            silent = self._silent + self._buffer.trimmed_silent  # side records after a window, its driving topic silent
            placed = self._placed + self._buffer.restamped
        raw_estimate = self._raw_estimate.total  # its samples decoded here, off the message path
        written = self.writer.stats()
        triggers = {trigger.name: trigger.stats() for trigger in self.triggers}
        classified = [triggers[trigger.name] for trigger in self.classifiers]
        calls = sum(t['classifier_calls'] for t in classified)
        s = self._stats
        with s.lock:
            result = {
                'enabled': self._enabled, 'messages_seen': s.messages_seen,
                **{key: written[key] for key in WRITER_COUNTERS},
                'messages_buffered': buffered, 'buffered_bytes': buffered_bytes,
                'buffer_trimmed': trimmed, 'topic_trimmed': limited, 'buffer_trimmed_silent': silent,
                'raw_json_bytes': s.raw_json_bytes + raw_estimate,
                'windows_opened': s.windows_opened, 'windows_saved': written['windows_saved'],
                'windows_queued': written['jobs_queued'], 'windows_lost': written['jobs_lost'],
                'windows_held': written['jobs_held'],
                'classifier_calls': calls,
                'classifier_mean_us': (sum(t['classifier_seconds'] for t in classified) / calls * 1e6
                                       if calls else 0.0),
                'classifier_max_us': max([t['classifier_max_seconds'] for t in classified] or [0.0]) * 1e6,
                'anomalous_messages': sum(t['anomalous_messages'] for t in classified),
                'fires_dropped': s.fires_dropped, 'triggers': triggers, 'time_resets': resets,
                'messages_refused': s.messages_refused, 'last_refused': s.last_refused,
                'messages_shed': sum(self._shed.values()), 'shed_by_topic': dict(self._shed),
                'messages_restamped': sum((self._restamped + placed).values()),
                'restamped_by_topic': dict(self._restamped + placed), **self.budget.stats(),  # windows_skipped, ...
            }
        # Not in any window (outside every anomaly, seen while paused, or trimmed from the pre buffer).
        result['messages_not_kept'] = result['messages_seen'] - sum(result[key] for key in (
            'messages_kept', 'messages_queued', 'messages_buffered', 'messages_lost', 'messages_shed'))
        return result

    # -- message path ---------------------------------------------------------------------------------

    def _type_ok(self, topic, msg_type):
        """Whether a message of ``msg_type`` has the type of its topic (the one its triggers read, else the
        first type seen there); other messages are counted as refused (one window file holds one type per
        topic)."""
        expected = self._expected.get(topic)
        if expected is None:
            expected = self._types.setdefault(topic, msg_type)
        if msg_type == expected:
            return True
        return self._refuse('%s: %s message refused (the topic carries %s)' % (topic, msg_type, expected))

    def _header_ok(self, record):
        """Whether a record's connection header says its type, md5sum and definition (else it is refused)."""
        problem = raw_message.header_problem(record.connection)
        return not problem or self._refuse('%s: message refused (%s)' % (record.topic, problem))

    def _refuse(self, text):
        """Count a message refused, ``text`` saying why; False."""
        with self._stats.lock:
            self._stats.messages_refused += 1
            self._stats.last_refused = text
        return False

    def _new_buffer(self):
        # the clock's stamps lie within 2 stamp_tolerance of each other: the buffer places what it could not judge
        buffer = WindowBuffer(pre=self.pre, post=self.post, max_window=self.max_window,
                              max_buffer_mb=self.max_buffer_mb, cost=self._cost,
                              part_factor=log_format.formats.get(self.format).PART_FACTOR,
                              topic_limits=self.topic_limits, held_elsewhere=self._bytes_queued,
                              max_ahead=min(2 * self.stamp_tolerance, MAX_SECONDS))
        self._held = fire_order.HeldFires(self.driving_topic, buffer.max_ahead)
        if getattr(self, '_buffer', None) is not None:
            self._placed.update(self._buffer.restamped)
            self._resets += self._buffer.resets
            self._trimmed += self._buffer.trimmed
            self._limited += self._buffer.limited
            self._silent += self._buffer.trimmed_silent
        else:
            self._resets = self._trimmed = self._limited = self._silent = 0
            self._placed = collections.Counter()  # side records the buffers placed at their driving clock
        self._buffer = buffer
        for trigger in self.triggers:
            trigger.reset()
        self._last_stamp = None

    def _fire(self, fires, stamp=None):
        """Open or extend windows for the Fires of a trigger (of a record stamped ``stamp``: held while that is
        after the driving clock, ``fire_order``)."""
        if stamp is not None and self._held.hold(stamp, fires, self._last_stamp):
            return
        for fire in fires:
            if self._last_stamp is None:  # nothing to keep around yet
                with self._stats.lock:
                    self._stats.fires_dropped += 1
                continue
            announce = not self._buffer.joins(fire.pre)  # it opens a window (else joins the open or pending one)
            if not self.budget.admit(self._last_stamp, fire, opens=announce):
                continue  # the keep budget is spent and this Fire would open a window: counted as skipped
            done = self._buffer.trigger(fire.reason, fire.score, fire.name, fire.pre, fire.post, fire.why)
            if announce:
                with self._stats.lock:
                    self._stats.windows_opened += 1
                start = self._buffer.window_start
                self._emit(Event(OPENED, self._last_stamp, fire.reason, fire.score, self._threshold_of(fire.name),
                                 self._last_stamp if start is None else start, None, 0, '', 0, '', fire.name, fire.why))
            self._complete(done)

    def _threshold_of(self, name):
        return next((trigger.threshold for trigger in self.classifiers if trigger.name == name), self.threshold)

    def _bytes_queued(self):
        """Memory of the parts handed to the writer and not yet written."""
        return self.writer.bytes_queued if self.writer is not None else 0

    def _complete(self, windows):
        """Hand completed windows to the writer, each with the latched messages at its start, thinned first when
        the writer's queue, the buffer, the window and room for the next part together pass the memory budget
        (``window_prep.thin``; an idle writer keeps up: the part is already held; never with ``wait_for_writer``).
        What is dropped is counted per topic (``stats()['shed_by_topic']``) and said in the metadata."""
        for window in windows:
            budget, queued = self._buffer.max_buffer_bytes, self._bytes_queued()
            shed = {}
            if budget and queued and not self.wait_for_writer:
                shed = window_prep.thin(window, budget - self._buffer.part_limit - self._buffer.buffered_bytes - queued)
                with self._stats.lock:
                    self._shed.update(shed)
            window = window_prep.restrict(self._latched.first_in(window, log_format.streams(self.format)), self.keep,
                                          self.driving_topic)
            metadata, shed = self._metadata(window), self._unsaid.said(window, shed)  # an emptied part's: the next's
            if shed:
                metadata['dropped'] = shed
            name = self._names.pop(window.key, None) or self.writer.window_name(window)
            if window.part and not window.final:
                self._names[window.key] = name  # all its files, every part's, take one name
            pieces = routes_mod.split(window, self.routes)  # one file per route (base.routes)
            for number, (route, piece) in enumerate(pieces, 1):
                last = (window.final or not window.part) and number == len(pieces)
                self.writer.submit(window_writer.Job(piece, metadata, name=name, last=last) if route is None else
                                   window_writer.Job(piece, routes_mod.metadata(metadata, route),
                                                     what=window_writer.ROUTE, fmt=route.format, route=route.name,
                                                     name=name, last=last))

    def _metadata(self, window):
        """Smart-mode metadata added to log_format's (which already holds triggers, names, part, counts)."""
        first = window.triggers[0] if window.triggers else None
        names = set(log_format.trigger_name(trigger) for trigger in window.triggers)
        meta = {
            'reason': first.reason if first else '',
            'trigger': log_format.trigger_name(first) if first else '',
            'threshold': self.threshold if self.classifiers else None,
            'driving_topic': self.driving_topic,
            'pre': str(self.pre), 'post': str(self.post),
            'trigger_info': {t.name: t.describe() for t in self.triggers if t.name in names},
        }
        if self.config is not None:
            meta['model'] = self.config.to_dict()
        meta.update(self.format_options)
        return meta

    # -- writer events --------------------------------------------------------------------------------

    def _written(self, event):
        """A WindowWriter event, told as this logger's Event."""
        self._emit(smart_events.from_writer(event, self._threshold_of))

    def _emit(self, event):
        for callback in self._callbacks:
            callback(event)
