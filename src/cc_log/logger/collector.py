"""Collect mode: log everything, rotated into complete window files, plus feature vectors for learning.

``Collector`` keeps every message it is fed. The stream is cut into files by ``rotate`` (a message count
``'6000'``, a duration ``'60s'`` or a size ``'20MB'`` of raw row-JSON bytes), and earlier when the messages
of the file being collected reach half the memory budget ``max_buffer_mb`` (the other half is for the file
being written); every file is a complete window file
of the chosen format, readable on its own. From the driving topic it computes a feature vector every
``stride`` messages once a whole feature window of continuous data is in, and writes each vector as its own
file under ``<directory>/features/<label>/`` with ``learning.write_vector`` — the training data of learn
mode. Files and vectors go through the ``window_writer.WindowWriter`` smart mode uses (background thread,
held in memory and retried on a disk problem, quota, free-space floor).

``collect_bag`` computes the same vectors from a bag (``cclog collect``), through the same writer. With a
configuration's rules, ``rule_spans`` finds where they fire in the bag and ``drop_flagged`` removes the vectors
whose window overlaps one (with the rule's pre/post): a day with aborts and collisions is not all nominal.

Pure: no rospy (``collect_bag`` imports ``bagio``, and so rosbag, only when called).
"""
import bisect
import collections
import functools
import os
import re
import threading
import time

from cc_log import features as features_mod
from cc_log.base import event_kinds, msg_codec, safe_files
from cc_log.learning import learning
from cc_log.storage import log_format
from cc_log.storage import window_writer
from cc_log.logger.options import STRIDE, check_label, get as option
from cc_log.base.spans import Rotation
from cc_log.base.records import LogWindow, Record, Trigger
from cc_log.buffer.window_buffer import DEFAULT_MAX_BUFFER_MB, MemoryCost, budget_bytes, part_bytes

__all__ = ['Collector', 'Rotation', 'collect_bag', 'DEFAULT_ROTATE', 'DEFAULT_STRIDE', 'DEFAULT_LABEL',
           'DEFAULT_WINDOW', 'DEFAULT_FEATURE_SET', 'FEATURES_SUBDIRECTORY']

DEFAULT_ROTATE = option('rotate').default
DEFAULT_STRIDE = option('stride').default  # driving messages between feature vectors (4 per second at 100 Hz)
ENOUGH_VECTORS = 200  # offline, without a stride given: a smaller stride when the default gives fewer vectors
DEFAULT_LABEL = option('label').default
DEFAULT_WINDOW = option('window').default
DEFAULT_FEATURE_SET = option('feature_set').default
FEATURES_SUBDIRECTORY = 'features'
JUMP_BACK_TOLERANCE = 1.0  # seconds a stamp may go backwards before the stream counts as restarted


def parse_stride(value):
    """A positive whole number of messages; ValueError('stride: ...') otherwise."""
    return STRIDE.parse(value, 'stride')


class VectorStream(features_mod.FeatureStream):
    """The feature vectors collect mode writes: ``features.FeatureStream`` with a vector every ``stride``
    messages of the set's first input (``add(msg, stamp)`` returns it, or None)."""

    def __init__(self, config, stride=DEFAULT_STRIDE):
        self.stride = parse_stride(stride)
        super(VectorStream, self).__init__(config, every=self.stride)


def input_roles(config, topics=None):
    """``{topic: role}`` of the other inputs of ``config``'s feature set: ``topics`` names them in the set's
    order (None: their role names); ValueError('input_topics: ...') when the number does not match."""
    roles = [role for role, _ in config.feature.inputs[1:]]
    topics = roles if topics is None else list(topics)
    if len(topics) != len(roles):
        raise ValueError('input_topics: the %s feature set reads %d other topic(s) (%s), got %d'
                         % (config.feature_set, len(roles), ', '.join(roles) or 'none', len(topics)))
    return dict(zip(topics, roles))


class VectorSpec(object):
    """One feature set collect mode computes: its ``name``, FeatureConfig, ``topics`` (one per input of the
    set) and the directory its vectors go to (``<directory>/<label>/<stamp>.json``)."""

    def __init__(self, name, config, topics, directory, stride):
        self.name = name
        self.config = config
        self.topic = topics[0]
        self.roles = input_roles(config, topics[1:])
        self.directory = directory
        self.stream = VectorStream(config, stride)

    @property
    def topics(self):
        """Every topic the set reads."""
        return {self.topic}.union(self.roles)


