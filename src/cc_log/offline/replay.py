"""Replay: one recorded bag through the smart logger (``logger.smart.SmartLogger``) as fast as it can be read.

``replay_one(bag, out, cfg)`` is ``cclog replay`` of one bag and the fleet's task per bag: the logger of a
configuration (``replay_setup``: its triggers, options and the topics to read), the bag opened once to select,
check and count those topics (``bagio.open_bag`` without its per-message index), then its records read by
``bag_reader`` and fed in batches (``replay_records``); the summary says what came in, what was kept and, per
classifier and envelope trigger, whether its flag rate drifted (``drift.DriftMonitor``). ``replay`` does the same
from a model file and options, ``replay_into`` for a logger already built (benchmarks, tests).

Edge module: ``bagio``/``bag_reader`` (and so rosbag) are imported when a bag is read.
"""
import bisect
import itertools
import operator

from cc_log.base import errors, raw_message
from cc_log.logger import smart, smart_events, trigger_topics
from cc_log.storage import window_writer

__all__ = ['replay_one', 'replay_setup', 'replay', 'replay_into', 'replay_records', 'check_bag_topics',
           'offline_logger', 'open_bag', 'checked_count', 'lost_text',
           'PROGRESS_EVERY', 'REPLAY_BATCH', 'REPLAY_BATCH_BYTES']

PROGRESS_EVERY = 1000  # messages between progress callbacks
REPLAY_BATCH = 2048    # records fed to the logger at a time (``on_records``); the writer's losses are looked at
#                        after each batch. Each batch costs the triggers a fixed part (an envelope trigger's
#                        rows and neighbour search, ~1 ms): 2048 rather than 512 takes ~8% off a Husky replay
#                        (the buffer takes a batch by slices, the open window's end too: ``WindowBuffer.add_batch``)
REPLAY_BATCH_BYTES = 16 << 20   # ... and at most this many serialized bytes (but one record): big messages
#                                 (images) come a few at a time
_MSG = operator.attrgetter('msg')
_RAW = operator.attrgetter('raw')


# -- the logger of a configuration --------------------------------------------------------------------------

def _options(cfg, online_dir=None):
    """``(SmartLogger keyword arguments, {topic: type} the triggers read)`` of ``cfg``, its triggers built (model
    files loaded; refits of online learning in ``online_dir``, None: beside the models); ``side_topics`` is None
    while topic patterns wait for a bag's topics."""
    from cc_log.learning.model import AnomalyModel
    triggers = cfg.build_triggers(AnomalyModel.load, raw_message.installed_class, online_dir=online_dir)
    return cfg.logger_options(triggers), trigger_topics.topic_types(triggers)


def _selected(cfg, options, types, bag):
    """``(options, types, topics)``: the side topics the patterns of ``cfg`` select among the topics of ``bag``
    (an open bag; none without one), with the names of ``topics``, of the triggers' ``keep`` and of the routes
    (``Config.named_topics``: a bag must hold them, but for those only a route names: ``absent_route_topics``),
    and the topics to read, driving first."""
    from cc_log.logger.config import global_name
    from cc_log.storage.bag import bagio
    if options['side_topics'] is None:
        selected = cfg.selection.select(sorted(bagio.topics_of(bag))) if bag is not None else []
        options['side_topics'] = list(dict.fromkeys(selected + [global_name(name) for name in cfg.named_topics()]))
    if bag is not None:
        absent = set(absent_route_topics(cfg, bag))
        options['side_topics'] = [topic for topic in options['side_topics'] if topic not in absent]
    driving = options['driving_topic']
    topics = [driving] + [t for t in sorted(set(options['side_topics']).union(types)) if t != driving]
    return options, types, topics


def absent_route_topics(cfg, bag):
    """The topic names only the routes of ``cfg`` name that the open ``bag`` lacks (global names, sorted): nothing
    is routed there."""
    from cc_log.logger.config import global_name
    from cc_log.storage.bag import bagio
    present = set(bagio.topics_of(bag))
    return sorted(set(global_name(name) for name in cfg.route_names()) - present)


def replay_setup(cfg, bag=None):
    """The logger options, topic types and topics (driving first) of a replay with configuration ``cfg``; topic
    patterns (``*``, ``re:``, ``!``) select among the topics of ``bag`` (an open bag, ``bagio.open_bag``; none
    without one). ValueError for a bad configuration, ModelError for a bad model."""
    options, types = _options(cfg)
    return _selected(cfg, options, types, bag)


def open_bag(bag_path):
    """The bag opened for its topics and counts (``bagio.open_bag``'s checks; its per-message index is left to
    ``bag_reader``, which reads the records)."""
    from cc_log.storage.bag import bagio
    return bagio.open_bag(bag_path, skip_index=True)


def checked_count(bag, topics, types):
    """How many messages ``topics`` have in the open ``bag``; ValueError when one is missing or not of its type
    in ``types`` (``{topic: type}``)."""
    from cc_log.storage.bag import bagio
    for topic in topics:
        bagio.check_topic(bag, topic, types.get(topic))
    return bag.get_message_count(topics)


