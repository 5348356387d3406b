"""Smart mode: keep only the messages around what the triggers find.

``SmartLogger`` is the one implementation behind the live node (``smart_node``) and offline replay
(``replay``, used by ``cclog replay``). Feed it every message with ``on_message``; it runs a list of
triggers (``triggers``: classifiers, rules, the manual trigger) over the records of their topics:

- a trigger's Fire opens (or extends) a logging window of ``pre`` messages before and ``post`` after the
  newest message of the driving topic (the topic whose messages count ``pre`` and ``post``, by default the
  first classifier's), or its own span; windows that touch or overlap merge into one file naming every
  trigger;
- other topics are buffered by time and saved in the windows whose time span holds them;
- the last message of each latched topic (connection header ``latching: '1'``: ``/tf_static``, maps) is
  written at the start of every window, as ``rosbag record`` keeps them.

Messages come decoded (``on_message``) or as their serialized bytes with their connection header
(``on_records``, a batch of them, what the live intake and ``replay`` hand over; ``on_raw``, one): the
classifiers take a batch at once (rows, vectors, one scoring call), then the window logic runs record by
record with their Fires known. Serialized messages are buffered as bytes and decoded only
when a trigger reads a field (a feature set reads its fixed layouts straight from the bytes) and, for
json-xz, in the writer thread, only for the messages kept. The row-JSON bytes of messages not decoded
are estimated from a sample (``RawJsonEstimate``).

Completed windows go to the ``window_writer.WindowWriter`` (shared with collect mode), whose background
thread calls ``log_format.write_window``, so compression and disk writes never run on the message path and
no message is lost while a window is written; it holds and retries windows on a disk problem and keeps the
disk limits. All buffered messages together are bounded by ``max_buffer_mb`` (an open window is written
in parts at half of it). ``stats()`` feeds the node's diagnostics; ``on_event`` callbacks hear when a window
opens, is written or fails to be written, and when the quota deletes an old window file.

Pure: no rospy (``replay`` imports ``bagio``, and so rosbag, only when called).
"""
import collections
import itertools
import math
import operator
import threading
import time

from cc_log import features as features_mod
from cc_log.storage import log_format
from cc_log.core import msg_codec
from cc_log.core import raw_message
from cc_log.storage import window_writer
from cc_log.core.spans import Span
from cc_log.triggers import (
    DEFAULT_CLASSIFY_EVERY, DEFAULT_RETRIGGER, RETRIGGER_MODES, ClassifierTrigger, ManualTrigger)
from cc_log.core.records import Record, records_of
from cc_log.core.window_buffer import (
    DEFAULT_MAX_BUFFER_MB, DEFAULT_MAX_WINDOW, DEFAULT_POST, DEFAULT_PRE, RAW_RECORD_OVERHEAD, MemoryCost, WindowBuffer)

__all__ = ['SmartLogger', 'Event', 'OPENED', 'WRITTEN', 'FAILED', 'DELETED', 'replay', 'replay_into', 'replay_records',
           'DEFAULT_FORMAT', 'DEFAULT_PRE', 'DEFAULT_POST', 'DEFAULT_MAX_WINDOW', 'DEFAULT_DRIVING_TOPIC',
           'RETRIGGER_MODES', 'DEFAULT_RETRIGGER', 'DEFAULT_CLASSIFY_EVERY', 'DEFAULT_MAX_BUFFER_MB']

DEFAULT_FORMAT = log_format.formats.DEFAULT
DEFAULT_DRIVING_TOPIC = 'odom'

PROGRESS_EVERY = 1000  # replay: messages between progress callbacks
JSON_SAMPLE_EVERY = 64  # serialized messages: one in this many is decoded to measure its row-JSON bytes ...
JSON_SAMPLE_FIRST = 256  # ... after the first this many of each type, which all are
REPLAY_BATCH = 256      # replay: records fed to the logger at a time (``on_records``); the writer's losses are
#                         looked at after each batch
_TOPIC, _RAW, _CONNECTION, _STAMP, _MSG = map(operator.attrgetter, ('topic', 'raw', 'connection', 'stamp', 'msg'))
_TYPE = operator.itemgetter('type')
LATCHED_KEPT = 4        # messages remembered per latched topic (the newest before a window's start is written)
HEAVY_BYTES = 64 * 1024  # a message this large (an image, a cloud, a scan) may be dropped when the writer falls behind
DEFAULT_STAMP_TOLERANCE = 5.0  # seconds a header stamp may differ from the message's arrival (else: its arrival)

OPENED = 'opened'
WRITTEN = 'written'
FAILED = 'failed'
DELETED = 'deleted'  # an old window file deleted to stay within max_disk_mb (path, bytes)

