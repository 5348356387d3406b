"""What the cc_log nodes share: typed parameters, start-up, the logging directory, crash leftovers,
diagnostics and the writer's part of their status.

- ``Params``: every private parameter is read through one typed reader that checks its type and range and
  raises ``ConfigError('~<name>: ...')`` (one line, printed by ``fail``) instead of a traceback; each
  resolved value is logged once. ``init_node`` first checks the ``_name:=value`` arguments for what rospy
  itself would choke on (an integer beyond XML-RPC's 32 bits, YAML it cannot parse).
- ``resolve_directory``: ``~directory``, else ``$ROS_HOME/cc_log``, else ``/tmp/cc_log``; a fallback is
  returned as a warning the node keeps on /diagnostics (WARN, with the directory in use).
- ``recover_leftovers``: crash leftovers recovered or reported at start (``recovery``), each logged.
- ``Diagnostics``: one DiagnosticStatus every period of wall time through diagnostic_updater, with each
  subscribed topic's message rate (``TopicRates``); ``writer_status``: the status of the
  window writer and the disk (write errors, held windows, paused writing, quota, leftovers, fallback).
- ``TopicSilenceWatch``: WARN when the driving topic is silent or a topic the configuration names never had a
  message, naming the published topics that look like it (``health``).

ROS edge (rospy).
"""
import ctypes
import logging
import os
import sys
import threading
import time

import diagnostic_updater
import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from cc_log.logger import config, health, options
from cc_log.base import safe_input
from cc_log.storage import log_format
from cc_log.storage import recovery
from cc_log.storage.directory import LoggingDirectory
from cc_log.buffer import window_buffer
from cc_log.base.errors import ConfigError

EXIT_BAD_CONFIG = 1                # as cclog's bad input (2 is its command-line usage error)
DISK_WARN_BYTES = 200 * 1000 ** 2  # diagnostics warn below this much free disk
XMLRPC_INT = 2 ** 31               # XML-RPC integers are 32-bit signed
DEFAULT_MAX_BUFFER_MB = window_buffer.DEFAULT_MAX_BUFFER_MB
CLOSE_TIMEOUT = 10.0               # seconds to wait at shutdown for the last windows to be written: roslaunch
#                                    sends SIGTERM 15 s after SIGINT (what is not written by then is counted in a
#                                    last log line; a window file cut off is recovered at the next start)
CLOSE_RETRY = 5.0                  # seconds held windows are retried at shutdown before they count as lost
MALLOC_MMAP_THRESHOLD = 32 * 2 ** 20   # glibc's largest: buffers below it come from the heap, reused once freed
MALLOC_TRIM_THRESHOLD = 256 * 2 ** 20  # free heap memory kept for reuse before any is handed back
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt's parameter numbers (malloc.h)


# -- parameters -------------------------------------------------------------------------------------------

def to_bool(name, value):
    """A parameter value as a bool (``true``/``1``/``yes``/``on`` or the opposites); ConfigError otherwise."""
    try:
        return options.BOOL.parse(value, '~' + name)
    except ValueError as error:
        raise ConfigError(str(error))


_SETTINGS = []  # [dict] once ``read_settings_only`` was called: the private parameters, not the master's


def read_settings_only(settings):
    """From now on every ``Params`` of this process reads ``settings`` (a dict) and never the parameter
    server: ``rosrun cc_log record`` reads its command line only, as rosbag record does (it sets nothing on
    the master and reads nothing an earlier run left there)."""
    _SETTINGS[:] = [dict(settings)]


def _ros_get(name, default):
    if _SETTINGS:
        return _SETTINGS[0].get(name, default)
    return rospy.get_param('~' + name, default)


def _ros_names():
    """The names of the node's private parameters (the first level under its namespace)."""
    if _SETTINGS:
        return list(_SETTINGS[0])
    prefix = rospy.get_name().rstrip('/') + '/'
    return [name[len(prefix):].split('/')[0] for name in rospy.get_param_names() if name.startswith(prefix)]