def check_bag_topics(bag_path, topics, types):
    """A readable bag holding ``topics`` of the ``types`` given (``{topic: type}``); how many messages they have."""
    bag = open_bag(bag_path)
    try:
        return checked_count(bag, topics, types)
    finally:
        bag.close()


def offline_logger(out_dir, options):
    """A SmartLogger of ``options`` (``replay_setup``'s) writing into ``out_dir`` with the offline retries, the
    reading waiting for the writer (``wait_for_writer``: no window thinned because the writer is behind). Online
    learning refits in the replay's own thread: a refit lands at the message it was due, as on a robot (where it
    takes about a second), not minutes of message time later while a background thread races a fast replay."""
    retry = window_writer.OFFLINE_RETRY_SECONDS
    logger = smart.SmartLogger(None, out_dir, retry_period=window_writer.OFFLINE_RETRY_PERIOD,
                               give_up_after=retry, close_retry=retry, wait_for_writer=True, **options)
    for trigger in logger.classifiers:
        if getattr(trigger, 'learner', None) is not None:
            trigger.learner.background = False
    return logger


def replay_one(bag_path, out_dir, cfg, progress=None, make_dir=None, online_dir=None):
    """The smart logger of configuration ``cfg`` over one bag into ``out_dir``: ``replay``'s summary plus
    ``driving_topic``, ``format``, ``messages``, ``absent_route_topics`` (names only a route lists that the bag
    lacks) and ``drift`` (a ``drift.DriftMonitor`` of each classifier, then
    of each envelope trigger).
    ``progress(done, total)``; ``make_dir(path)`` creates ``out_dir`` once the bag is checked (default:
    ``safe_files.make_dirs``); ``online_dir``: where online learning saves its refits, resuming none (None:
    beside the model files, resuming the refit found there, as on a robot)."""
    from cc_log.learning import drift
    from cc_log.base import safe_files
    options, types = _options(cfg, online_dir)
    bag = open_bag(bag_path)
    try:
        options, types, topics = _selected(cfg, options, types, bag)
        total = checked_count(bag, topics, types)
        absent = absent_route_topics(cfg, bag)
    finally:
        bag.close()
    (make_dir or safe_files.make_dirs)(out_dir)
    logger = offline_logger(out_dir, options)
    monitors = drift.monitor_classifiers(logger.classifiers) + drift.monitor_envelopes(logger.triggers)
    summary = replay_records(logger, _records(bag_path, topics),
                             None if progress is None else (lambda done: progress(done, total)), bag_path)
    summary.update(driving_topic=options['driving_topic'], format=cfg.format, messages=total, drift=monitors,
                   absent_route_topics=absent,
                   online=[{'classifier': t.name, 'resumed': t.learner.resumed} for t in logger.classifiers
                           if getattr(t, 'learner', None) is not None])
    return summary


# -- feeding a logger ---------------------------------------------------------------------------------------

def _records(bag_path, topics):
    """The serialized records of ``topics`` in bag order (``bag_reader``: no Python call per record)."""
    from cc_log.storage.bag import bag_reader  # rosbag: imported here
    return itertools.chain.from_iterable(bag_reader.read_runs(bag_path, topics))


def replay(bag_path, topic, model_path, out_dir, pre=smart.DEFAULT_PRE, post=smart.DEFAULT_POST,
           fmt=smart.DEFAULT_FORMAT, side_topics=(), max_window=smart.DEFAULT_MAX_WINDOW, progress=None,
           retrigger=smart.DEFAULT_RETRIGGER, classify_every=smart.DEFAULT_CLASSIFY_EVERY,
           max_buffer_mb=smart.DEFAULT_MAX_BUFFER_MB, retry_seconds=None, triggers=(), input_topics=None):
    """Run the smart logger over a bag as fast as it can be read; return a summary dict:

    ``{'input_messages', 'raw_json_bytes', 'stored_bytes', 'windows': [{'name', 'start', 'end', 'messages',
    'files', 'path'}], 'keep_budget', 'messages_restamped', 'restamped_by_topic', 'messages_trimmed_silent'}``
    with windows in start order, one per window whatever its files
    (``smart_events.WindowTally``: messages in all of them; start/end: header stamps, float s, of the first and last
    message saved; path: its first file); ``keep_budget``: ``KeepBudget.stats()``, the windows the keep budget
    skipped; ``messages_restamped``, ``restamped_by_topic``: the messages placed at the clock, their header stamps
    off it; ``messages_trimmed_silent``: side messages after a window's end let go to stay within the memory budget,
    the driving topic silent while the window was open (``SmartLogger.stats()``). ``model_path``: the model of the
    classifier on ``topic`` (None: only ``triggers``); ``triggers``,
    ``input_topics``: as SmartLogger's. ``progress``: optional ``callback(messages read)``, called every
    PROGRESS_EVERY messages and at the end. The reading waits for the writer (``SmartLogger``'s
    ``wait_for_writer``: nothing thinned because it is behind). A window that cannot be written (disk full...) is
    retried for ``retry_seconds`` (None: ``window_writer.OFFLINE_RETRY_SECONDS``); then the replay stops.
    Raises ValueError for bad arguments, ModelError for a bad model, OSError when the bag cannot be read or a
    window cannot be written (naming ``out_dir`` and what was not written).
    """
    from cc_log.learning.model import AnomalyModel
    model = AnomalyModel.load(model_path) if model_path else None
    retry_seconds = window_writer.OFFLINE_RETRY_SECONDS if retry_seconds is None else retry_seconds
    logger = smart.SmartLogger(model, out_dir, fmt, pre, post, driving_topic=topic, side_topics=tuple(side_topics),
                               max_window=max_window, retrigger=retrigger, classify_every=classify_every,
                               max_buffer_mb=max_buffer_mb, retry_period=window_writer.OFFLINE_RETRY_PERIOD,
                               give_up_after=retry_seconds, close_retry=retry_seconds, triggers=triggers,
                               input_topics=input_topics, wait_for_writer=True)
    return replay_into(logger, bag_path, progress)