DEFAULT_RETRY_PERIOD = window_writer.DEFAULT_RETRY_PERIOD        # seconds between attempts at held windows
DEFAULT_MAX_HELD_MESSAGES = window_writer.DEFAULT_MAX_HELD_MESSAGES  # unwritten messages kept in memory

Event = collections.namedtuple('Event', 'kind stamp reason score threshold start end messages path bytes error trigger',
                               defaults=('',))
Event.__doc__ = """What happened to a logging window.

kind: OPENED (a trigger opened a window), WRITTEN (the window file is on disk), FAILED (writing it failed;
``error`` says why: once when a disk problem first keeps the window in memory to be retried, and again if it
is lost for good) or DELETED (``path``, an old window file, was deleted to stay within max_disk_mb; stamp,
start and end are None). stamp: of the message that triggered (the first trigger of the window for WRITTEN
and FAILED). trigger: the name of that trigger ('classifier', 'manual', a rule's name...); reason: its
reason ('classifier' for classifiers, a rule's condition, a manual request's text); score: the lowest
classifier score of the window's triggers (NaN when none); threshold: of the classifier that fired (else
of the first classifier; NaN without one). start, end: header stamps (float s) of the first and last
message (end is None for OPENED). messages, path, bytes: the window's message count (all topics), file and
size on disk (0, '' and 0 until WRITTEN).
"""


class _Stats(object):
    """Counters of the message path (guarded by one lock); the writer keeps its own."""

    def __init__(self):
        self.lock = threading.Lock()
        self.messages_seen = 0
        self.raw_json_bytes = 0      # row-JSON bytes of every message seen
        self.windows_opened = 0
        self.fires_dropped = 0       # Fires before any driving message (no window to keep yet)
        self.messages_refused = 0    # a message type other than the topic's (first seen / the model's)
        self.last_refused = ''


