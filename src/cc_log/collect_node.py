"""The collect logger node (``rosrun cc_log collect_logger.py``): log everything for learning.

Node name: ``collect_logger``.

Subscribed topics
  ``odom`` (nav_msgs/Odometry): the driving topic; its feature vectors are written for learn mode.
  every topic in ``~topics`` (any type): logged too.

Published topics
  ``/diagnostics`` (diagnostic_msgs/DiagnosticArray): files and vectors written, messages, raw vs stored
  bytes, queues, free disk, every ``~diagnostic_period`` seconds (wall time).

Parameters (defaults below as module constants; each resolved value is logged once)
  ``~directory`` (string, default: ~/.ros/cc_log, then /tmp/cc_log): window files go here, vectors into
  ``<directory>/features/<label>/``.
  ``~format`` (string, default: json-xz): ``json-xz`` or ``bag-lz4``.
  ``~rotate`` (string, default: 60s): a new file after this many messages (``6000``), seconds (``60s``) or
  raw row-JSON bytes (``20MB``).
  ``~topics`` (list or space-separated string, default: none): other topics to log.
  ``~label`` (string, default: nominal): label of the feature vectors.
  ``~window`` (string, default: 500): feature window, messages or seconds.
  ``~feature_set`` (string, default: motion): ``motion`` or ``raw``.
  ``~stride`` (int, default: 25): a vector every this many odometry messages.
  ``~diagnostic_period`` (double, default: 1.0): seconds between diagnostics; 0 turns them off.

At shutdown the current file is written, so every file is complete.
"""
import sys

import rospy
from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Odometry

from . import collector
from .smart_node import (ConfigError, Diagnostics, Intake, free_disk, fail, param, param_float, param_topics,
                         resolve_directory, DEFAULT_DIAGNOSTIC_PERIOD, DISK_WARN_BYTES, CLOSE_TIMEOUT)

NODE_NAME = 'collect_logger'
DRIVING_TOPIC = 'odom'
DEFAULT_FORMAT = 'json-xz'
DEFAULT_ROTATE = collector.DEFAULT_ROTATE
DEFAULT_LABEL = collector.DEFAULT_LABEL
DEFAULT_WINDOW = collector.DEFAULT_WINDOW
DEFAULT_FEATURE_SET = collector.DEFAULT_FEATURE_SET
DEFAULT_STRIDE = collector.DEFAULT_STRIDE


class CollectNode(object):
    """Parameters, subscribers and diagnostics around a Collector."""

    def __init__(self):
        self.directory = resolve_directory(param('directory', ''))
        fmt = param('format', DEFAULT_FORMAT)
        rotate = param('rotate', DEFAULT_ROTATE)
        topics = param_topics()
        label = param('label', DEFAULT_LABEL)
        window = param('window', DEFAULT_WINDOW)
        feature_set = param('feature_set', DEFAULT_FEATURE_SET)
        stride = param('stride', DEFAULT_STRIDE)
        period = param_float('diagnostic_period', DEFAULT_DIAGNOSTIC_PERIOD)
        try:
            self.collector = collector.Collector(
                self.directory, fmt, rotate, driving_topic=rospy.resolve_name(DRIVING_TOPIC),
                side_topics=[rospy.resolve_name(topic) for topic in topics], window=window,
                feature_set=feature_set, stride=stride, label=label)
        except ValueError as error:
            raise ConfigError('~%s' % error)
        self.collector.on_event(self._on_event)
        self.intake = Intake(self.collector, DRIVING_TOPIC, Odometry, topics)
        self.diagnostics = Diagnostics('cc_log: %s' % rospy.get_name().lstrip('/'), period, self._status)
        rospy.loginfo('collecting %s and %s; vectors into %s/%s', self.intake.driving_topic,
                      ', '.join(self.intake.side_topics) or 'no other topics',
                      self.collector.features_directory, label)

    def _on_event(self, kind, detail):
        if kind == 'file':
            rospy.loginfo('wrote %s (%d messages, %d bytes)', detail['path'], detail['messages'], detail['bytes'])
        elif kind == 'failed':
            rospy.logerr('write failed: %s', detail['error'])

    def _status(self):
        stats = self.collector.stats()
        free = free_disk(self.directory)
        level, message = DiagnosticStatus.OK, 'collecting'
        if free is not None and free < DISK_WARN_BYTES:
            level, message = DiagnosticStatus.WARN, 'low disk space: %d MB free' % (free // 1000 ** 2)
        if stats['write_errors']:
            level, message = DiagnosticStatus.ERROR, 'write errors: %s' % stats['last_error']
        raw, stored = stats['raw_json_bytes'], stats['stored_bytes']
        values = [
            ('files written', stats['files_written']),
            ('vectors written', stats['vectors_written']),
            ('messages seen', stats['messages_seen']),
            ('messages kept', stats['messages_kept']),
            ('messages buffered', stats['messages_buffered']),
            ('messages lost', stats['messages_lost'] + self.intake.dropped),
            ('raw JSON bytes', raw),
            ('stored bytes', stored),
            ('stored / raw', '%.4f' % (float(stored) / raw) if raw and stats['messages_kept'] else 'n/a'),
            ('writer queue', stats['queue_depth']),
            ('intake queue', self.intake.queue.qsize()),
            ('write errors', stats['write_errors']),
            ('time resets', stats['time_resets']),
            ('directory', self.directory),
            ('free disk bytes', free if free is not None else 'unknown'),
        ]
        return level, message, values

    def shutdown(self):
        """Feed what is queued, write the current file, stop diagnostics."""
        self.intake.stop()
        if not self.collector.close(CLOSE_TIMEOUT):
            rospy.logerr('files still unwritten after %g s', CLOSE_TIMEOUT)
        self.diagnostics.stop()


def main(argv=None):
    """Run the node; return the exit status (1 with one line on stderr for bad configuration)."""
    rospy.init_node(NODE_NAME, argv=sys.argv if argv is None else argv)
    try:
        node = CollectNode()
    except ConfigError as error:
        return fail(rospy.get_name(), error)
    rospy.spin()
    node.shutdown()
    return 0