class Params(object):
    """Typed private parameters. ``get(name, default)`` reads one (default: ``rospy.get_param('~' + name,
    default)``; a dict's ``get`` serves in tests); ``log(format, *args)`` reports the resolved value
    (default: rospy.loginfo); ``names()`` lists the private parameters set (default: the node's namespace).
    Every reader raises ConfigError('~name: ...') for a value of the wrong type or out of range."""

    def __init__(self, get=None, log=None, names=None):
        self._get = get if get is not None else _ros_get
        self._log = log if log is not None else rospy.loginfo
        self._names = names if names is not None else _ros_names

    def unknown(self):
        """A warning for each private parameter that is neither an option (``logger.options``) nor a key of the
        configuration (``rosparam load`` of a file): ``unknown parameter ~formt (did you mean ~format?)``."""
        known = sorted(set(o.name for o in options.OPTIONS).union(options.sections(), STRUCTURED))
        warnings = []
        for name in sorted(set(self._names()) - set(known)):
            near = safe_input.closest(name, known)
            warnings.append('unknown parameter ~%s%s' % (safe_input.printable(name),
                                                         ' (did you mean ~%s?)' % near if near else ''))
        return warnings

    def value(self, name, default, log=True):
        """The raw value (any type) or ``default``; logged once unless ``log`` is False."""
        value = self._get(name, default)
        if log:
            shown = value
            if value in (None, '') or value == default:
                shown = '%s (default)' % (value if value not in (None, '', ()) else 'none')
            self._log('~%s: %s', name, shown)
        return value

    def given(self, name):
        """Whether the parameter is set to something other than '' (launch files pass '' for "not given")."""
        return self.value(name, None, log=False) not in (None, '')

    def text(self, name, default='', log=True):
        """A string (None and '' give ``default``)."""
        value = self.value(name, default, log)
        if value is None or value == '':
            return default
        if not isinstance(value, str):
            raise ConfigError('~%s: %r is not a string' % (name, value))
        return value

    def option(self, name):
        """The parameter of the option ``name`` (``logger.options``) checked by its grammar; its declared default
        when it is not set."""
        declared = options.get(name)
        value = self.value(name, declared.default)
        if value is None or value == '':
            return declared.default
        try:
            return declared.parse(value, '~' + name)
        except ValueError as error:
            raise ConfigError(str(error))

    def configuration(self, node):
        """``{name: checked value}`` of the configuration's options that are parameters of ``node`` (``'smart'``,
        ``'collect'``) and are set: they override the configuration file's keys."""
        return dict((o.name, self.option(o.name)) for o in options.for_node(node) if o.key and self.given(o.name))


def _too_large(value):
    if isinstance(value, bool):
        return False
    if isinstance(value, int):
        return not -XMLRPC_INT <= value < XMLRPC_INT
    if isinstance(value, (list, tuple)):
        return any(_too_large(item) for item in value)
    if isinstance(value, dict):
        return any(_too_large(item) for item in value.values())
    return False


def check_command_line(argv):
    """ConfigError for a ``_name:=value`` argument that rospy.init_node would fail on with a traceback."""
    from rospy.client import load_command_line_node_params
    try:
        params = load_command_line_node_params(argv)
    except rospy.exceptions.ROSInitException as error:
        raise ConfigError(' '.join(str(error).split()))
    for name, value in sorted(params.items()):
        if _too_large(value):
            raise ConfigError('~%s: %s is too large (a ROS parameter integer has 32 bits: -2147483648 to '
                              '2147483647)' % (name, value))


def node_name(name, argv):
    """The node's name for messages: rospy's once initialized, else ``__name:=`` or ``name``."""
    if rospy.core.is_initialized():
        return rospy.get_name()
    import rosgraph.names
    return '/' + rosgraph.names.load_mappings(argv).get('__name', name).lstrip('/')