class Collector(object):
    """Log every message into rotated window files and write feature vectors of every feature set.

    directory: the logging directory (window files there, vectors under ``features/<label>/``, or
    ``features/<name>/<label>/`` for each of ``feature_specs``); fmt: ``'json-xz'`` or ``'bag-lz4'``;
    rotate: see ``Rotation.parse``; driving_topic: the topic name the feature set's first input (the
    odometry) is fed with; input_topics: the topic names of the set's other inputs, in its order (default:
    their role names, e.g. ``cmd_vel``; logged too); window, feature_set: the feature window and set of the
    vectors; feature_specs: instead of those, ``[(name, FeatureConfig, topics)]``: several sets, each with
    the topics of its inputs (the collect side of a configuration's classifiers; driving_topic then defaults
    to the first one's first topic); side_topics: other topics to keep (None: every topic fed); stride: a
    vector every ``stride`` messages of a set's first input; label: the vectors' label; background: write
    on a writer thread; max_buffer_mb: memory budget of the file being collected and the one being written
    (MB; 0: none): half of it starts a new file; max_disk_mb, min_free_mb, retry_period, max_held_messages,
    close_retry: the writer's (see ``window_writer.WindowWriter``); format_options: keys added to every
    window's metadata that the format reads (json-xz: ``precision``); max_files, prefix: the writer's quota in
    files and the file names' prefix (``log_format.file_prefix``).

    Thread-safe. Bad configuration raises ``ValueError('<parameter>: ...')``.
    """

    def __init__(self, directory, fmt=log_format.formats.DEFAULT, rotate=DEFAULT_ROTATE, driving_topic='odom',
                 side_topics=None, input_topics=None,
                 window=DEFAULT_WINDOW, feature_set=DEFAULT_FEATURE_SET, stride=DEFAULT_STRIDE,
                 label=DEFAULT_LABEL, background=True, max_buffer_mb=DEFAULT_MAX_BUFFER_MB, max_disk_mb=0,
                 min_free_mb=0, retry_period=window_writer.DEFAULT_RETRY_PERIOD,
                 max_held_messages=window_writer.DEFAULT_MAX_HELD_MESSAGES, close_retry=0.0, feature_specs=None,
                 format_options=None, max_files=0, prefix=log_format.PREFIX):
        self.directory = str(directory)
        self.format = log_format.Format.check(fmt)
        self.format_options = dict(format_options or {})  # e.g. json-xz precision: in every window's metadata
        self.rotate = Rotation.parse(rotate)
        self.stride = parse_stride(stride)
        self.label = check_label(label)
        self.features_directory = os.path.join(self.directory, FEATURES_SUBDIRECTORY)
        self.max_buffer_bytes = budget_bytes(max_buffer_mb)
        if feature_specs is None:
            config = features_mod.FeatureConfig(feature_set, window)
            roles = [role for role, _ in config.feature.inputs[1:]]
            others = roles if input_topics is None else list(input_topics)
            self.specs = [VectorSpec('', config, [driving_topic] + others, self.features_directory, self.stride)]
        else:
            self.specs = [VectorSpec(name, config, list(topics),
                                     safe_files.inside(self.features_directory, name, 'classifier', True),
                                     self.stride) for name, config, topics in feature_specs]
            if driving_topic is None and self.specs:
                driving_topic = self.specs[0].topic
        if not driving_topic:
            raise ValueError('driving_topic: must not be empty')
        self.driving_topic = driving_topic
        self.config = self.specs[0].config if self.specs else None
        watched = set().union(*(spec.topics for spec in self.specs))
        self.side_topics = None if side_topics is None else frozenset(side_topics).union(watched) - {driving_topic}
        self._lock = threading.Lock()
        self._stats_lock = threading.Lock()
        self._cost = MemoryCost()
        self._chunk = []
        self._chunk_bytes = 0
        self._chunk_cost = 0
        self._chunk_span = None
        self._clock = None
        self._part = 0
        self._closed = False
        self._callbacks = []
        self.counters = collections.OrderedDict([('messages_seen', 0), ('raw_json_bytes', 0), ('time_resets', 0)])
        self.writer = window_writer.WindowWriter(
            self.directory, self.format, max_disk_mb, min_free_mb, retry_period=retry_period,
            max_held_messages=max_held_messages, background=background, close_retry=close_retry,
            name='cc_log collect writer', max_files=max_files, prefix=prefix)
        self.guard = self.writer.guard
        self.writer.on_event(self._written)

    def on_event(self, callback):
        """Call ``callback(kind, detail)`` after each write, ``kind`` of ``base.event_kinds``: WRITTEN, FAILED or
        DELETED; ``detail`` a dict with ``what`` (``window_writer.WINDOW`` or ``VECTOR``) and path, bytes,
        messages, start, end for a window file; path, stamp for a vector; messages, error, kept for a failure
        (kept True while the file is held in memory and retried); path, error for a window file the quota
        deleted."""
        self._callbacks.append(callback)

    def on_message(self, topic, msg, stamp=None, size=None):
        """Keep one message (``stamp``: receipt/bag time, used when the message has no header stamp;
        ``size``: its serialized length when known, for the memory estimate)."""
        if topic != self.driving_topic and self.side_topics is not None and topic not in self.side_topics:
            return
        raw = msg_codec.row_json_bytes(msg)
        stamp = features_mod.stamp_of(msg, time.time() if stamp is None else stamp)
        with self._lock:
            if self._closed:
                raise ValueError('on_message: the collector is closed')
            cost = self._cost(msg, size)
            self._count('messages_seen', 1)
            self._count('raw_json_bytes', raw)
            if self._clock is not None and stamp < self._clock - JUMP_BACK_TOLERANCE:
                self._count('time_resets', 1)
                self._rotate()
                self._clock = None
            if self._chunk and (self._due(stamp, raw) or (
                    self.max_buffer_bytes and self._chunk_cost + cost > part_bytes(self.max_buffer_bytes))):
                self._rotate()
            self._clock = stamp if self._clock is None else max(self._clock, stamp)
            if self._chunk_span is None:
                self._chunk_span = (stamp, stamp)
            else:
                self._chunk_span = (min(self._chunk_span[0], stamp), max(self._chunk_span[1], stamp))
            self._chunk.append(Record(stamp, topic, msg, cost))
            self._chunk_bytes += raw
            self._chunk_cost += cost
            for spec in self.specs:
                if topic == spec.topic:
                    vector = spec.stream.add(msg, stamp)
                    if vector is not None:
                        self.writer.submit(vector_job(spec.directory, self.label, stamp, vector, spec.config))
                elif topic in spec.roles:
                    spec.stream.observe(spec.roles[topic], msg, stamp)

    def flush(self):
        """Write the current file now (even when it is not due for rotation)."""
        with self._lock:
            self._rotate()

    def close(self, timeout=None):
        """Write the current file and wait for the writer (see ``WindowWriter.close``); idempotent. True when
        the writer finished within ``timeout`` seconds."""
        with self._lock:
            if not self._closed:
                self._rotate()
                self._closed = True
        return self.writer.close(timeout)

    def stats(self):
        """A snapshot of the counters (dict): messages_seen, raw_json_bytes, time_resets, messages_buffered,
        buffered_bytes, files_written, vectors_written, and the writer's (messages_kept, messages_lost,
        stored_bytes, write_errors, last_error, files_held, ... see ``WindowWriter.stats``)."""
        with self._lock:
            buffered, buffered_bytes = len(self._chunk), self._chunk_cost
        with self._stats_lock:
            result = dict(self.counters)
        written = self.writer.stats()
        result.update((key, value) for key, value in written.items() if key not in ('written', 'windows_saved'))
        result['files_written'] = written['windows_saved']
        result['vectors_written'] = written['written'].get(VECTOR, 0)
        result['files_held'] = written['jobs_held']
        result['files_lost'] = written['jobs_lost']
        result['messages_buffered'] = buffered
        result['buffered_bytes'] = buffered_bytes
        return result

    # -- internals ------------------------------------------------------------------------------------

    def _count(self, key, amount):
        with self._stats_lock:
            self.counters[key] += amount

    def _due(self, stamp, raw):
        """Whether the message at ``stamp`` of ``raw`` bytes belongs in a new file."""
        rotate = self.rotate
        if rotate.bytes is not None:
            return self._chunk_bytes + raw > rotate.bytes
        if rotate.span.is_duration:  # the file spans less than the duration, whatever the arrival order
            first, last = self._chunk_span
            return max(last, stamp) - min(first, stamp) >= rotate.span.seconds
        return len(self._chunk) >= rotate.span.count

    def _rotate(self):
        if not self._chunk:
            return
        records = sorted(self._chunk, key=lambda record: record.stamp)  # stable: arrival order on ties
        self._part += 1
        window = LogWindow(records, [Trigger(records[0].stamp, 'collect', None)], self._part)
        self._chunk = []
        self._chunk_bytes = 0
        self._chunk_cost = 0
        self._chunk_span = None
        metadata = {'reason': 'collect', 'part': window.part, 'driving_topic': self.driving_topic,
                    'rotate': str(self.rotate)}
        metadata.update(self.format_options)
        self.writer.submit(window_writer.Job(window, metadata))

    def _written(self, event):
        """A WindowWriter event as this collector's ``(kind, detail)`` callback."""
        job = event.job
        if event.kind == event_kinds.DELETED:
            detail = {'what': window_writer.WINDOW, 'path': event.path, 'error': event.error}
        elif event.kind == event_kinds.FAILED:
            detail = {'what': job.what, 'messages': job.messages, 'error': event.error, 'kept': event.kept}
        elif job.window is not None:
            window = job.window
            detail = {'what': window_writer.WINDOW, 'path': event.path, 'bytes': event.bytes,
                      'messages': len(window), 'start': window.start, 'end': window.end}
        else:
            detail = {'what': VECTOR, 'path': event.path, 'stamp': job.tag}
        for callback in self._callbacks:
            callback(event.kind, detail)


