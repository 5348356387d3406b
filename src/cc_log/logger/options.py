"""Every option of cc_log, declared once: name, grammar, default, one line of documentation and where it is set.

An ``Option`` may be

- a key of the configuration file (``key``: ``windows.pre``; the file every mode reads, ``config.Config``),
- a private parameter of the nodes named in ``nodes`` (``~pre``; ``smart`` is smart_logger.py, ``collect`` is
  collect_logger.py),
- a flag of the ``cclog`` commands named in ``commands`` (``--pre``),

and the configuration's checks, the nodes' parameters, the flags and docs/OPTIONS.md all come from here, with
one grammar per kind of value (``spans``: ``1G`` and ``5m`` mean the same everywhere). A parameter or flag
overrides the configuration's key. Every grammar states the sane range of what it reads (``Grammar.ranges``,
``spans.Range``: minimum, maximum, unit, and the value that turns the option off), so an accepted value is a
sane one; only the grammars of a few named values (``CHOICES``) have none.

``TOPIC_OPTIONS`` are per topic: the keys of ``topic_limits`` (``{camera/image_raw: {pre: 2s, max_mb: 64}}``),
read into one ``TopicLimits`` per topic.

To add an option: declare it here (with a grammar that states its range) and use it where it acts (a per-topic
one: a field of ``TopicLimits``, read by the window buffer); a launch file passes it as an ``<arg>`` if it
should; ``tools/options_doc.py`` rewrites docs/OPTIONS.md (a test checks that it is current).
"""
import argparse
import collections
import math
import re

from cc_log import features
from cc_log.base import safe_input
from cc_log.logger.keep_budget import MAX_PER_HOUR
from cc_log.base.routes import ROUTE_KEYS, parse_routes
from cc_log.base.safe_input import brief
from cc_log.base.spans import ROTATIONS, Range, Rotation, Span, megabytes, seconds
from cc_log.base.topic_select import topic_list
from cc_log.buffer.window_buffer import DEFAULT_MAX_BUFFER_MB, DEFAULT_MAX_WINDOW, DEFAULT_POST, DEFAULT_PRE
from cc_log.storage import context_track, formats, log_format
from cc_log.storage.formats import json_xz
from cc_log.triggers.classifier import DEFAULT_CLASSIFY_EVERY, DEFAULT_RETRIGGER, RETRIGGER_MODES
from cc_log.triggers.drift_gate import DEFAULT_ON_DRIFT, ON_DRIFT

SMART, COLLECT, BOTH = ('smart',), ('collect',), ('smart', 'collect')
MAX_TEXT = 1 << 20   # characters of a YAML value given as text (a launch argument)
MAX_DIAGNOSTIC_PERIOD = 3600.0  # longest ``~diagnostic_period`` (a longer wait overflows the thread's timer)


class Grammar(collections.namedtuple('Grammar', 'parse metavar text ranges', defaults=((),))):
    """How a value is written: ``parse(value, name)`` returns it checked (ValueError('<name>: ...') naming the
    option), ``metavar`` shows it on a command line, ``text`` in the docs; ``ranges``: the ``spans.Range`` of
    each quantity it reads (a duration, a count, a size, the length of a text, the entries of a list), outside
    which ``parse`` refuses a value with ``<name>: <value> is outside <low>..<high> <unit>`` (none: one of a
    few values, ``CHOICES``)."""

    __slots__ = ()


def _choice(values_of):
    """A grammar of one of the strings ``values_of()`` returns."""
    def parse(value, name):
        values = values_of()
        if not isinstance(value, str) or value not in values:
            raise ValueError('%s: %s is not one of: %s' % (name, brief(value), ', '.join(values)))
        return value
    return parse


def _text(value, name):
    if not isinstance(value, str):
        raise ValueError('%s: %s is not a string' % (name, brief(value)))
    return value


def _boolean(value, name):
    text = str(value).strip().lower() if isinstance(value, (str, int)) else None
    if isinstance(value, bool):
        return value
    if text in ('true', '1', 'yes', 'on'):
        return True
    if text in ('false', '0', 'no', 'off'):
        return False
    raise ValueError('%s: %s is not true or false' % (name, brief(value)))


