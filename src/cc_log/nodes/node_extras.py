"""The context track and the upload hook of a node (smart or collect): parameters, writer, sink, status.

Parameters (private, both nodes)
  ``~context_topics`` (list or space-separated string, default: none = no context track): topics recorded
  always, each ``topic`` or ``topic:Hz`` (``odom:1 amcl_pose /diagnostics``; BWI's ``odom_1hz`` means the
  driving topic ``odom`` at 1 Hz), into ``<directory>/context/`` (see ``context_track``).
  ``~context_rotate`` (double, default: 600): seconds of stamps per context file.
  ``~upload_command`` (list or string, default: none): run detached with the path of each closed window or
  context file (see ``upload``: at most ``upload.MAX_RUNNING`` at a time, the others queued); uploads running,
  queued, failed and dropped (queue full) are on /diagnostics, failures and drops as a WARN.

The context files have a writer of their own (closing, fsync, naming, retries) whose disk guard and the
node's count the window and context files together: ``~max_disk_mb`` and ``~max_files`` hold for both, oldest
deleted first.
"""
import math
import os

import rospy
from diagnostic_msgs.msg import DiagnosticStatus

from cc_log.base import event_kinds, raw_message
from cc_log.features.base import stamp_of
from cc_log.storage import context_track, disk_guard, upload, window_writer
from cc_log.nodes.node_common import ConfigError
from cc_log.nodes.topic_watch import TopicWatcher

__all__ = ['NodeExtras', 'context_rates', 'Thinned']


def context_rates(params, driving_topic):
    """``({topic: Hz or None}, {topic: name stored under})`` of ``~context_topics``, topics resolved; BWI's
    ``odom_1hz`` is ``driving_topic`` at 1 Hz, stored and republished under the resolved ``odom_1hz``."""
    names = {}
    try:
        rates = context_track.parse_topics(params.value('context_topics', ''), '~context_topics',
                                           {'odom_1hz': (driving_topic, 1.0)}, names)
    except ValueError as error:
        raise ConfigError(str(error))
    return (dict((rospy.resolve_name(topic), rate) for topic, rate in rates.items()),
            dict((rospy.resolve_name(topic), rospy.resolve_name(name)) for topic, name in names.items()))


class Thinned(object):
    """A sink that republishes ``source`` at most ``rate`` times a second of its stamps on ``topic`` (BWI's live
    ``odom_1hz``), decoded with the class its connection names."""

    def __init__(self, source, topic, rate):
        self.source, self.topic, self.rate = source, topic, rate
        self.publisher = None
        self._slot = None

    def on_raw(self, topic, raw, connection, stamp=None):
        """Republish the message when it is the first of its slot."""
        return topic == self.source and self._offer(raw_message.stamp(raw, connection, 0.0 if stamp is None else stamp),
                                                    lambda: raw_message.decode(raw, connection))

    def on_message(self, topic, msg, stamp=None, size=None):
        """The same for a decoded message: its slot by its header stamp (``stamp``, the receipt, without one)."""
        return topic == self.source and self._offer(stamp_of(msg, 0.0 if stamp is None else stamp), lambda: msg)

    def _offer(self, stamp, message):
        slot = math.floor(stamp * self.rate)
        if slot == self._slot:
            return False
        self._slot = slot
        msg = message()
        if self.publisher is None:
            self.publisher = rospy.Publisher(self.topic, type(msg), queue_size=10)
        self.publisher.publish(msg)
        return True


CLOSE_TIMEOUT = 3.0  # seconds the context track may take to close at shutdown, after the windows' 10 s