VECTOR = 'vector'  # Job.what of a feature-vector file


def vector_job(directory, label, stamp, vector, config):
    """A WindowWriter job writing one feature vector with ``learning.write_vector`` (tag: its stamp)."""
    return window_writer.Job(write=functools.partial(learning.write_vector, directory, label, stamp, vector, config),
                             what=VECTOR, tag=stamp)


def auto_stride(count, stride, enough=ENOUGH_VECTORS):
    """The stride that gives about ``enough`` vectors where ``stride`` gave ``count`` (never larger than
    ``stride``, at least 1)."""
    if count >= enough:
        return stride
    return max(1, min(stride, count * stride // enough))


def _vectors_of(bag_path, topics, config, stride):
    """``(stride, stamps, vectors)`` of a bag; ``stride`` None: DEFAULT_STRIDE, or smaller (``auto_stride``)
    when that gives fewer than ENOUGH_VECTORS vectors."""
    from cc_log.storage.bag import bagio  # rosbag: imported here so the module stays pure
    chosen = DEFAULT_STRIDE if stride is None else stride
    stamps, vectors = bagio.feature_vectors(bag_path, topics, config, chosen)
    smaller = chosen if stride is not None else auto_stride(len(stamps), chosen)
    if smaller < chosen:
        chosen = smaller
        stamps, vectors = bagio.feature_vectors(bag_path, topics, config, chosen)
    return chosen, stamps, vectors


def collect_bag(bag_path, topic, out_dir, label=DEFAULT_LABEL, window=DEFAULT_WINDOW, stride=None,
                feature_set=DEFAULT_FEATURE_SET, retry_seconds=None, feature_specs=None):
    """Write the feature vectors of ``topic`` in a bag into ``out_dir/<label>/`` (one file each), as collect
    mode does live (``topic``: of the feature set's first input, or a list: it and the topics of the set's
    other inputs, in its order); with ``feature_specs`` (``[(name, FeatureConfig, topics)]``, as Collector's)
    instead, the vectors of each set into ``out_dir/<name>/<label>/``. Returns ``{'vectors': n, 'directory':
    out_dir/<label>, 'sets': {name: (vectors, directory)}, 'strides': {name: stride}, 'stride': the first
    set's}`` (directory: the first set's). ``stride`` None: DEFAULT_STRIDE, or a smaller one that gives about
    ENOUGH_VECTORS vectors when the bag is short (``auto_stride``). Raises ValueError
    for bad arguments or an unreadable bag; a vector that cannot be written (disk full...) is retried for
    ``retry_seconds`` (None: ``window_writer.OFFLINE_RETRY_SECONDS``), then OSError names the directory and
    how many vectors were not written.
    """
    check_label(label)
    stride = None if stride is None else parse_stride(stride)
    if feature_specs is None:
        specs = [('', features_mod.FeatureConfig(feature_set, window), topic, out_dir)]
    else:
        specs = [(name, config, topics, safe_files.inside(out_dir, name, 'classifier', True))
                 for name, config, topics in feature_specs]
    computed = [(name, config, directory) + _vectors_of(bag_path, topics, config, stride)
                for name, config, topics, directory in specs]
    retry_seconds = window_writer.OFFLINE_RETRY_SECONDS if retry_seconds is None else retry_seconds
    writer = window_writer.WindowWriter(out_dir, background=False, retry_period=window_writer.OFFLINE_RETRY_PERIOD,
                                        give_up_after=retry_seconds, close_retry=retry_seconds)
    result = {'sets': {}, 'strides': {}}
    for name, config, directory, chosen, stamps, vectors in computed:
        result['strides'][name] = chosen
        before = writer.stats()['written'].get(VECTOR, 0)
        for stamp, vector in zip(stamps, vectors):
            writer.submit(vector_job(directory, label, stamp, vector, config))
            if writer.lost:
                break
        written = writer.stats()['written'].get(VECTOR, 0) - before
        where = safe_files.inside(directory, label, 'label', True)
        if written < len(stamps):
            writer.close()
            raise OSError('%s: %d of %d feature vectors not written: %s' % (
                where, len(stamps) - written, len(stamps), writer.stats()['last_error']))
        result['sets'][name] = (len(stamps), where)
    writer.close()
    first = result['sets'][computed[0][0]] if computed else (0, out_dir)
    result.update(vectors=first[0], directory=first[1],
                  stride=result['strides'][computed[0][0]] if computed else stride)
    return result


RULE_EXCLUDED_KINDS = ('classifier', 'periodic')  # triggers that say nothing about a span being anomalous


def rule_triggers(triggers):
    """The triggers of ``triggers`` that flag anomalies by rule (aborts, collisions, bumper, diagnostics errors):
    every kind but the classifiers (their model is what is being trained) and periodic samples."""
    return [trigger for trigger in triggers if trigger.kind not in RULE_EXCLUDED_KINDS]


def rule_spans(bag_path, triggers, pre, post, rate):
    """``[(start, end, [names])]``: the merged spans of message time (seconds) ``triggers`` fire on over a bag,
    each fire widened by its trigger's ``pre``/``post`` (else the logger's ``pre``/``post``: Spans; a count of
    messages is read at ``rate`` messages per second). Topics the bag lacks are left out."""
    from cc_log.storage.bag import bagio  # rosbag: imported here so the module stays pure
    bag = bagio.open_bag(bag_path)
    try:
        present = set(bagio.topics_of(bag))
    finally:
        bag.close()
    types = {}
    for trigger in triggers:
        types.update(trigger.topic_types())
    topics = sorted(set().union(*(trigger.topics for trigger in triggers)) & present) if triggers else []
    timed = [trigger for trigger in triggers if trigger.watches_time]

    def seconds(span, default):
        span = default if span is None else span
        return span.seconds if span.is_duration else span.count / float(rate)

    fired = []
    if topics:
        for record in bagio.read_messages(bag_path, topics, dict((t, types[t]) for t in topics if t in types)):
            for trigger in triggers:
                found = list(trigger.on_record(record)) if record.topic in trigger.topics else []
                if trigger in timed:
                    found += trigger.on_time(record.stamp)
                fired += [(record.stamp - seconds(fire.pre, pre), record.stamp + seconds(fire.post, post), fire.name)
                          for fire in found]
    spans = []
    for start, end, name in sorted(fired):
        if spans and start <= spans[-1][1]:
            spans[-1][1] = max(spans[-1][1], end)
            spans[-1][2].add(name)
        else:
            spans.append([start, end, {name}])
    return [(start, end, sorted(names)) for start, end, names in spans]


def drop_flagged(directory, label, spans, window_seconds):
    """Remove the vector files of ``directory/<label>/`` whose feature window ``[stamp - window_seconds, stamp]``
    overlaps one of ``spans`` (``rule_spans``): they are not nominal. Returns how many were removed."""
    folder = safe_files.inside(directory, label, 'label', True)
    if not spans or not os.path.isdir(folder):
        return 0
    starts = [start for start, _, _ in spans]
    removed = 0
    for name in os.listdir(folder):
        if not name.endswith('.json') or safe_files.TMP_MARK in name:
            continue
        try:
            stamp = float(name[:-len('.json')])
        except ValueError:
            continue
        # the last span starting at or before the stamp: spans are merged, so it also ends last among those
        index = bisect.bisect_right(starts, stamp) - 1
        if index >= 0 and spans[index][1] >= stamp - window_seconds:
            os.unlink(safe_files.inside(folder, name, 'vector'))
            removed += 1
    return removed


_VECTOR_LEFTOVER = re.compile(r'.+\.json%s(\d+)(\.\d+)?' % re.escape(safe_files.TMP_MARK))


def remove_vector_leftovers(directory):
    """Remove the feature-vector files a cancelled collect left half written (``<stamp>.json.tmp-<pid>[.<n>]``
    anywhere below ``directory``) by this process or by processes that have ended (the workers of a cancelled
    cluster); a running process's are kept. A vector is recomputed from its bag, so nothing saved is lost.
    Returns the paths removed."""
    removed = []
    for root, _, names in os.walk(directory):
        for name in names:
            match = _VECTOR_LEFTOVER.fullmatch(name)
            if match and not safe_files.writer_running(safe_files.pid_of(match.group(1))):
                path = os.path.join(root, name)
                try:
                    os.unlink(path)
                except FileNotFoundError:
                    continue
                removed.append(path)
    return sorted(removed)
