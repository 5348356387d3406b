"""The context track: an always-on, low-rate recording of chosen topics in rotated LZ4 rosbags.

Windows keep the data around anomalies; the context track keeps, between them, enough to say where the robot
went and what it reported (BWI's choice by default: odometry thinned to 1 Hz, ``amcl_pose``, ``/diagnostics``),
as BWI's ``bwi_logging`` did with ``rosbag record``. ``ContextTrack(directory, rates)``:

- ``rates``: ``{topic: Hz or None}`` (``parse_topics('odom:1 amcl_pose /diagnostics')``); a topic with a
  rate keeps at most one message per ``1/Hz`` slot of its stamps (``floor(stamp * Hz)``), so 100 Hz
  odometry at ``:1`` is exactly one message per second; ``None`` keeps every message. ``names``: ``{topic: name
  it is stored under}`` (BWI's ``odom_1hz`` holds the driving topic at 1 Hz under that name).
- files go to ``<directory>/context/cc_log_context_<UTC of the first stamp>.bag`` (LZ4 chunks); the open file
  is ``<name>.tmp-<pid>.<n>`` (``n`` counts the files this process opened, so the name is unique whatever the
  stamps do: a looping bag starts over at the same stamps while the last loop's file is still being closed) and
  is closed, fsynced and renamed when it spans ``rotate`` seconds (stamps), when
  a topic's stamps jump back (a replayed bag, a simulation reset; topics on different clocks are not a jump)
  and at ``close``. A closed file is handed to
  ``submit(job)`` as a ``window_writer.Job(write=..., what=CONTEXT)`` (the node's context writer: quota,
  retries, WRITTEN events for the upload hook); without ``submit`` it is finished in the caller's thread.
- ``add(record)`` takes a ``records.Record``: with ``raw`` and ``connection`` set (serialized bytes and
  the publisher's connection header) the bytes are written as they came (``rosbag.Bag.write(..., raw=True,
  connection_header=...)``), else the decoded message. ``on_message(topic, msg, stamp, size)`` is the same
  for the intake's sink interface, so ``Tee`` can feed a logger and the track together.
- a write that fails (disk full...) is counted and said in ``last_error``; the file is closed (what was
  written before is kept; a file no message reached is removed) and for ``retry`` seconds (``RETRY_PERIOD``,
  monotonic clock) no new file is opened: the messages of that time are counted in ``messages_lost``, then
  the next message opens a new file.

Crash leftovers (``cc_log_context_*.bag.tmp-*``) are salvaged by ``recover`` (through ``recovery``).
Pure apart from rosbag (imported when a file opens).
"""
import datetime
import itertools
import math
import os
import re
import threading
import time

from cc_log import features as features_mod
from cc_log.storage import log_format, recovery, window_writer
from cc_log.base import raw_message, safe_files
from cc_log.storage.bag import bag_writer
from cc_log.storage.formats import bag_lz4
from cc_log.base.records import Record
from cc_log.base.spans import Range, seconds
from cc_log.base.topic_select import topic_list

__all__ = ['ContextTrack', 'Tee', 'parse_topics', 'recover', 'SUBDIRECTORY', 'PREFIX', 'DEFAULT_TOPICS',
           'DEFAULT_ROTATE', 'BWI_ALIASES']

SUBDIRECTORY = 'context'
PREFIX = log_format.CONTEXT_PREFIX
EXTENSION = '.bag'
DEFAULT_TOPICS = 'odom:1 amcl_pose /diagnostics'
DEFAULT_ROTATE = 600.0   # seconds of stamps per file
JUMP_BACK = 1.0          # stamps going back more than this start a new file
RETRY_PERIOD = 5.0       # seconds (monotonic clock) without a new file after a write failed: messages are lost
# bwi_logging/record.launch names its odometry thinned to 1 Hz (topic_tools drop) odom_1hz; here it means the same.
BWI_ALIASES = {'odom_1hz': ('odom', 1.0)}
#: A context topic's sane rate (1e308 Hz kept every message, with an ERROR per message).
RATES = Range(0.001, 1000.0, 'Hz', form=lambda hz: '/odom:%r' % hz)
_SERIAL = itertools.count()  # the files this process opened: their temporary names never collide
_ENTRY = re.compile(r'(?P<topic>[^\s:]+)(?::(?P<rate>[^\s:]+))?')