class NodeExtras(object):
    """The context track and upload hook around a node's ``writer`` (its WindowWriter) in ``directory``."""

    def __init__(self, params, writer, directory, driving_topic, context=None):
        self.rates, names = context or context_rates(params, driving_topic)  # (``context``: read already)
        try:
            self.hook = upload.UploadHook(params.value('upload_command', ''))
        except ValueError as error:
            raise ConfigError(str(error))
        self.republisher = Thinned(driving_topic, names[driving_topic], 1.0) if driving_topic in names else None
        rotate = params.option('context_rotate')
        self.track = self.writer = self.watcher = None
        self.leftovers = []
        if self.rates:
            recovered, self.leftovers = context_track.recover(directory, writer.prefix)
            for path in recovered:
                rospy.logwarn('context track: crash leftover recovered as %s', path)
            for path, why in self.leftovers:
                rospy.logwarn('context track: crash leftover NOT recovered, kept: %s: %s', path, why)
            folder = os.path.join(directory, context_track.SUBDIRECTORY)
            guard = writer.guard
            self.writer = window_writer.WindowWriter(
                folder, max_disk_mb=guard.max_bytes / float(disk_guard.MB),
                min_free_mb=guard.min_free_bytes / float(disk_guard.MB), close_retry=writer.close_retry,
                name='cc_log context writer', max_files=guard.max_files, prefix=writer.prefix)
            self.writer.guard.share(guard)
            self.writer.on_event(self._context_event)
            self.track = context_track.ContextTrack(directory, self.rates, rotate, submit=self.writer.submit,
                                                    names=names, prefix=writer.prefix,
                                                    chunk_bytes=params.option('chunk_kb') * 1024)
            rospy.loginfo('context track: %s into %s', ', '.join(
                '%s%s' % (topic, ' at %g Hz' % rate if rate else '') for topic, rate in sorted(self.rates.items())),
                folder)
        if self.hook.enabled:
            writer.on_event(self.hook.on_event)
            if self.writer is not None:
                self.writer.on_event(self.hook.on_event)
            rospy.loginfo('upload command: %s', ' '.join(self.hook.command))

    def watch(self, selection, intake, skip):
        """With ``~topics`` patterns (``*``, ``re:...``): subscribe to matching topics as they appear, through
        ``intake.subscribe`` (``skip``: topics subscribed already)."""
        if not selection.dynamic:
            return
        if not hasattr(intake, 'subscribe'):
            raise ConfigError('~topics: %s: topics that appear later need an intake that subscribes at run time '
                              '(intake.subscribe)' % selection.describe())
        rospy.loginfo('topics: %s (subscribed as they appear)', selection.describe())
        self.watcher = TopicWatcher(selection, intake.subscribe, skip=skip).start()

    @property
    def topics(self):
        """The context topics (resolved)."""
        return sorted(self.rates)

    def sink(self, main):
        """The intake's sink: ``main``, the context track and the ``odom_1hz`` topic."""
        if self.track is None and self.republisher is None:
            return main
        return context_track.tee(main, self.track, self.republisher)

    def _context_event(self, event):
        if event.kind == event_kinds.WRITTEN:
            rospy.loginfo('context file closed: %s', event.path)
        elif event.kind == event_kinds.FAILED:
            rospy.logerr('context file not closed: %s', event.error)
        else:
            rospy.logwarn('file deleted (%s): %s', event.error, event.path)

    def status(self, level, message):
        """``(level, message, values)``: the node's level and message with the context track's and the upload
        hook's problems added, and their diagnostic values."""
        values = []
        if self.track is not None:
            stats, written = self.track.stats(), self.writer.stats()
            values += [('context topics', ' '.join(self.topics)),
                       ('context messages kept', stats['messages_kept']),
                       ('context messages lost', stats['messages_lost']),
                       ('context files', written['written'].get(window_writer.CONTEXT, 0)),
                       ('context write errors', stats['write_errors'] + written['write_errors'])]
            if stats['write_errors'] or written['jobs_lost'] or written['jobs_held']:
                level = max(level, DiagnosticStatus.WARN)
                message += '; context track: %s' % (written['last_error'] or stats['last_error'])
            if self.leftovers:
                level = max(level, DiagnosticStatus.WARN)
                message += '; %d context leftovers kept (not recovered)' % len(self.leftovers)
        if self.watcher is not None:
            values += [('topics discovered', len(self.watcher.added)), ('topic watch errors', self.watcher.errors)]
            if self.watcher.errors:
                level = max(level, DiagnosticStatus.WARN)
                message += '; topic watch: %s' % self.watcher.last_error
        if self.hook.enabled:
            stats = self.hook.stats()
            values += [('uploads started', stats['started']), ('uploads running', stats['running']),
                       ('uploads queued', stats['queued']), ('uploads failed', stats['failed']),
                       ('uploads dropped', stats['dropped']), ('last upload error', stats['last_error'] or 'none')]
            if stats['failed'] or stats['dropped']:
                level = max(level, DiagnosticStatus.WARN)
                message += '; %d uploads failed, %d dropped (last: %s)' % (
                    stats['failed'], stats['dropped'], stats['last_error'])
        return level, message, values

    def close(self):
        """Stop watching for topics, close the open context file and wait for its writer."""
        if self.watcher is not None:
            self.watcher.stop()
        if self.track is not None:
            self.track.close()
            if not self.writer.close(CLOSE_TIMEOUT):
                rospy.logerr('context file still unwritten after %g s', CLOSE_TIMEOUT)