def number(within, metavar, text, integer=False):
    """A grammar of a finite number within the Range ``within`` (a whole one when ``integer``)."""
    def parse(value, name):
        result = float('nan')
        if not isinstance(value, bool) and isinstance(value, (int, float, str)):
            try:
                result = float(value)
            except (ValueError, OverflowError):
                pass
        if not math.isfinite(result):
            raise ValueError('%s: %s is not a number' % (name, brief(value)))
        if integer and result != int(result):
            raise ValueError('%s: %s is not a whole number' % (name, brief(value)))
        within.check(result, value, name)
        return int(result) if integer else result
    return Grammar(parse, metavar, text, (within,))


def size(low, high, off=0.0):
    """A grammar of a byte size in MB (``spans.megabytes``) from ``low`` to ``high`` MB, or ``off``."""
    within = Range(low, high, 'MB', off)
    return Grammar(lambda value, name: megabytes(value, name, within=within), 'SIZE',
                   'a size: MB (`64`) or with a unit (`64MB`, `2GB`, `1G`, `1.5GiB`)', (within,))


def duration(low, high, off=None):
    """A grammar of a duration (``spans.seconds``) from ``low`` to ``high`` seconds, or ``off``."""
    within = Range(low, high, 's', off)
    return Grammar(lambda value, name: seconds(value, name, within=within), 'DURATION',
                   'a duration (`2s`, `250ms`, `5m`, `2h`; a number is seconds)', (within,))


def span(counts, durations):
    """A grammar of a span (``spans.Span``): ``counts`` messages or ``durations`` seconds (two Ranges)."""
    return Grammar(lambda value, name: Span.parse(value, name, counts, durations), 'N|DURATION',
                   'messages (`100`) or a duration (`2s`, `250ms`, `5m`)', (counts, durations))


def ranged(grammar, within, measure):
    """``grammar`` whose values also have ``measure(value)`` (their length, their entries) within the Range
    ``within``, checked first."""
    def parse(value, name):
        amount = measure(value)
        if amount is not None:
            within.check(amount, value, name)
        return grammar.parse(value, name)
    return grammar._replace(parse=parse, ranges=grammar.ranges + (within,))


def _characters(value):
    """The length of a text (of an argument list: its words joined), None for anything else."""
    if isinstance(value, str):
        return len(value)
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        return len(' '.join(value))
    return None


def _entries(value):
    """How many entries a list, a mapping or a space/comma-separated text holds (None for anything else)."""
    if isinstance(value, str):
        return len(value.replace(',', ' ').split())
    return len(value) if isinstance(value, (list, tuple, dict)) else None


def characters(grammar, low, high):
    """``grammar`` for texts of ``low`` to ``high`` characters."""
    return ranged(grammar, Range(low, high, 'characters', form=lambda n: 'x' * int(n)), _characters)


def entries(grammar, high, form):
    """``grammar`` for lists (or mappings) of at most ``high`` entries; ``form(n)``: a value of ``n`` entries."""
    return ranged(grammar, Range(0, high, 'entries', form=form), _entries)


def _topic(value, name):
    if not isinstance(value, str) or not value.strip():
        raise ValueError('%s: %s is not a topic name' % (name, brief(value)))
    return value.strip()


def _stride(value, name):
    stride = Span.parse(value, name, STRIDES)
    if stride.is_duration:
        raise ValueError('%s: %s must be a whole number of messages' % (name, brief(value)))
    return stride.count


_LABEL = re.compile(r'[A-Za-z0-9_.-]+')


def check_label(label, name='label'):
    """``label`` when it can name a directory, else ValueError('<name>: ...')."""
    if not isinstance(label, str) or not _LABEL.fullmatch(label) or label in ('.', '..'):
        raise ValueError('%s: %s must be letters, digits, ".", "_" or "-"' % (name, brief(label)))
    return label


def _text_or_list(value, name):
    if isinstance(value, str) or (isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value)):
        return value
    raise ValueError('%s: %s is not a string or a list of strings' % (name, brief(value)))


