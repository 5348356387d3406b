"""The collect logger node (``rosrun cc_log collect_logger.py``): log everything for learning.

Node name: ``collect_logger``.

Subscribed topics
  ``odom`` (nav_msgs/Odometry): the driving topic; its feature vectors are written for learn mode.
  every topic in ``~topics`` (any type): logged too.

Published topics
  ``/diagnostics`` (diagnostic_msgs/DiagnosticArray): files and vectors written, messages, raw vs stored
  bytes, queues, free disk, write errors and held files, each topic's rate (``rate <topic> Hz``), every
  ``~diagnostic_period`` seconds (wall time); WARN when the driving topic is silent for 5 s, naming the topics
  that carry its type, and when a topic of ``~topics`` has had no message 5 s after start, naming the published
  topics that look like it.

Parameters
  every option with a ``collect`` node parameter in docs/OPTIONS.md (declared in ``cc_log.logger.options``;
  ``--help`` lists them with their defaults): ``~config`` (with classifiers, the vectors of each go to
  ``<directory>/features/<name>/<label>/`` and ``~feature_set``/``~window`` are not used), ``~directory``
  (vectors into ``<directory>/features/<label>/``), ``~format``, ``~rotate``, ``~topics``, ``~label``,
  ``~window``, ``~feature_set`` (its first input is the driving topic, ``odom``; its other inputs are
  subscribed under their role names, e.g. ``cmd_vel``: remap them), ``~stride``, ``~max_buffer_mb`` (a new file
  starts when it is reached), ``~max_disk_mb``, ``~max_files``, ``~min_free_mb``, ``~name_prefix`` (files
  ``<name_prefix>_<UTC>_<reason>``), ``~tcp_nodelay``, ``~fast_receive``, ``~chunk_kb``. Each resolved value is
  logged once (``~quiet``: warnings and errors only).

Every parameter is type-checked (one line ``/collect_logger: ~<name>: ...``, exit 1). On start, crash
leftovers in ``~directory`` are recovered or reported and kept, as the smart node does. Files and vectors
go through the smart node's window writer: a write that fails (disk full...) is reported and kept in memory
and retried; at shutdown the current file is written, so every file is complete.
"""
import os
import sys

import rospy
from diagnostic_msgs.msg import DiagnosticStatus

from cc_log.logger import collector
from cc_log import features
from cc_log.base import event_kinds
from cc_log.storage import log_format, window_writer
from cc_log.learning.model import AnomalyModel
from cc_log.nodes.node_common import (
    CLOSE_RETRY, CLOSE_TIMEOUT, ConfigError, Diagnostics, Params, fail, format_options, init_node,
    named_subscribed, node_config, node_name, recover_leftovers, resolve_directory, TopicSilenceWatch, writer_status)
from cc_log.nodes.intake import Intake
from cc_log.nodes.node_extras import NodeExtras

NODE_NAME = 'collect_logger'
DEFAULT_FORMAT = log_format.formats.DEFAULT
DEFAULT_ROTATE = collector.DEFAULT_ROTATE
DEFAULT_LABEL = collector.DEFAULT_LABEL
DEFAULT_WINDOW = collector.DEFAULT_WINDOW
DEFAULT_FEATURE_SET = collector.DEFAULT_FEATURE_SET
DEFAULT_STRIDE = collector.DEFAULT_STRIDE
OPTIONS_NODE = 'collect'  # its parameters in logger.options