def parse_topics(value, name='context_topics', aliases=None, names=None):
    """``{topic: Hz or None}`` from ``'odom:1 amcl_pose /diagnostics'`` (or a list of such entries, or a dict);
    ``aliases`` maps a name to ``(topic, Hz)`` (``BWI_ALIASES``), and ``names`` (a dict, filled) the topic of an
    alias to the alias, the name it is stored under. ValueError('<name>: ...') for a bad entry."""
    aliases = aliases or {}
    if isinstance(value, dict):
        entries = [(topic, rate) for topic, rate in value.items()]
    else:
        entries = []
        for item in topic_list(value, name):
            match = _ENTRY.fullmatch(item)
            if match is None:
                raise ValueError('%s: %r is not a topic or topic:Hz' % (name, item))
            entries.append((match.group('topic'), match.group('rate')))
    rates = {}
    for topic, rate in entries:
        if rate is None and topic in aliases:
            alias, (topic, rate) = topic, aliases[topic]
            if names is not None:
                names[topic] = alias
        rates[topic] = _rate(rate, '%s: %s' % (name, topic))
    return rates


def _rate(value, name):
    if value is None or value == '':
        return None
    try:
        rate = float(str(value).lower().replace('hz', ''))
    except ValueError:
        rate = float('nan')
    if not math.isfinite(rate):
        raise ValueError('%s: rate %r is not a number of Hz' % (name, value))
    return RATES.check(rate, value, name)