class RawJsonEstimate(object):
    """Row-JSON bytes of serialized messages without decoding them all: per message type, the row-JSON
    bytes per serialized byte of the first ``first`` messages and of every ``every``-th one after them, times
    the serialized bytes of them all (exact up to ``first`` messages of a type); not thread-safe."""

    def __init__(self, every=JSON_SAMPLE_EVERY, first=JSON_SAMPLE_FIRST):
        self.every = int(every)
        self.first = int(first)
        self._counter = msg_codec.RowJsonCounter()
        self._types = {}  # type -> [messages, serialized bytes, sampled serialized bytes, sampled JSON bytes]

    def count(self, raw, connection):
        """Note one message (its bytes and connection header)."""
        entry = self._types.get(connection['type'])
        if entry is None:
            entry = self._types[connection['type']] = [0, 0, 0, 0]
        if entry[0] < self.first or entry[0] % self.every == 0:
            try:
                json_bytes = self._counter.count(raw_message.decode(raw, connection))
            except raw_message.DECODE_ERRORS:
                json_bytes = None
            if json_bytes is not None:
                entry[2] += len(raw)
                entry[3] += json_bytes
        entry[0] += 1
        entry[1] += len(raw)

    def count_all(self, raws, connections):
        """``count`` of each message in turn (``raws`` and their ``connections``), looking each type up once."""
        if len(raws) <= 4:  # a live batch: the bookkeeping of a batch would cost more than it saves
            for raw, connection in zip(raws, connections):
                self.count(raw, connection)
            return
        types = list(map(_TYPE, connections))
        for msg_type in dict.fromkeys(types):
            if types.count(msg_type) == len(types):
                places = range(len(raws))
            else:
                places = list(itertools.compress(range(len(raws)), map(msg_type.__eq__, types)))
            entry = self._types.get(msg_type)
            if entry is None:
                entry = self._types[msg_type] = [0, 0, 0, 0]
            seen = entry[0]
            first = range(min(max(self.first - seen, 0), len(places)))  # the first of the type: all sampled
            start = max(seen, self.first)
            every = range(start + (-start) % self.every - seen, len(places), self.every)  # then every every-th
            for k in itertools.chain(first, every):
                raw = raws[places[k]]
                try:
                    json_bytes = self._counter.count(raw_message.decode(raw, connections[places[k]]))
                except raw_message.DECODE_ERRORS:
                    json_bytes = None
                if json_bytes is not None:
                    entry[2] += len(raw)
                    entry[3] += json_bytes
            entry[0] += len(places)
            entry[1] += sum(map(len, map(raws.__getitem__, places)))

    @property
    def total(self):
        """Estimated row-JSON bytes of every message noted."""
        return int(round(sum(json_bytes * size / sampled for _, size, sampled, json_bytes in self._types.values()
                             if sampled)))


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
    (False); max_disk_mb, min_free_mb: disk limits (0: off; see ``disk_guard``); retry_period: seconds between
    attempts to write windows that could not be written (disk full, unwritable directory, min_free_mb
    reached: they are kept in memory, in order, up to max_held_messages messages; beyond, the oldest are
    dropped and counted as lost); give_up_after, close_retry: see ``window_writer.WindowWriter`` (offline use:
    lose a window still failing after that many seconds; keep retrying that long at close); max_buffer_mb:
    memory budget of every buffered message together (MB; 0: none): an open window is written in parts at
    half of it, divided by the format's ``PART_FACTOR`` (what its writer and the process need per estimated
    byte of a part; see ``WindowBuffer``).
    format_options: keys added to every window's metadata that the format reads (json-xz: ``precision``).

    Thread-safe: ``on_message``, ``on_raw``, ``on_records``, ``tick``, ``trigger_now``, ``set_enabled``, ``stats``
    and ``close`` may be called from different threads. Bad configuration raises ``ValueError('<parameter>: ...')``.
    """

    def __init__(self, model, directory, fmt=DEFAULT_FORMAT, pre=DEFAULT_PRE, post=DEFAULT_POST,
                 driving_topic=DEFAULT_DRIVING_TOPIC, side_topics=(), max_window=DEFAULT_MAX_WINDOW,
                 enabled=True, background=True, retrigger=DEFAULT_RETRIGGER, max_disk_mb=0, min_free_mb=0,
                 retry_period=DEFAULT_RETRY_PERIOD, max_held_messages=DEFAULT_MAX_HELD_MESSAGES,
                 classify_every=DEFAULT_CLASSIFY_EVERY, max_buffer_mb=DEFAULT_MAX_BUFFER_MB, give_up_after=None,
                 close_retry=0.0, triggers=(), input_topics=None, format_options=None, topic_limits=None,
                 stamp_tolerance=DEFAULT_STAMP_TOLERANCE):
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
        self.triggers = _check_triggers(triggers)
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
        self.topic_limits = dict(topic_limits or {})  # topic -> options.TopicLimits
        self.stamp_tolerance = float(stamp_tolerance)
        if not self.stamp_tolerance > 0:
            raise ValueError('stamp_tolerance: %r must be a positive number of seconds' % (stamp_tolerance,))
        self._restamped = collections.Counter()  # topic -> messages whose header stamp was off the clock
        self._clock_offset = 0.0                 # the driving topic's header stamps minus their arrival
        self._shed = collections.Counter()       # topic -> messages of windows dropped under overload
        self.writer = None
        self._expected = topic_types(self.triggers)  # topic -> the type its triggers read
        self._types = {}  # other topics -> their message type (the first seen)
        self._by_topic = collections.defaultdict(list)
        for trigger in self.triggers:
            for topic in trigger.topics:
                self._by_topic[topic].append(trigger)
        self._timed = [trigger for trigger in self.triggers if trigger.watches_time]
        self._batched = [trigger for trigger in self.triggers if trigger.batched and not trigger.watches_time]
        self._decode = {}  # (topic, id(connection)) -> (connection, whether a trigger of the topic reads fields)
        self._accepted = {}  # (id(connection), topic) -> connection: its messages are wanted and of the topic's type
        self._lock = threading.RLock()
        self._stats = _Stats()
        self._raw = msg_codec.RowJsonCounter()
        self._raw_estimate = RawJsonEstimate()
        self._latched = {}  # latched topic -> the last LATCHED_KEPT records of it
        self._cost = MemoryCost()
        self._callbacks = []
        self._enabled = bool(enabled)
        self._closed = False
        self._new_buffer()  # raises ValueError for a bad pre/post/max_window/max_buffer_mb
        # Writing, disk limits and write failures: see window_writer (and disk_guard).
        self.writer = window_writer.WindowWriter(
            self.directory, self.format, max_disk_mb, min_free_mb, retry_period=retry_period,
            max_held_messages=max_held_messages, background=background, give_up_after=give_up_after,
            close_retry=close_retry, name='cc_log window writer')
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
                stamp = features_mod.stamp_of(msg, time.time())
            else:
                arrival = stamp.to_sec() if hasattr(stamp, 'to_sec') else float(stamp)
                stamp = self._on_clock([features_mod.stamp_of(msg, arrival)], [arrival], [topic])[0]
            self._take(Record(stamp, topic, msg, self._cost(msg, size)))

    def on_raw(self, topic, raw, connection, stamp=None):
        """Feed one message of ``topic`` as its serialized bytes ``raw`` with its ``connection`` header (a
        dict with at least ``type``, ``md5sum`` and ``message_definition``); ``stamp`` as ``on_message``'s. It is
        buffered as bytes and decoded only when a trigger reads its fields; ValueError (and the errors of
        ``raw_message.decode``) when a trigger needs it decoded and it cannot be."""
        try:
            self.on_records([Record(time.time() if stamp is None else stamp, topic, None, 0, raw, connection)])
        except raw_message.UndecodableRecord as error:
            raise error.error from None

    def on_records(self, records):
        """Feed a batch of serialized messages, ``Record(stamp, topic, None, 0, raw, connection)`` in the order
        they came (``stamp``: receipt or bag time, float s, used when the message has no header stamp): the same
        as ``on_raw`` of each in turn, with less work per message (a classifier scores every vector of the
        batch in one call). A record a trigger must read that cannot be decoded raises
        ``raw_message.UndecodableRecord`` (its ``index`` in ``records``: those before it were taken)."""
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
                if self.wants(record.topic):
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
        stamps = self._on_clock(raw_message.stamps(raws, connections, arrivals), arrivals, topics)
        costs = list(map(RAW_RECORD_OVERHEAD.__add__, map(len, raws)))
        taken = records_of(stamps, topics, itertools.repeat(None), costs, raws, connections)
        try:
            self._take_all(taken, topics, connections)
        except raw_message.UndecodableRecord as error:
            raise raw_message.UndecodableRecord(places[error.index], error.topic, error.error)

    def _on_clock(self, stamps, arrivals, topics):
        """The stamps that place messages in windows. The driving topic's header stamps set the clock: its
        offset from the arrival (receipt or bag time) of each of its messages (0 before the first; a bag played
        without its clock keeps its own stamps). Any other message whose header stamp is more than
        ``stamp_tolerance`` from its arrival on that clock is placed at that arrival instead, and counted
        (``stats()['restamped_by_topic']``): a sensor stamping by another clock (wall time next to a bag's, a
        camera without time sync, a stamp in the future) can neither stretch a window nor hold others back."""
        tolerance, driving, offset = self.stamp_tolerance, self.driving_topic, self._clock_offset
        if not stamps:
            return stamps
        differences = list(map(operator.sub, stamps, arrivals))
        if all(arrivals) and max(differences) - min(differences) <= tolerance \
                and offset - tolerance <= min(differences) and max(differences) <= offset + tolerance:
            # every stamp within the tolerance of the clock and of each other: none is off, whatever the driving
            # messages among them set the clock to (the common case, checked without a Python step per message)
            if driving in topics:
                self._clock_offset = differences[len(topics) - 1 - topics[::-1].index(driving)]
            return stamps
        restamped = None
        for k, (stamp, arrival, topic) in enumerate(zip(stamps, arrivals, topics)):
            if not arrival:  # the clock has not started (use_sim_time before /clock)
                continue
            if topic == driving:
                offset = stamp - arrival
            elif not -tolerance <= stamp - arrival - offset <= tolerance:
                if restamped is None:
                    stamps, restamped = list(stamps), []
                stamps[k] = arrival + offset
                restamped.append(topic)
        self._clock_offset = offset
        if restamped:
            with self._stats.lock:
                self._restamped.update(restamped)
        return stamps

    def _needs_message(self, record, triggers):
        """Whether a trigger reads fields of ``record``'s messages (memoised per topic and connection)."""
        key = (record.topic, id(record.connection))
        known = self._decode.get(key)
        if known is None or known[0] is not record.connection:
            known = self._decode[key] = (record.connection, any(t.needs_message(record) for t in triggers))
        return known[1]

    def _check_open(self, name):
        if self._closed:
            raise ValueError('%s: the logger is closed' % name)

    def _take(self, record):
        """Buffer a record and run the triggers of its topic (those that read fields get it decoded)."""
        if not record.cost:
            record = record._replace(cost=self._cost.of(record))  # the buffer keeps this very record
        self._take_all([record])

    def _take_all(self, records, topics=None, connections=None):
        """Buffer records (each with its cost) and run the triggers of their topics: first every trigger that
        reads a batch (``batched``) over its records of the batch, then, record by record, the buffer and the
        Fires of every trigger in order (those that read fields get the record decoded). ``topics``,
        ``connections``: of the records, when known."""
        topics = list(map(_TOPIC, records)) if topics is None else topics
        connections = list(map(_CONNECTION, records)) if connections is None else connections
        views, error = self._views(records, topics, connections)
        if error is not None:
            error = raw_message.UndecodableRecord(len(views), records[len(views)].topic, error)
            records = records[:len(views)]
            topics, connections = topics[:len(views)], connections[:len(views)]
        present = set(topics)
        ahead = {}  # batched trigger -> its Fires of each of its records, in order
        for trigger in self._batched:
            if present <= trigger.topics:
                mine = views
            else:
                mine = list(itertools.compress(views, map(trigger.topics.__contains__, topics)))
            if mine:
                ahead[trigger] = iter(trigger.on_records(mine))
        driving = self.driving_topic
        by_topic = self._by_topic
        timed, latched, fire = self._timed, self._latched_of(connections), self._fire
        for record, view, topic in zip(records, views, topics):
            if latched and raw_message.is_latched(record.connection):
                self._latched.setdefault(topic, collections.deque(maxlen=LATCHED_KEPT)).append(record)
            if topic == driving:
                done = self._buffer.add(record)
                if done:
                    self._complete(done)
                self._last_stamp = record.stamp
            else:
                done = self._buffer.add_side(record)
                if done:
                    self._complete(done)
            for trigger in by_topic.get(topic, ()):
                fires = ahead.get(trigger)
                fires = next(fires) if fires is not None else trigger.on_record(view)
                if fires:
                    fire(fires)
            for trigger in timed:
                fires = trigger.on_time(record.stamp)
                if fires:
                    fire(fires)
        if error is not None:
            raise error

    @staticmethod
    def _latched_of(connections):
        """Whether any of ``connections`` latches."""
        distinct = dict(zip(map(id, connections), connections)).values()
        return any(raw_message.is_latched(connection) for connection in distinct)

    def _views(self, records, topics, connections):
        """``(the records as the triggers see them: decoded where a trigger of the topic reads fields, the
        error decoding one)``; the views stop before a record that cannot be decoded."""
        by_topic = self._by_topic
        firsts = dict(zip(zip(map(id, connections), topics), records))  # one record of each connection and topic
        if not any(record.msg is None and topic in by_topic and self._needs_message(record, by_topic[topic])
                   for (_, topic), record in firsts.items()):
            return records, None
        views = list(records)
        for k, record in enumerate(records):
            triggers = by_topic.get(record.topic)
            if record.msg is None and triggers and self._needs_message(record, triggers):
                try:
                    views[k] = raw_message.decoded(record)  # before buffering: one that cannot be decoded is not kept
                except raw_message.DECODE_ERRORS as error:
                    return views[:k], error
        return views, None

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
        ``before`` and ``after`` in seconds (None or 0: ``pre`` and ``post``; the past only as far as the
        logger holds it, at most ``pre``).

        Returns ``(True, message)`` or ``(False, why not)``: disabled, closed, no driving message yet, or a
        bad span.
        """
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
            self._fire([fire])
            start = self._buffer.window_start
            return True, 'window triggered at %.3f (%s)%s' % (
                self._last_stamp, fire.reason, '' if start is None else ', from %.3f' % start)

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
        """Flush, then wait for the writer to write every queued window (see ``WindowWriter.close``).
        Idempotent. Returns True when every queued window was handled within ``timeout`` s (None: wait).
        """
        with self._lock:
            if not self._closed:
                self._complete(self._buffer.flush())
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
            raw_estimate = self._raw_estimate.total
        written = self.writer.stats()
        triggers = {trigger.name: trigger.stats() for trigger in self.triggers}
        classified = [triggers[trigger.name] for trigger in self.classifiers]
        calls = sum(t['classifier_calls'] for t in classified)
        s = self._stats
        with s.lock:
            result = {
                'enabled': self._enabled,
                'messages_seen': s.messages_seen,
                'messages_kept': written['messages_kept'],
                'messages_queued': written['messages_queued'],
                'messages_buffered': buffered,
                'buffered_bytes': buffered_bytes,
                'buffer_trimmed': trimmed,
                'messages_lost': written['messages_lost'],
                'raw_json_bytes': s.raw_json_bytes + raw_estimate,
                'stored_bytes': written['stored_bytes'],
                'windows_opened': s.windows_opened,
                'windows_saved': written['windows_saved'],
                'windows_queued': written['jobs_queued'],
                'windows_lost': written['jobs_lost'],
                'write_errors': written['write_errors'],
                'last_error': written['last_error'],
                'classifier_calls': calls,
                'classifier_mean_us': (sum(t['classifier_seconds'] for t in classified) / calls * 1e6
                                       if calls else 0.0),
                'classifier_max_us': max([t['classifier_max_seconds'] for t in classified] or [0.0]) * 1e6,
                'anomalous_messages': sum(t['anomalous_messages'] for t in classified),
                'fires_dropped': s.fires_dropped,
                'triggers': triggers,
                'time_resets': resets,
                'windows_held': written['jobs_held'],
                'messages_held': written['messages_held'],
                'write_retries': written['write_retries'],
                'disk_paused': written['disk_paused'],
                'windows_deleted': written['windows_deleted'],
                'bytes_deleted': written['bytes_deleted'],
                'last_deleted': written['last_deleted'],
                'messages_refused': s.messages_refused,
                'last_refused': s.last_refused,
                'queue_depth': written['queue_depth'],
                'bytes_queued': written['bytes_queued'],
                'messages_shed': sum(self._shed.values()),
                'shed_by_topic': dict(self._shed),
                'messages_restamped': sum(self._restamped.values()),
                'restamped_by_topic': dict(self._restamped),
            }
        # Not in any window (outside every anomaly, seen while paused, or trimmed from the pre buffer).
        result['messages_dropped'] = (result['messages_seen'] - result['messages_kept'] - result['messages_queued']
                                      - result['messages_buffered'] - result['messages_lost'] - result['messages_shed'])
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
        with self._stats.lock:
            self._stats.messages_refused += 1
            self._stats.last_refused = '%s: %s message refused (the topic carries %s)' % (topic, msg_type, expected)
        return False

    def _new_buffer(self):
        buffer = WindowBuffer(pre=self.pre, post=self.post, max_window=self.max_window,
                              max_buffer_mb=self.max_buffer_mb, cost=self._cost,
                              part_factor=log_format.formats.get(self.format).PART_FACTOR,
                              topic_limits=self.topic_limits, held_elsewhere=self._bytes_queued)
        if getattr(self, '_buffer', None) is not None:
            self._resets += self._buffer.resets
            self._trimmed += self._buffer.trimmed
        else:
            self._resets = self._trimmed = 0
        self._buffer = buffer
        for trigger in self.triggers:
            trigger.reset()
        self._last_stamp = None

    def _fire(self, fires):
        """Open or extend windows for the Fires of a trigger."""
        for fire in fires:
            if self._last_stamp is None:  # nothing to keep around yet
                with self._stats.lock:
                    self._stats.fires_dropped += 1
                continue
            announce = not self._buffer.window_active
            done = self._buffer.trigger(fire.reason, fire.score, fire.name, fire.pre, fire.post)
            if announce:
                with self._stats.lock:
                    self._stats.windows_opened += 1
                start = self._buffer.window_start
                self._emit(Event(OPENED, self._last_stamp, fire.reason, fire.score, self._threshold_of(fire.name),
                                 self._last_stamp if start is None else start, None, 0, '', 0, '', fire.name))
            self._complete(done)

    def _threshold_of(self, name):
        for trigger in self.classifiers:
            if trigger.name == name:
                return trigger.threshold
        return self.threshold

    def _bytes_queued(self):
        """Memory of the parts handed to the writer and not yet written."""
        return self.writer.bytes_queued if self.writer is not None else 0

    def _complete(self, windows):
        """Hand completed windows to the writer, each with the latched messages at its start, thinned first when
        the writer has fallen so far behind that it would not fit in the memory budget (``_within_budget``)."""
        for window in windows:
            window, shed = self._within_budget(window)
            metadata = self._metadata(window)
            if shed:
                metadata['dropped'] = shed
            self.writer.submit(window_writer.Job(self._with_latched(window), metadata))

    def _within_budget(self, window):
        """``(window, {topic: messages dropped})``: when the writer's queue, the buffer, this window and room for
        the next part together pass the memory budget, the window's heavy messages (``HEAVY_BYTES`` or more:
        images, clouds, scans) are thinned evenly, over the window, until it fits; light ones (odometry, IMU,
        diagnostics) are always kept.
        What is dropped is counted per topic (``stats()['shed_by_topic']``) and said in the window's metadata."""
        budget, queued = self._buffer.max_buffer_bytes, self._bytes_queued()
        if not budget or not window.records or not queued:  # (an idle writer keeps up: the part is already held)
            return window, {}
        cost = sum(record.cost for record in window.records)
        room = budget - self._buffer.part_limit - self._buffer.buffered_bytes - queued  # and room for the next
        if cost <= room:
            return window, {}
        heavy = [record.cost >= HEAVY_BYTES for record in window.records]
        heavy_bytes = sum(record.cost for record, big in zip(window.records, heavy) if big)
        if not heavy_bytes:
            return window, {}
        keep = max(0.0, min(1.0, (room - (cost - heavy_bytes)) / float(heavy_bytes)))
        kept, shed, share = [], collections.Counter(), 0.0
        for record, big in zip(window.records, heavy):
            if big:
                share += keep
                if share < 1.0:
                    shed[record.topic] += 1
                    continue
                share -= 1.0
            kept.append(record)
        with self._stats.lock:
            self._shed.update(shed)
        window.records = kept
        return window, dict(shed)

    def _with_latched(self, window):
        """``window`` with, first, the newest message of each latched topic from before its start (not one it
        holds), restamped at its start, as ``rosbag record`` writes latched messages when it subscribes (in the
        first part of a window whose parts go into one file)."""
        if not self._latched or not window.records or (window.part > 1 and log_format.streams(self.format)):
            return window
        held = set(id(record) for record in window.records)
        start = window.start
        first = []
        for topic in sorted(self._latched):
            before = [record for record in self._latched[topic] if record.stamp <= start and id(record) not in held]
            if before:
                first.append(before[-1]._replace(stamp=start))
        if first:
            window.records[:0] = first
        return window

    def _metadata(self, window):
        """Smart-mode metadata added to log_format's (which already holds triggers, names, part, counts)."""
        first = window.triggers[0] if window.triggers else None
        names = set(log_format.trigger_name(trigger) for trigger in window.triggers)
        meta = {
            'reason': first.reason if first else '',
            'trigger': log_format.trigger_name(first) if first else '',
            'threshold': self.threshold if self.classifiers else None,
            'driving_topic': self.driving_topic,
            'pre': str(self.pre),
            'post': str(self.post),
            'trigger_info': {t.name: t.describe() for t in self.triggers if t.name in names},
        }
        if self.config is not None:
            meta['model'] = self.config.to_dict()
        meta.update(self.format_options)
        return meta

    # -- writer events --------------------------------------------------------------------------------

    def _written(self, event):
        """A WindowWriter event as this logger's Event."""
        if event.kind == window_writer.DELETED:
            self._emit(Event(DELETED, None, 'max_disk_mb', float('nan'), self.threshold, None, None, 0, event.path,
                             0, event.error))
            return
        window, metadata = event.job.window, event.job.metadata
        scores = [t.score for t in window.triggers if t.score is not None and not math.isnan(t.score)]
        start, end = (window.start, window.end) if len(window) else (None, None)  # (the end of a window in parts)
        first = window.triggers[0].stamp if window.triggers else start
        kind = WRITTEN if event.kind == window_writer.WRITTEN else FAILED
        self._emit(Event(kind, first, metadata['reason'], min(scores) if scores else float('nan'),
                         self._threshold_of(metadata['trigger']), start, end, len(window), event.path,
                         event.bytes, event.error, metadata['trigger']))

    def _emit(self, event):
        for callback in self._callbacks:
            callback(event)