def replay_into(logger, bag_path, progress=None):
    """Feed every message of the bag that ``logger`` keeps or watches (its driving topic, side topics and
    trigger topics; every topic when its side topics are None) to it as serialized bytes (``on_records``, the
    path of the live node), close it, and return ``replay``'s summary; the same errors."""
    if logger.side_topics is None:
        bag = open_bag(bag_path)
        try:
            from cc_log.storage.bag import bagio
            topics = sorted(bagio.topics_of(bag))
        finally:
            bag.close()
    else:
        topics = [logger.driving_topic] + sorted(logger.side_topics)
    return replay_records(logger, _records(bag_path, topics), progress, bag_path)


def _batches(records, size=None, most_bytes=None):
    """Lists of up to ``size`` (REPLAY_BATCH) consecutive records and ``most_bytes`` (REPLAY_BATCH_BYTES) of
    serialized bytes (a record larger alone), each all serialized or all decoded."""
    stream = iter(records)
    while True:
        batch = list(itertools.islice(stream, size or REPLAY_BATCH))
        if not batch:
            return
        for part in _by_bytes(batch, most_bytes or REPLAY_BATCH_BYTES):
            if list(map(_MSG, part)).count(None) in (0, len(part)):
                yield part
                continue
            for _, run in itertools.groupby(part, key=lambda record: record.msg is None):
                yield list(run)


def _by_bytes(batch, most):
    """``batch`` cut into runs of at most ``most`` serialized bytes each (a record larger alone)."""
    ends = list(itertools.accumulate([0 if raw is None else len(raw) for raw in map(_RAW, batch)]))
    if ends[-1] <= most:
        return [batch]
    parts, start = [], 0
    while start < len(batch):
        before = ends[start - 1] if start else 0
        stop = max(bisect.bisect_right(ends, before + most, start), start + 1)
        parts.append(batch[start:stop])
        start = stop
    return parts


def lost_text(stats):
    """What a replay lost, as its error says it: the windows not written (and their messages), or, when every window
    was written, the messages left out of them (json-xz: bytes that cannot be decoded)."""
    if stats['windows_lost']:
        return '%d window(s) (%d messages) not written' % (stats['windows_lost'], stats['messages_lost'])
    return '%d messages not written, left out of the windows written' % stats['messages_lost']


def replay_records(logger, records, progress=None, source='the records'):
    """``replay_into`` of an iterable of ``records.Record``s (serialized ones go to ``on_records``, decoded
    ones to ``on_message``) read from ``source`` (named in errors): the one replay of ``cclog replay`` and the
    benchmarks."""
    out_dir = logger.directory
    tally = smart_events.WindowTally()
    logger.on_event(tally)
    count, stopped = 0, False
    try:
        for batch in _batches(records):
            try:
                if batch[0].msg is None:
                    logger.on_records(batch)
                else:
                    for record in batch:
                        logger.on_message(record.topic, record.msg, record.stamp)
            except errors.UndecodableRecord as error:
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
        raise OSError('%s: %s: %s; %d window(s) written%s' % (
            out_dir, lost_text(stats), stats['last_error'], stats['windows_saved'],
            '; replay stopped after %d messages of %s' % (count, source) if stopped else ''))
    return {
        'input_messages': stats['messages_seen'],
        'raw_json_bytes': stats['raw_json_bytes'],
        'stored_bytes': stats['stored_bytes'],
        'windows': tally.windows(),
        'keep_budget': logger.budget.stats(),  # the windows it skipped (logger.keep_budget)
        'messages_restamped': stats['messages_restamped'], 'restamped_by_topic': stats['restamped_by_topic'],
        'messages_trimmed_silent': stats['buffer_trimmed_silent'],  # after a window, its driving topic silent
    }