class CollectNode(object):
    """Parameters, subscribers and diagnostics around a Collector."""

    def __init__(self, note=''):
        self.note = note  # why collect mode runs (record.launch without a model): said on /diagnostics
        params = Params()
        for warning in params.unknown():  # a typo in a parameter's name: said, not silently ignored
            rospy.logwarn(warning)
        self.directory, self.directory_warning = resolve_directory(params.text('directory', ''))
        prefix = log_format.file_prefix(params.option('name_prefix'))
        self.leftovers = recover_leftovers(self.directory, os.path.join(self.directory,
                                                                        collector.FEATURES_SUBDIRECTORY), prefix)

        cfg = node_config(params, params.configuration('collect'))
        window = str(params.option('window'))
        feature_set = params.option('feature_set')
        period = params.option('diagnostic_period')
        options = {'side_topics': None if cfg.selection.dynamic else [rospy.resolve_name(t) for t in cfg.topics],
                   'close_retry': CLOSE_RETRY,
                   'label': cfg.label or DEFAULT_LABEL, 'stride': cfg.stride or DEFAULT_STRIDE,
                   'max_buffer_mb': cfg.max_buffer_mb, 'max_disk_mb': cfg.max_disk_mb,
                   'min_free_mb': cfg.min_free_mb, 'format_options': format_options(params, cfg),
                   'max_files': cfg.max_files, 'prefix': prefix}
        try:
            specs = cfg.feature_specs(AnomalyModel.load, rospy.resolve_name)
        except ValueError as error:
            raise ConfigError(str(error))
        if specs:  # the configuration's classifiers: vectors of each into features/<name>/<label>/
            if params.given('feature_set') or params.given('window'):
                rospy.logwarn('~feature_set and ~window are not used: the configuration names its classifiers')
            driving = rospy.resolve_name(cfg.driving_topic) if cfg.driving_topic else None
            options.update(feature_specs=specs, driving_topic=driving)
        else:  # one feature set, its inputs by their role names (odom, imu, cmd_vel): remap them
            inputs = features.get(feature_set).inputs
            options.update(window=window, feature_set=feature_set, driving_topic=rospy.resolve_name(inputs[0][0]),
                           input_topics=[rospy.resolve_name(role) for role, _ in inputs[1:]])
        try:
            self.collector = collector.Collector(self.directory, cfg.format, cfg.rotate or DEFAULT_ROTATE,
                                                 **options)
        except ValueError as error:
            raise ConfigError('~%s' % error)
        label = self.collector.label
        types = dict((spec.topic, spec.config.topic_type) for spec in self.collector.specs)
        topics = sorted(self.collector.side_topics or [rospy.resolve_name(t) for t in cfg.topics])
        self.collector.on_event(self._on_event)
        self.extras = NodeExtras(params, self.collector.writer, self.directory, self.collector.driving_topic)
        self.intake = Intake(self.extras.sink(self.collector), self.collector.driving_topic,
                             sorted(set(topics).union(types, self.extras.topics) - {self.collector.driving_topic}),
                             tcp_nodelay=params.option('tcp_nodelay'),
                             fast_receive=params.option('fast_receive'))
        self.extras.watch(cfg.selection, self.intake, self.intake.side_topics + [self.intake.driving_topic])
        driving = self.intake.driving_topic
        self.silence = TopicSilenceWatch(driving, types.get(self.collector.driving_topic), self.intake.counts,
                                         named_subscribed(cfg, self.intake.side_topics), types)
        self.diagnostics = Diagnostics('cc_log: %s' % rospy.get_name().lstrip('/'), period, self._status,
                                       self.intake.counts, self.intake.sizes)
        rospy.loginfo('collecting %s and %s; vectors into %s/%s', self.intake.driving_topic,
                      ', '.join(self.intake.side_topics) or 'no other topics',
                      self.collector.features_directory, label)

    def _on_event(self, kind, detail):
        if kind == event_kinds.WRITTEN and detail['what'] == window_writer.WINDOW:
            rospy.loginfo('wrote %s (%d messages, %d bytes)', detail['path'], detail['messages'], detail['bytes'])
        elif kind == event_kinds.FAILED:
            rospy.logerr('%s of %d messages not written: %s', detail['what'], detail['messages'], detail['error'])
        elif kind == event_kinds.DELETED:
            rospy.logwarn('window file %s: %s', detail['error'], detail['path'])

    def _status(self):
        stats = self.collector.stats()
        level, message, disk = writer_status(DiagnosticStatus.OK, self.note or 'collecting', self.collector.writer,
                                             self.leftovers, self.directory_warning)
        level, message, extra = self.extras.status(level, message)
        level, message = self.silence.status(level, message)
        raw, stored = stats['raw_json_bytes'], stats['stored_bytes']
        values = [
            ('files written', stats['files_written']),
            ('vectors written', stats['vectors_written']),
            ('messages seen', stats['messages_seen']),
            ('messages kept', stats['messages_kept']),
            ('messages buffered', stats['messages_buffered']),
            ('buffered bytes (estimated)', stats['buffered_bytes']),
            ('messages lost', stats['messages_lost'] + self.intake.dropped),
            ('files lost', stats['files_lost']),
            ('raw JSON bytes', raw),
            ('stored bytes', stored),
            ('stored / raw', '%.4f' % (float(stored) / raw) if raw and stats['messages_kept'] else 'n/a'),
            ('writer queue', stats['queue_depth']),
            ('intake queue', self.intake.queue.qsize()),
            ('time resets', stats['time_resets']),
        ] + extra + disk
        return level, message, values

    def shutdown(self):
        """Feed what is queued, write the current file, stop diagnostics."""
        self.silence.stop()
        self.intake.stop()
        if not self.collector.close(CLOSE_TIMEOUT):
            rospy.logerr('files still unwritten after %g s', CLOSE_TIMEOUT)
        self.extras.close()
        self.diagnostics.stop()


def main(argv=None, note=''):
    """Run the node; return the exit status (1 with one line on stderr for bad configuration). ``note``: why
    collect mode runs, logged and shown as the status message."""
    argv = sys.argv if argv is None else argv
    try:
        init_node(NODE_NAME, argv)
        if note:
            rospy.logwarn(note)
        node = CollectNode(note)
    except ConfigError as error:
        return fail(node_name(NODE_NAME, argv), error)
    rospy.spin()
    node.shutdown()
    return 0