def _check_triggers(triggers):
    """The triggers, each a ``triggers.Trigger`` with a name of its own; ValueError('triggers: ...')."""
    seen = set()
    for trigger in triggers:
        name = getattr(trigger, 'name', None)
        if not hasattr(trigger, 'on_record') or not hasattr(trigger, 'topics'):
            raise ValueError('triggers: %r is not a trigger' % (trigger,))
        if name in seen:
            raise ValueError('triggers: two triggers are named %r' % name)
        seen.add(name)
    return list(triggers)


def topic_types(triggers):
    """``{topic: type}`` the triggers read; ValueError('topics: ...') when two read one topic as two types."""
    types, owners = {}, {}
    for trigger in triggers:
        for topic, kind in trigger.topic_types().items():
            if types.setdefault(topic, kind) != kind:
                raise ValueError('topics: %s is %s for trigger %s and %s for trigger %s'
                                 % (topic, types[topic], owners[topic], kind, trigger.name))
            owners.setdefault(topic, trigger.name)
    return types


def replay(bag_path, topic, model_path, out_dir, pre=DEFAULT_PRE, post=DEFAULT_POST, fmt=DEFAULT_FORMAT,
           side_topics=(), max_window=DEFAULT_MAX_WINDOW, progress=None, retrigger=DEFAULT_RETRIGGER,
           classify_every=DEFAULT_CLASSIFY_EVERY, max_buffer_mb=DEFAULT_MAX_BUFFER_MB,
           retry_seconds=None, triggers=(), input_topics=None):
    """Run the smart logger over a bag as fast as it can be read; return a summary dict:

    ``{'input_messages', 'raw_json_bytes', 'stored_bytes', 'windows': [{'start', 'end', 'messages',
    'path'}]}`` with windows in start order (start/end: header stamps, float s, of the first and last
    message saved). ``model_path``: the model of the classifier on ``topic`` (None: only ``triggers``);
    ``triggers``, ``input_topics``: as SmartLogger's. ``progress``: optional ``callback(messages read)``,
    called every PROGRESS_EVERY messages and at the end. A window that cannot be written (disk full...) is
    retried for ``retry_seconds`` (None: ``window_writer.OFFLINE_RETRY_SECONDS``); then the replay stops.
    Raises ValueError for bad arguments, ModelError for a bad model, OSError when the bag cannot be read or a
    window cannot be written (naming ``out_dir`` and what was not written).
    """
    from cc_log.core.model import AnomalyModel
    model = AnomalyModel.load(model_path) if model_path else None
    retry_seconds = window_writer.OFFLINE_RETRY_SECONDS if retry_seconds is None else retry_seconds
    logger = SmartLogger(model, out_dir, fmt, pre, post, driving_topic=topic, side_topics=tuple(side_topics),
                         max_window=max_window, retrigger=retrigger, classify_every=classify_every,
                         max_buffer_mb=max_buffer_mb, retry_period=window_writer.OFFLINE_RETRY_PERIOD,
                         give_up_after=retry_seconds, close_retry=retry_seconds, triggers=triggers,
                         input_topics=input_topics)
    return replay_into(logger, bag_path, progress)