def _scalar(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ValueError('%s: %s is not a string or a number' % (name, brief(value)))
    return str(value)


# The sane ranges (``spans.Range``) of the options' quantities: an accepted value is a sane one.
DAY = 86400.0
MIN_MB = 1e-6             # a byte: the smallest size on disk (a sub-byte split meant "never")
MIN_MEMORY_MB = 0.001     # a kB: the smallest memory bound
MAX_MEMORY_MB = 1e6       # a TB of memory
MAX_DISK_MB = 1e9         # a PB of disk
MAX_TOPICS = 10000        # topics named in one option
MAX_PATH_CHARS = 4096     # a file name or a command
MAX_NAME_CHARS = 100      # a name part or a label
MARGINS = (Range(0, 10 ** 7, 'messages'), Range(0, DAY, 's'))    # pre, post: up to a day
WINDOW_LENGTHS = (Range(1, 10 ** 8, 'messages'), Range(0.001, 7 * DAY, 's'))   # windows.max: a week
STRIDES = Range(1, 10 ** 6, 'messages')
CLASSIFY_EVERY = (STRIDES, Range(0.001, 3600.0, 's'))   # a classification per message or per ms, up to an hour

SPAN = span(*MARGINS)
DURATION = duration(0, DAY)
SIZE = size(MIN_MB, MAX_DISK_MB)
BOOL = Grammar(_boolean, 'BOOL', '`true` or `false`')
TEXT = characters(Grammar(_text, 'TEXT', 'a string'), 0, MAX_PATH_CHARS)
SCALAR = characters(Grammar(_scalar, 'VALUE', 'a string or a number'), 0, 64)
TOPIC = characters(Grammar(_topic, 'TOPIC', 'a topic name'), 1, MAX_PATH_CHARS)
TOPICS = entries(Grammar(topic_list, 'TOPICS', 'topic names: a list or a space/comma-separated string'),
                 MAX_TOPICS, lambda n: ['/t%d' % i for i in range(int(n))])
STRIDE = Grammar(_stride, 'N', 'a whole number of messages', (STRIDES,))
LABEL = characters(Grammar(check_label, 'LABEL', 'letters, digits, `.`, `_`, `-`'), 1, MAX_NAME_CHARS)
ROTATION = Grammar(Rotation.parse, 'N|DURATION|SIZE', 'messages (`6000`), a duration (`60s`) or a size (`20MB`)',
                   ROTATIONS)
FORMAT = Grammar(_choice(formats.names), 'FORMAT', 'a window format: %s' % ', '.join(
    '`%s`' % name for name in formats.names()))
PRECISION = entries(Grammar(json_xz.check_precision, 'FIELD=STEP,...', "field patterns and steps: "
                            "`{'pose.pose.position.*': 1e-4}` or `'twist.twist.*=1e-5, ...'`"),
                    1000, lambda n: dict(('f%d.*' % i, 1e-4) for i in range(int(n))))
RETRIGGER = Grammar(_choice(lambda: RETRIGGER_MODES), 'MODE', ', '.join('`%s`' % m for m in RETRIGGER_MODES))
ON_DRIFT_MODE = Grammar(_choice(lambda: ON_DRIFT), 'MODE', ', '.join('`%s`' % m for m in ON_DRIFT))
FEATURE_SET = Grammar(_choice(features.names), 'SET', 'a feature set: %s' % ', '.join(
    '`%s`' % name for name in features.names()))
COMMAND = characters(Grammar(_text_or_list, 'COMMAND', 'an argument list or a string'), 0, MAX_PATH_CHARS)
NAME_PREFIX = characters(Grammar(lambda value, name: log_format.file_prefix(value, name)[:-1], 'NAME',
                                 'a plain part of a file name (no `/`, no control character, not starting with `.`)'),
                         1, MAX_NAME_CHARS)
COUNT = number(Range(1, 10 ** 7, 'files', off=0), 'N', 'a whole number', True)
MEMORY = size(MIN_MEMORY_MB, MAX_MEMORY_MB)
WINDOW_LENGTH = span(*WINDOW_LENGTHS)
FEATURE_WINDOW = span(*features.WINDOW_RANGES)
CLASSIFY_SPAN = span(*CLASSIFY_EVERY)
WINDOWS_PER_HOUR = number(Range(0.01, MAX_PER_HOUR, 'windows/h', off=0), 'N', 'a number of windows, e.g. 0.1 .. 60')
DIAGNOSTIC_PERIOD = number(Range(0.01, MAX_DIAGNOSTIC_PERIOD, 's', off=0, form=repr), 'SECONDS', 'seconds')
INTAKE_COUNT = number(Range(1, 10 ** 7, 'messages'), 'N', 'a whole number', True)
INTAKE_SIZE = size(MIN_MEMORY_MB, MAX_MEMORY_MB, None)
CHUNK_KB = number(Range(1, 1 << 20, 'KB'), 'KB', 'a whole number of KB (1024 bytes)', True)
#: The grammars of one of a few values: their values are their range.
CHOICES = (BOOL, FORMAT, RETRIGGER, ON_DRIFT_MODE, FEATURE_SET)


class Option(collections.namedtuple('Option', 'name key grammar default doc nodes commands')):
    """One option (see the module docstring): ``key`` is its path in the configuration ('' for none),
    ``nodes`` and ``commands`` where it is a parameter and a flag."""

    __slots__ = ()

    def parse(self, value, name=None):
        """``value`` checked by the option's grammar (ValueError naming ``name``, default: the key or name)."""
        return self.grammar.parse(value, name or self.key or self.name)

    @property
    def flag(self):
        """The ``cclog`` flag: ``--max-buffer-mb``."""
        return '--' + self.name.replace('_', '-')


def _option(name, key, grammar, default, doc, nodes=(), commands=()):
    return Option(name, key, grammar, default, doc, tuple(nodes), tuple(commands))


TOPIC_OPTIONS = (
    _option('pre', 'pre', DURATION, None, "the topic's own time kept before the window's first trigger (at most "
            "the window's)"),
    _option('post', 'post', DURATION, None, "the topic's own time kept after the window's last trigger (at most "
            "the window's)"),
    _option('max_mb', 'max_mb', MEMORY, 0.0, 'memory its messages may take outside every window (0: no cap of its '
            'own)'),
)

TopicLimits = collections.namedtuple('TopicLimits', [o.name for o in TOPIC_OPTIONS],
                                     defaults=[o.default for o in TOPIC_OPTIONS])
TopicLimits.__doc__ = """What one topic of the windows keeps where it differs from the window's: one field per
``TOPIC_OPTIONS`` entry (None or 0: the window's own)."""


def parse_topic_limits(value, name='topic_limits'):
    """``{topic: TopicLimits}`` of a mapping ``{topic: {pre: 2s, post: 1s, max_mb: 64}}`` (or its YAML text,
    as a launch argument gives it); ValueError('<name>.<topic>.<key>: ...')."""
    if value is None or value == '':
        return {}
    if isinstance(value, str):
        if len(value) > MAX_TEXT:
            raise ValueError('%s: longer than %d characters' % (name, MAX_TEXT))
        value = safe_input.loads_yaml(value, name)
    if not isinstance(value, dict):
        raise ValueError('%s: a mapping of topic names to {%s}, not %s' % (
            name, ', '.join(o.key for o in TOPIC_OPTIONS), type(value).__name__))
    limits = {}
    for topic, entry in value.items():
        where = '%s.%s' % (name, _topic(topic, name))
        if isinstance(entry, TopicLimits):
            limits[topic.strip()] = entry
            continue
        entry = known_keys(entry, [o.key for o in TOPIC_OPTIONS], where)
        limits[topic.strip()] = TopicLimits(*(
            o.parse(entry[o.key], '%s.%s' % (where, o.key)) if entry.get(o.key) is not None else o.default
            for o in TOPIC_OPTIONS))
    return limits


TOPIC_LIMITS = entries(Grammar(parse_topic_limits, 'YAML', 'per topic: {%s} (see below)' % ', '.join(
    o.key for o in TOPIC_OPTIONS)), MAX_TOPICS, lambda n: dict(('/t%d' % i, {}) for i in range(int(n))))


def _context_topics(value, name):
    """The context track's topics (``topic_list``), each ``topic`` or ``topic:Hz`` with its rate within
    ``context_track.RATES`` (``context_track.parse_topics``)."""
    context_track.parse_topics(value, name, context_track.BWI_ALIASES)
    return TOPICS.parse(value, name)


CONTEXT_TOPICS = TOPICS._replace(parse=_context_topics, text='topic names, each `topic` or `topic:Hz`',
                                 ranges=TOPICS.ranges + (context_track.RATES,))
ROUTES = entries(Grammar(lambda value, name: parse_routes(value, formats.names(), name), 'YAML',
                         'a list of {%s}' % ', '.join(ROUTE_KEYS)),
                 100, lambda n: [{'name': 'r%d' % i, 'topics': ['/t%d' % i], 'format': formats.DEFAULT}
                                 for i in range(int(n))])

OPTIONS = (
    # the configuration file's keys, in the order the file documents them
    _option('topics', 'topics', TOPICS, (), 'other topics to keep in the windows: names, `*` (all), '
            '`re:<regex>`, `!<excluded>`', BOTH),
    _option('topic_limits', 'topic_limits', TOPIC_LIMITS, {}, "per-topic limits (`TOPIC_OPTIONS`), e.g. "
            "`{camera/image_raw: {pre: 2s, max_mb: 64}}`", SMART),
    _option('driving_topic', 'driving_topic', TOPIC, None, "the topic whose messages count `pre` and `post` "
            "(default: the first trigger's first topic)"),
    _option('format', 'format', FORMAT, formats.DEFAULT, 'window file format', BOTH, ('replay',)),
    _option('routes', 'routes', ROUTES, (), "topic sets written beside the window's file in a format of their own, "
            "e.g. `[{name: numeric, topics: [odom, imu/data], format: json-xz}]` (`base.routes`)", SMART),
    _option('precision', 'json_xz.precision', PRECISION, {}, 'json-xz only, opt-in lossy: round fields to a step',
            BOTH, ('replay',)),
    _option('pre', 'windows.pre', SPAN, str(DEFAULT_PRE), 'kept before an anomaly (not given: the default, or the '
            'longest `pre` of a trigger in the configuration)', SMART, ('replay',)),
    _option('post', 'windows.post', SPAN, str(DEFAULT_POST), 'kept after the last anomaly', SMART, ('replay',)),
    _option('max_window', 'windows.max', WINDOW_LENGTH, str(DEFAULT_MAX_WINDOW),
            'longer windows are handed to the writer '
            'in parts (one file)', SMART),
    _option('max_disk_mb', 'limits.max_disk_mb', SIZE, 0.0, 'keep window files within this size by deleting the '
            'oldest (0: no quota)', BOTH),
    _option('max_files', 'limits.max_files', COUNT, 0, 'keep at most this many window (and context) files by '
            "deleting the oldest, as `max_disk_mb` does (rosbag record's `--max-splits`; 0: no limit)", BOTH),
    _option('min_free_mb', 'limits.min_free_mb', SIZE, 0.0, 'below this much free disk, writing pauses and '
            'windows wait in memory (0: off)', BOTH),
    _option('max_buffer_mb', 'limits.max_buffer_mb', MEMORY, DEFAULT_MAX_BUFFER_MB, 'memory budget of every '
            'buffered message and the writer queue (0: none)', BOTH, ('replay',)),
    _option('max_windows_per_hour', 'limits.max_windows_per_hour', WINDOWS_PER_HOUR, 0.0,
            'keep budget: once this many windows opened '
            'in the last hour, a Fire opens a window only if its score is more anomalous than the hour\'s N-th '
            'most anomalous window (a rising threshold; Fires without a score always open; skipped windows are '
            'counted); 0: no budget', SMART, ('replay',)),
    _option('split_mb', 'limits.split_mb', SIZE, 0.0, "a window's file is closed and a new one begun once it holds "
            "this many MB, at the next part (`.001`, `.002`, ... before the extension; bag-lz4 and any format written "
            "a part at a time); 0: never split", SMART, ('replay',)),
    _option('rotate', 'collect.rotate', ROTATION, '60s', 'collect mode: a new file after this many messages, '
            'seconds or bytes', COLLECT),
    _option('label', 'collect.label', LABEL, 'nominal', "collect mode: the feature vectors' label directory",
            COLLECT),
    _option('stride', 'collect.stride', STRIDE, 25, 'collect mode: a feature vector every N driving messages',
            COLLECT),
    # parameters of the nodes only
    _option('config', '', TEXT, '', 'the configuration file (these keys; parameters override it)', BOTH),
    _option('directory', '', TEXT, '', 'where files go (default: $ROS_HOME/cc_log, ~/.ros/cc_log without ROS_HOME, '
            'then /tmp/cc_log)', BOTH),
    _option('name_prefix', '', NAME_PREFIX, 'cc_log', 'what file names begin with, before `_<UTC>_<reason>` '
            "(rosbag record's `-o PREFIX`); listing, recovery, the quota and uploads follow it: files named "
            'otherwise are left alone', BOTH),
    _option('model', '', TEXT, '', 'the default trigger: an envelope file (cclog learn-envelope: the trigger named '
            '`envelope`) or a model file (cclog learn: the classifier named `classifier`)', SMART),
    _option('window', '', FEATURE_WINDOW, features.DEFAULT_WINDOW,
            "the feature window (smart mode: checked against the "
            "model's)", BOTH),
    _option('feature_set', '', FEATURE_SET, 'motion', 'the feature set collect mode computes', COLLECT),
    _option('retrigger', '', RETRIGGER, DEFAULT_RETRIGGER, 'every classifier: `event` (the onset opens a window, '
            'extended while the newest rows are anomalous), `every` anomalous score, or the `onset` only', SMART),
    _option('classify_every', '', CLASSIFY_SPAN, DEFAULT_CLASSIFY_EVERY,
            'every classifier: score every N-th message or '
            'at most once per duration', SMART),
    _option('recent', '', SCALAR, '', 'every classifier, `event` only: the newest rows that keep an anomaly open '
            '(default: a quarter of the feature window)', SMART),
    _option('on_drift', '', ON_DRIFT_MODE, DEFAULT_ON_DRIFT, 'every envelope trigger, once its drift monitor has '
            'stated drift for 2 min without a break: `confirm` (a feature beyond its limit opens a window only where '
            'the robust distance confirms it; the joint check flags at 2x) or `none` (no change); '
            'triggers.drift_gate', SMART, ('replay',)),
    _option('learn_online', '', BOOL, False, 'every classifier learns nominal online and refits in the '
            'background (saved beside the model)', SMART),
    _option('enabled', '', BOOL, True, 'start logging, or start paused (`~enable` service)', SMART),
    _option('diagnostic_period', '', DIAGNOSTIC_PERIOD, 1.0,
            'seconds of wall time between /diagnostics; 0 turns them off', BOTH),
    _option('intake_max_messages', '', INTAKE_COUNT, 20000,
            'bound of the subscriber queue in messages; beyond it messages are counted as lost', SMART),
    _option('intake_max_mb', '', INTAKE_SIZE, 64.0, 'bound of the subscriber queue in bytes', SMART),
    _option('chunk_kb', '', CHUNK_KB, 768, "bag-lz4 windows and context bags: a chunk is closed once "
            "it holds this many KB uncompressed (rosbag record's `--chunksize`)", BOTH),
    _option('quiet', '', BOOL, False, "log warnings and errors only, no INFO lines (rosbag record's `-q`)", BOTH),
    _option('tcp_nodelay', '', BOOL, False, "subscribe with TCP_NODELAY (rosbag record's `--tcpnodelay`): lower "
            'latency for small messages, more packets', BOTH),
    _option('fast_receive', '', BOOL, True, "read every topic's messages off rospy's connections with cc_log's own "
            "reader (one thread for every connection), not rospy's receive (a thread per connection): docs/COST.md",
            BOTH),
    _option('context_topics', '', CONTEXT_TOPICS, (), 'topics recorded always, each `topic` or `topic:Hz`, in rotated '
            'LZ4 bags under `context/`', BOTH),
    _option('context_rotate', '', duration(1, DAY), context_track.DEFAULT_ROTATE, 'seconds of stamps per context '
            'file', BOTH),
    _option('upload_command', '', COMMAND, '', 'run with the path of each closed window or context file', BOTH),
)

_BY_NAME = dict((o.name, o) for o in OPTIONS)


def get(name):
    """The Option ``name`` (KeyError for none)."""
    return _BY_NAME[name]


def keyed():
    """The options of the configuration file, in its order."""
    return [o for o in OPTIONS if o.key]


def sections():
    """``{top-level key: [keys under it]}`` of the configuration file (``[]``: a plain value), with
    ``triggers`` last."""
    result = collections.OrderedDict()
    for option in keyed():
        top, _, sub = option.key.partition('.')
        result.setdefault(top, [])
        if sub:
            result[top].append(sub)
    result['triggers'] = []
    return result


def for_node(node):
    """The options that are parameters of ``node`` (``'smart'`` or ``'collect'``)."""
    return [o for o in OPTIONS if node in o.nodes]


def for_command(command):
    """The options that are flags of the ``cclog`` command ``command``."""
    return [o for o in OPTIONS if command in o.commands]


def known_keys(data, keys, where):
    """``data`` when it is a mapping of only ``keys`` (None: ``{}``); ValueError('<where>: ...') otherwise."""
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValueError('%s: a mapping, not %s' % (where or 'configuration', brief(data)))
    unknown = safe_input.unknown_key(data, keys, where)
    if unknown:
        raise ValueError(unknown)
    return data


def read(data):
    """``{name: checked value}`` of every configuration key in ``data`` (None where absent: see ``default``);
    ValueError('<key>: ...') for an unknown key or a bad value."""
    tree = sections()
    known_keys(data, list(tree), '')
    for top, subs in tree.items():
        if subs:
            known_keys(data.get(top), subs, top)
    values = {}
    for option in keyed():
        top, _, sub = option.key.partition('.')
        value = (data.get(top) or {}).get(sub) if sub else data.get(top)
        values[option.name] = None if value is None else option.parse(value)
    return values


def default(name):
    """The declared default of option ``name``, checked by its grammar (None stays None)."""
    option = get(name)
    return None if option.default is None else option.parse(option.default)


def with_values(data, values):
    """``data`` (not changed) with ``values`` (``{option name: value}``; None: not given) at their keys."""
    result = dict(data)
    for name, value in values.items():
        if value is None:
            continue
        top, _, sub = get(name).key.partition('.')
        if sub:
            result[top] = dict(result.get(top) or {}, **{sub: value})
        else:
            result[top] = value
    return result


def add_flags(parser, command):
    """Add the flags of ``command``'s options to the argparse ``parser``: each parsed by its grammar, None
    when not given (the configuration's value, else the default, holds)."""
    for option in for_command(command):
        parser.add_argument(option.flag, dest=option.name, metavar=option.grammar.metavar,
                            type=_argparse_type(option),
                            help='%s (default: %s)' % (option.doc.replace('%', '%%'), shown(option.default)))


def _argparse_type(option):
    def parse(text):
        try:
            option.parse(text, option.flag)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error))
        return text
    parse.__name__ = option.name
    return parse


def shown(default):
    """A default as the docs show it."""
    if default in (None, '', (), {}):
        return 'none'
    return str(default).lower() if isinstance(default, bool) else str(default)


def describe(node):
    """The parameters of ``node`` as ``--help`` shows them: a line each, ``~name (value; default): what``."""
    return ['  ~%s (%s; default: %s): %s' % (o.name, o.grammar.text.replace('`', ''), shown(o.default),
                                             o.doc.replace('`', '')) for o in for_node(node)]