def init_node(name, argv):
    """``rospy.init_node`` after ``check_command_line`` (ConfigError instead of a traceback), with freed
    message buffers reused (``reuse_freed_memory``); with ``~quiet`` the node logs warnings and errors only."""
    check_command_line(argv)
    reuse_freed_memory()
    rospy.init_node(name, argv=argv)
    if Params(log=lambda *args: None).option('quiet'):
        logging.getLogger('rosout').setLevel(logging.WARNING)  # rospy.loginfo's logger (init_node's log_level)


def format_options(params, cfg):
    """What the window format is told in each window's metadata: the configuration's (``precision``) and
    ``~chunk_kb`` when it is set."""
    chunk = {'chunk_kb': params.option('chunk_kb')} if params.given('chunk_kb') else {}
    return dict(cfg.format_options(), **chunk)


def reuse_freed_memory():
    """Make glibc keep freed message buffers for the next messages instead of handing them back to the system
    and mapping fresh pages again, a page fault per 4 kB: with a 30 Hz camera and a lidar (37 MB/s) that cost
    the smart node 2/3 of its CPU time, in the kernel (bench/heavy_sensors.py). What the node holds stays bounded
    by ``max_buffer_mb``; its resident memory then stays near its peak instead of falling back. Returns whether
    the C library took both settings (False where it is not glibc)."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    return bool(mallopt(_M_MMAP_THRESHOLD, MALLOC_MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, MALLOC_TRIM_THRESHOLD))


def fail(node, error):
    """Print the one-line configuration error and return the exit status."""
    sys.stderr.write('%s: %s\n' % (node, ' '.join(str(error).split())))
    return EXIT_BAD_CONFIG


# -- configuration ----------------------------------------------------------------------------------------

STRUCTURED = ('driving_topic', 'windows', 'limits', 'collect', 'triggers')


def node_config(params, flat, classifier=None):
    """The node's ``config.Config``: the YAML file ``~config``, then the structured parameters (``~triggers``,
    ``~windows``, ``~limits``, ``~collect``, ``~driving_topic``: what ``rosparam load`` of such a file into the
    node's namespace sets), then the flat ones (``flat``: ``{'pre': value or None, ...}``, see
    ``config.FLAT``) and the single classifier of ``classifier`` (see ``config.with_classifier``): later ones
    override. ConfigError naming what is wrong."""
    path = params.text('config', '')
    data = {}
    if path:
        try:
            data = config.load_file(os.path.expanduser(path))
        except ValueError as error:
            raise ConfigError('~config: %s' % error)
    structured = dict((key, params.value(key, None)) for key in STRUCTURED if params.given(key))
    data = config.with_flat(config.merge(data, structured), flat)
    try:
        data = config.with_classifier(data, **(classifier or {}))  # ~model: an envelope file or a model
    except ValueError as error:
        raise ConfigError('~model: %s' % error)
    try:
        return config.Config.from_dict(data, ('~config %s' % path) if path else 'parameters')
    except ValueError as error:
        raise ConfigError(str(error))


# -- directory and leftovers ------------------------------------------------------------------------------

def resolve_directory(value):
    """``(directory, warning)``: ``value``, else $ROS_HOME/cc_log, else /tmp/cc_log (created); ``warning`` is ''
    or says why the requested directory is not used and which one is (the node shows it on /diagnostics)."""
    try:
        directory = LoggingDirectory(value or None)
    except OSError as error:
        raise ConfigError('~directory: %s' % error)
    for path, reason in directory.tried:
        rospy.logwarn('~directory: cannot use %s (%s)', path, reason)
    rospy.loginfo('logging to %s', directory.path)
    warning = ''
    if directory.tried and value:
        warning = '~directory %s cannot be used (%s): logging to %s' % (
            directory.tried[0][0], directory.tried[0][1], directory.path)
    return directory.path, warning


def recover_leftovers(directory, vector_directory=None, prefix=log_format.PREFIX):
    """Recover crash leftovers in ``directory`` (of files named ``<prefix>...``, see ``recovery``) and log each;
    return the outcomes. Leftovers
    of feature-vector files under ``vector_directory`` (``<label>/*.tmp-*``) are reported (UNRECOVERABLE,
    kept)."""
    outcomes = recovery.recover_directory(directory, prefix)
    if vector_directory and os.path.isdir(vector_directory):
        for label in sorted(os.listdir(vector_directory)):
            folder = os.path.join(vector_directory, label)
            names = sorted(os.listdir(folder)) if os.path.isdir(folder) else []
            outcomes.extend(recovery.Outcome(os.path.join(folder, name), recovery.UNRECOVERABLE, '', 0,
                                             'a feature vector file cut off by a crash, kept')
                            for name in names if log_format.TMP_MARK in name)
    for outcome in outcomes:
        if outcome.status == recovery.BUSY:
            rospy.loginfo('leftover %s: %s', outcome.leftover, outcome.detail)
        elif outcome.status == recovery.UNRECOVERABLE:
            rospy.logwarn('crash leftover NOT recovered, kept: %s: %s', outcome.leftover, outcome.detail)
        else:
            rospy.logwarn('crash leftover %s: %s', outcome.leftover, outcome.detail)
    return outcomes


# -- diagnostics ------------------------------------------------------------------------------------------

def free_disk(path):
    """Bytes free for an unprivileged user on the file system of ``path`` (None if unknown)."""
    try:
        status = os.statvfs(path)
    except OSError:
        return None
    return status.f_bavail * status.f_frsize


class TopicRates(object):
    """Messages and MB per second of wall time of each topic since the previous ``values`` call (pure).

    ``clock``: seconds of wall time (default ``time.monotonic``). ``values(counts, sizes=None)`` takes ``{topic:
    messages received so far}`` (and ``{topic: bytes received so far}``) and returns the /diagnostics pairs
    ``('rate <topic> Hz', '12.50')`` (and ``('MB/s <topic>', '3.200')``), sorted by topic; a topic first seen
    counts from 0, so its first rate is taken over the whole interval."""

    def __init__(self, clock=time.monotonic):
        self._clock = clock
        self._last = clock()
        self._counts, self._sizes = {}, {}

    def values(self, counts, sizes=None):
        """The rate pairs for ``counts`` and ``sizes`` (see the class)."""
        now = self._clock()
        elapsed = now - self._last

        def per_second(total, before):
            return (total - before) / elapsed if elapsed else 0.0
        pairs = [('rate %s Hz' % topic, '%.2f' % per_second(count, self._counts.get(topic, 0)))
                 for topic, count in sorted(counts.items())]
        pairs += [('MB/s %s' % topic, '%.3f' % (per_second(size, self._sizes.get(topic, 0)) / 1e6))
                  for topic, size in sorted((sizes or {}).items())]
        self._last, self._counts, self._sizes = now, dict(counts), dict(sizes or {})
        return pairs


class _Updater(diagnostic_updater.Updater):
    """diagnostic_updater's Updater that publishes each status under the task's own name (the library
    prefixes the node's name) and publishes nothing when a task is added (no "Node starting up" status
    without the node's values)."""

    def publish(self, msg):
        array = DiagnosticArray(status=msg if isinstance(msg, list) else [msg])
        array.header.stamp = rospy.get_rostime()
        self.publisher.publish(array)

    def addedTaskCallback(self, task):
        pass


class Diagnostics(object):
    """The node's DiagnosticStatus ``name`` on /diagnostics through a ``diagnostic_updater.Updater``, every
    ``period`` seconds of wall time (0: none), so a paused or jumping simulated clock never stops it: the
    updater's own ``update()`` schedules on rospy time, so a wall-time thread calls ``force_update()``.

    ``status_fn()`` returns ``(level, message, [(key, value), ...])``; ``counts()`` (optional) returns
    ``{topic: messages received so far}`` (``Intake.counts``) and ``sizes()`` (optional) ``{topic: bytes}``
    (``Intake.sizes``), shown as ``rate <topic> Hz`` and ``MB/s <topic>`` entries (see ``TopicRates``) after the
    node's values."""

    def __init__(self, name, period, status_fn, counts=None, sizes=None):
        self.name = name
        self.period = period
        self.status_fn = status_fn
        self.counts, self.sizes = counts, sizes
        self.rates = TopicRates()
        self.updater = None
        self._stop = threading.Event()
        self._thread = None
        if period > 0:
            self.updater = _Updater()
            self.updater.setHardwareID(rospy.get_name())
            self.updater.add(name, self._run)
            self._thread = threading.Thread(target=self._loop, name='cc_log diagnostics')
            self._thread.daemon = True
            self._thread.start()

    def _run(self, stat):
        level, message, values = self.status_fn()
        stat.summary(level, message)
        rates = self.rates.values(self.counts(), self.sizes() if self.sizes else None) if self.counts else []
        for key, value in list(values) + rates:
            stat.add(key, value)
        return stat

    def _loop(self):
        while not self._stop.wait(self.period) and not rospy.is_shutdown():
            self.publish()

    def publish(self):
        """Publish the status now (nothing when diagnostics are off)."""
        if self.updater is None:
            return
        try:
            self.updater.force_update()
        except rospy.ROSException:  # shutting down (rospy.ROSTimeMovedBackwardsException is one too)
            pass

    def stop(self):
        """Stop publishing (waits for the thread)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()


def named_subscribed(cfg, subscribed):
    """The topic names ``cfg`` lists (``config.Config.named_topics``), resolved, that are among ``subscribed``."""
    return [topic for topic in dict.fromkeys(rospy.resolve_name(name) for name in cfg.named_topics())
            if topic in subscribed]


class TopicSilenceWatch(object):
    """Warns when the node's driving topic ``topic`` (of type ``msg_type``) is silent or missing
    (``health.DrivingWatch``: no message for ``silence`` seconds after start or after the last one), naming the
    topics the master lists with its type, and when a topic of ``named`` (the names the configuration lists,
    subscribed; ``types``: ``{topic: type}`` known) has had no message since start (``health.NamedWatch``),
    naming the published topics that look like it. Checked every ``period`` seconds of wall time on a daemon
    thread; ``counts()`` returns the node's ``{topic: messages received so far}``. Logged once: the driving
    topic's WARN per change, one WARN per silent name, INFO when their messages come; ``status(level,
    message)`` adds the WARNs to the node's /diagnostics status."""

    def __init__(self, topic, msg_type, counts, named=(), types=None, period=1.0, silence=health.SILENCE,
                 published=None):
        now = time.monotonic()
        self.watch = health.DrivingWatch(topic, msg_type, now, silence)
        self.named = health.NamedWatch([name for name in named if name != topic], now, types, silence)
        self._counts = counts
        self._published = published or rospy.get_published_topics
        self.text = self.named_text = ''
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, args=(period,), name='cc_log topic silence watch')
        self._thread.daemon = True
        self._thread.start()

    def _loop(self, period):
        while not self._stop.wait(period) and not rospy.is_shutdown():
            self.poll()

    def poll(self):
        """Check once; log what changed."""
        before, named_before = self.watch.state, self.named.state
        answers = []

        def published():  # the master asked at most once per check
            if not answers:
                answers.append(self._published())
            return answers[0]
        now, counts = time.monotonic(), self._counts()
        try:
            self.text = self.watch.check(now, counts.get(self.watch.topic, 0), published)
            silent = self.named.check(now, counts, published)
        except Exception as error:  # the master is unreachable: said next time
            rospy.logwarn_throttle(60.0, 'topic silence watch: %s' % error)
            return
        self.named_text = self.named.summary(now)
        if self.watch.state != before:
            if self.text:
                rospy.logwarn(self.text)
            else:
                rospy.loginfo('messages arrive on %s', self.watch.topic)
        for name, text in silent:
            if name not in named_before:  # once per name; /diagnostics follows what is published since
                rospy.logwarn(text)
        for name in sorted(set(named_before) - set(self.named.state)):
            rospy.loginfo('messages arrive on %s', name)

    def status(self, level, message):
        """``(level, message)`` with the silences added (WARN; the message when the status was OK)."""
        text = '; '.join(part for part in (self.text, self.named_text) if part)
        if not text:
            return level, message
        if level < health.WARN:
            return health.WARN, text
        return level, message + '; ' + text

    def stop(self):
        """Stop checking."""
        self._stop.set()
        self._thread.join(1.0)


def writer_status(level, message, writer, leftovers=(), directory_warning=''):
    """The window writer's and the disk's part of a node's status.

    ``level``, ``message``: the node's own status so far; ``writer``: its ``WindowWriter``; ``leftovers``:
    the start-up recovery outcomes; ``directory_warning``: from ``resolve_directory``. Returns ``(level,
    message, values)``: the most severe condition wins (disk low, directory fallback, unrecovered leftovers:
    WARN; write errors: WARN once all were retried and written, ERROR when messages were lost; windows held
    or writing paused: ERROR), quota deletions are appended, values are the /diagnostics key-value pairs.
    """
    written, guard, directory = writer.stats(), writer.guard, writer.directory
    free = free_disk(directory)
    low = guard.min_free_bytes and free is not None and free < guard.min_free_bytes
    unrecovered = recovery.incomplete(leftovers)
    candidates = []
    if free is not None and free < DISK_WARN_BYTES:
        candidates.append((DiagnosticStatus.WARN, 'low disk space: %d MB free' % (free // 1000 ** 2)))
    if directory_warning:
        candidates.append((DiagnosticStatus.WARN, directory_warning))
    if unrecovered:
        candidates.append((DiagnosticStatus.WARN, '%d crash leftovers could not be recovered (kept): %s' % (
            len(unrecovered), unrecovered[0].kept or unrecovered[0].leftover)))
    if (written['write_errors'] or written['jobs_lost']) and not written['jobs_held']:
        if written['messages_lost'] or written['jobs_lost']:
            candidates.append((DiagnosticStatus.ERROR, 'write errors, %d messages (%d files) lost: %s' % (
                written['messages_lost'], written['jobs_lost'], written['last_error'])))
        else:
            candidates.append((DiagnosticStatus.WARN, 'write errors (%d, all retried and written): %s' % (
                written['write_errors'], written['last_error'])))
    if written['jobs_held'] or low or written['disk_paused']:
        if low or written['disk_paused']:
            text = 'disk nearly full: %.1f MB free < ~min_free_mb %g: writing paused' % (
                (free or 0) / 1e6, guard.min_free_bytes / 1e6)
        else:
            text = 'cannot write: %s' % written['last_error']
        candidates.append((DiagnosticStatus.ERROR, text + '; %d windows (%d messages) held in memory' % (
            written['jobs_held'], written['messages_held'])))
    for candidate in candidates:
        if candidate[0] >= level:
            level, message = candidate
    if written['windows_deleted']:
        message += '; %d oldest window files deleted to stay within ~max_disk_mb' % written['windows_deleted']
    values = [
        ('write errors', written['write_errors']),
        ('directory', directory),
        ('directory fallback', directory_warning or 'no'),
        ('free disk bytes', free if free is not None else 'unknown'),
        ('windows held', written['jobs_held']),
        ('messages held', written['messages_held']),
        ('write retries', written['write_retries']),
        ('writing paused', bool(low or written['disk_paused'])),
        ('max disk bytes', guard.max_bytes or 'no quota'),
        ('min free bytes', guard.min_free_bytes or 'off'),
        ('disk usage bytes', guard.usage()),
        ('windows deleted (quota)', written['windows_deleted']),
        ('bytes deleted (quota)', written['bytes_deleted']),
        ('last deleted', written['last_deleted']),
        ('leftovers recovered', sum(1 for o in leftovers if o.status in (
            recovery.COMPLETE, recovery.PARTIAL, recovery.DUPLICATE, recovery.EMPTY))),
        ('leftovers unrecoverable', len(unrecovered)),
        ('leftover messages recovered', sum(o.messages for o in leftovers if o.status == recovery.PARTIAL)),
        ('leftover bytes unrecoverable', sum(o.lost_bytes for o in leftovers)),
    ]
    return level, message, values