def replay_into(logger, bag_path, progress=None):
    """Feed every message of the bag that ``logger`` keeps or watches (its driving topic, side topics and
    trigger topics; every topic when its side topics are None) to it as serialized bytes (``on_raw``, the
    path of the live node), close it, and return ``replay``'s summary; the same errors."""
    from cc_log.storage.bag import bag_reader, bagio  # rosbag: imported here so the module stays pure
    if logger.side_topics is None:
        bag = bagio.open_bag(bag_path)
        try:
            topics = sorted(bagio.topics_of(bag))
        finally:
            bag.close()
    else:
        topics = [logger.driving_topic] + sorted(logger.side_topics)
    records = itertools.chain.from_iterable(bag_reader.read_runs(bag_path, topics))  # no Python call per record
    return replay_records(logger, records, progress, bag_path)


def _batches(records, size=None):
    """Lists of up to ``size`` (REPLAY_BATCH) consecutive records, each all serialized or all decoded."""
    stream = iter(records)
    while True:
        batch = list(itertools.islice(stream, size or REPLAY_BATCH))
        if not batch:
            return
        if list(map(_MSG, batch)).count(None) in (0, len(batch)):
            yield batch
            continue
        for _, run in itertools.groupby(batch, key=lambda record: record.msg is None):
            yield list(run)