def file_name(stamp, prefix=log_format.PREFIX):
    """``cc_log_context_<UTC of stamp>`` (no extension; ``prefix``: ``log_format.file_prefix``'s, for ``cc_log_``)."""
    moment = datetime.datetime(1970, 1, 1) + datetime.timedelta(seconds=float(stamp))
    return prefix + log_format.CONTEXT_MARK + moment.strftime('%Y%m%dT%H%M%S.') + '%03dZ' % (moment.microsecond // 1000)


class _OpenBag(object):
    """One context file being written: a rosbag on ``<final>.tmp-<pid>.<n>``; ``finish`` closes it (rosbag writes
    its index), fsyncs it and gives it the first free final name; a retried finish is safe (after a close that
    failed half-way, what reached the disk is salvaged by ``recovery``); ``discard`` removes it. A file that cannot
    be opened is removed at once."""

    def __init__(self, directory, first_stamp, prefix=log_format.PREFIX, chunk_bytes=None):
        import rosbag
        safe_files.make_dirs(directory)
        self.directory = directory
        self.base = file_name(first_stamp, prefix)
        self.prefix = prefix
        self.first = first_stamp
        name = '%s%s%s%d.%d' % (self.base, EXTENSION, safe_files.TMP_MARK, os.getpid(), next(_SERIAL))
        self.tmp = safe_files.inside(directory, name, 'context')
        self.bag = self._sync_fd = self.path = self._close_error = None
        self.messages = 0
        fd = safe_files.create(self.tmp)
        try:
            self._sync_fd = os.dup(fd)
            stream = os.fdopen(fd, 'w+b')
        except BaseException:
            os.close(fd)
            self.discard()
            raise
        try:
            self.bag = rosbag.Bag(stream, 'w', compression=rosbag.Compression.LZ4,
                                  chunk_threshold=chunk_bytes or bag_writer.CHUNK_THRESHOLD)
        except BaseException:
            _quietly(stream.close)
            self.discard()
            raise

    def write(self, record, time):
        bag_lz4.write_record(self.bag, record, time)
        self.messages += 1

    def finish(self):
        """Close, fsync and name the file; its final path."""
        if self.path is not None:
            return self.path
        if self._close_error is not None:  # rosbag cannot close twice: what reached the disk is salvaged
            outcome = recovery.recover(self.tmp, self.prefix)
            if not outcome.path:
                raise RuntimeError('%s: closing failed (%s), %d messages lost: %s'
                                   % (self.tmp, self._close_error, self.messages, outcome.detail))
            self.path = outcome.path
            return self.path
        if self.bag is not None:
            bag, self.bag = self.bag, None
            try:
                bag.close()
            except Exception as error:  # rosbag cannot close twice: what reached the disk is for recovery
                self._close_error = str(error) or type(error).__name__
                self._release()
                raise
        if self._sync_fd is not None:
            os.fsync(self._sync_fd)
            self._release()
        self.path = safe_files.publish(self.tmp, log_format.final_names(self.directory, self.base, EXTENSION))
        safe_files.fsync_directory(self.directory)
        return self.path

    def discard(self):
        """Close without keeping anything and remove the temporary file (a file no message reached)."""
        if self.bag is not None:
            bag, self.bag = self.bag, None
            _quietly(bag.close)
        self._release()
        try:
            os.unlink(self.tmp)
        except FileNotFoundError:
            pass

    def _release(self):
        if self._sync_fd is not None:
            fd, self._sync_fd = self._sync_fd, None
            os.close(fd)


def _quietly(close):
    """Call ``close()``; its failure (the disk is full) does not matter: what it would write is given up."""
    try:
        close()
    except Exception:
        pass


class ContextTrack(object):
    """The context track of one logging directory (see the module docstring). Thread-safe."""

    def __init__(self, directory, rates, rotate=DEFAULT_ROTATE, submit=None, retry=RETRY_PERIOD, clock=time.monotonic,
                 names=None, prefix=log_format.PREFIX, chunk_bytes=None):
        self.directory = os.path.join(str(directory), SUBDIRECTORY)
        self.prefix = prefix  # of the file names (``log_format.file_prefix``)
        self.chunk_bytes = chunk_bytes  # of the bags' LZ4 chunks, uncompressed (None: rosbag's 768 KB)
        self.rates = dict(rates)
        self.names = dict(names or {})  # topic -> the name it is stored under (BWI's odom_1hz), when not its own
        self.rotate = seconds(rotate, 'context_rotate', positive=True)
        self.retry = seconds(retry, 'context_retry', positive=True)
        self._clock = clock
        self._retry_at = None  # clock before which no file is opened again after a failed write
        self._submit = submit
        self._lock = threading.Lock()
        self._slots = {}
        self._bag = None
        self._last = {}  # topic -> its last stamp written (topics may run on different clocks)
        self.counts = {'messages_kept': 0, 'messages_thinned': 0, 'messages_lost': 0, 'files_closed': 0,
                       'write_errors': 0}
        self.last_error = ''
        self.last_file = ''

    @property
    def topics(self):
        """The topics the track records."""
        return sorted(self.rates)

    def wants(self, record):
        """Whether ``record`` is kept (its topic is tracked and its rate slot is new); notes the slot."""
        if record.topic not in self.rates:
            return False
        rate = self.rates[record.topic]
        if rate is None:
            return True
        slot = math.floor(record.stamp * rate)
        if self._slots.get(record.topic) == slot:
            self.counts['messages_thinned'] += 1
            return False
        self._slots[record.topic] = slot
        return True

    def on_message(self, topic, msg, stamp=None, size=None, raw=None, connection=None):
        """The intake's sink interface: ``add`` a Record of the message (stamp: its header stamp, else ``stamp``)."""
        if topic not in self.rates:
            return False
        stamp = features_mod.stamp_of(msg, 0.0 if stamp is None else stamp)
        return self.add(Record(stamp, topic, msg, 0, raw, connection))

    def on_raw(self, topic, raw, connection, stamp=None):
        """The intake's sink interface for serialized messages (``SmartLogger.on_raw``'s): written as bytes."""
        if topic not in self.rates:
            return False
        stamp = raw_message.stamp(raw, connection, 0.0 if stamp is None else stamp)
        return self.add(Record(stamp, topic, None, 0, raw, connection))

    def add(self, record):
        """Write ``record`` when the track wants it; True when written."""
        with self._lock:
            if not self.wants(record):
                return False
            if not math.isfinite(record.stamp) or record.stamp < 0:
                self._failed('%s: stamp %r cannot be a bag time' % (record.topic, record.stamp))
                self.counts['messages_lost'] += 1
                return False
            if self._retry_at is not None and self._clock() < self._retry_at:
                self.counts['messages_lost'] += 1  # backing off after a failed write (the disk is full)
                return False
            import genpy
            time = genpy.Time.from_sec(record.stamp)
            bag = self._bag
            if bag is not None and (record.stamp - bag.first >= self.rotate or
                                    record.stamp < self._last.get(record.topic, record.stamp) - JUMP_BACK):
                self._close_locked()
            try:
                if self._bag is None:
                    self._bag = _OpenBag(self.directory, record.stamp, self.prefix, self.chunk_bytes)
                self._bag.write(record._replace(topic=self.names[record.topic]) if record.topic in self.names
                                else record, time)
            except Exception as error:  # OSError (disk full), rosbag's, a bad message: the track goes on
                self._failed('%s: %s' % (record.topic, error or type(error).__name__))
                self.counts['messages_lost'] += 1
                self._retry_at = self._clock() + self.retry
                self._close_locked()
                return False
            self._retry_at = None
            self._last[record.topic] = record.stamp
            self.counts['messages_kept'] += 1
            return True

    def close(self):
        """Close the open file (it is handed to ``submit``, or finished here)."""
        with self._lock:
            self._close_locked()

    def stats(self):
        """Counters: messages_kept, messages_thinned, messages_lost (wanted, not written), files_closed,
        write_errors; last_error, last_file."""
        with self._lock:
            result = dict(self.counts)
            result.update(last_error=self.last_error, last_file=self.last_file)
        return result

    def _failed(self, error):
        self.counts['write_errors'] += 1
        self.last_error = error

    def _close_locked(self):
        bag, self._bag = self._bag, None
        if bag is None:
            return
        if not bag.messages:  # nothing written (the first write failed): no file worth keeping
            bag.discard()
            return
        self.counts['files_closed'] += 1

        def finish():
            path = bag.finish()
            self.last_file = path
            return path
        if self._submit is not None:
            self._submit(window_writer.Job(write=finish, what=window_writer.CONTEXT, tag=bag.base))
            return
        try:
            finish()
        except Exception as error:
            self._failed('closing %s: %s' % (bag.tmp, error))


class Tee(object):
    """A sink feeding every message to each of ``sinks`` (``on_message(topic, msg, stamp, size)``) in order."""

    def __init__(self, *sinks):
        self.sinks = [sink for sink in sinks if sink is not None]

    def _each(self, name, *arguments):
        """Call ``name`` on every sink; the first exception is raised after all were fed."""
        failure = None
        for sink in self.sinks:
            try:
                getattr(sink, name)(*arguments)
            except Exception as error:
                failure = failure or error
        if failure is not None:
            raise failure

    def on_message(self, topic, msg, stamp=None, size=None):
        """Feed the message to every sink."""
        self._each('on_message', topic, msg, stamp, size)


class RawTee(Tee):
    """A Tee of sinks that all take serialized messages (``on_raw``): the intake hands them bytes."""

    def on_raw(self, topic, raw, connection, stamp=None):
        """Feed the serialized message to every sink."""
        self._each('on_raw', topic, raw, connection, stamp)


def tee(*sinks):
    """A RawTee when every sink takes serialized messages, else a Tee."""
    sinks = [sink for sink in sinks if sink is not None]
    return (RawTee if all(hasattr(sink, 'on_raw') for sink in sinks) else Tee)(*sinks)


def recover(directory, prefix=log_format.PREFIX):
    """Recover the crash leftovers of the context track in ``<directory>/context`` (``*.bag.tmp-<pid>[.<n>]`` of
    a dead process) through ``recovery`` (``formats.bag_salvage``: every message of every complete chunk, and
    of a chunk cut off mid-write, into ``<name>_recovered.bag``; one that holds no message is removed); returns
    ``(recovered paths, [(path, why)] kept)``."""
    recovered, kept = [], []
    for outcome in recovery.recover_directory(os.path.join(str(directory), SUBDIRECTORY), prefix):
        if outcome.path and outcome.status != recovery.DUPLICATE:
            recovered.append(outcome.path)
        if outcome.status == recovery.UNRECOVERABLE or outcome.lost_bytes:
            kept.append((outcome.kept or outcome.leftover, outcome.detail))
    return recovered, kept