def replay_records(logger, records, progress=None, source='the records'):
    """``replay_into`` of an iterable of ``records.Record``s (serialized ones go to ``on_raw``, decoded
    ones to ``on_message``) read from ``source`` (named in errors): the one replay of ``cclog replay`` and the
    benchmarks."""
    out_dir = logger.directory
    windows = []

    def collect(event):
        if event.kind == WRITTEN:
            windows.append({'start': event.start, 'end': event.end, 'messages': event.messages,
                            'path': event.path})
    logger.on_event(collect)
    count, stopped = 0, False
    try:
        for batch in _batches(records):
            try:
                if batch[0].msg is None:
                    logger.on_records(batch)
                else:
                    for record in batch:
                        logger.on_message(record.topic, record.msg, record.stamp)
            except raw_message.UndecodableRecord as error:
                raise ValueError('%s: a message of %s cannot be decoded (%s)' % (source, error.topic, error.error))
            except raw_message.DECODE_ERRORS as error:
                raise ValueError('%s: a message cannot be decoded (%s)' % (source, error))
            before, count = count, count + len(batch)
            if progress is not None and count // PROGRESS_EVERY != before // PROGRESS_EVERY:
                progress(count)
            if logger.writer.lost:
                stopped = True  # a window is lost: stop reading, say so below
                break
        if progress is not None:
            progress(count)
    finally:
        logger.close()
    stats = logger.stats()
    if stats['messages_lost']:
        raise OSError('%s: %d window(s) (%d messages) not written: %s; %d window(s) written%s' % (
            out_dir, stats['windows_lost'], stats['messages_lost'], stats['last_error'], stats['windows_saved'],
            '; replay stopped after %d messages of %s' % (count, source) if stopped else ''))
    return {
        'input_messages': stats['messages_seen'],
        'raw_json_bytes': stats['raw_json_bytes'],
        'stored_bytes': stats['stored_bytes'],
        'windows': sorted(windows, key=lambda window: window['start']),
    }
