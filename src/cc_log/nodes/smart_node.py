"""The smart logger node (``rosrun cc_log smart_logger.py``): keep only the data around anomalies.

Node name: ``smart_logger``.

Subscribed topics
  ``odom`` (nav_msgs/Odometry): the driving topic the classifier watches (relative: remap it; an envelope file
  as ``~model`` watches the topic it was learned on, remapped the same way); the topics of
  the model's other inputs by their role names (``cmd_vel`` for a command model; ``imu`` is the driving
  topic of an imu model), or those of the configuration's triggers.
  every topic in ``~topics`` (any type): saved in the windows whose time span holds them; of a latched topic
  (``/tf_static``, a map) the newest message before a window's start is also written at the start of it.

Published topics
  ``~anomalies`` (cc_log/AnomalyEvent): when a window opens, is written, or fails to be written.
  ``/diagnostics`` (diagnostic_msgs/DiagnosticArray): windows, messages seen/kept/not kept (outside every
  window), raw vs stored bytes, classifier latency, queues, free disk, each topic's rate (``rate <topic> Hz``);
  WARN while paused, when the driving topic is silent for 5 s (naming the topics that carry its type), when a
  topic named in ``~topics``, ``keep`` or routes has had no message 5 s after start (naming the published topics
  that look like it: ``health.NamedWatch``) and when
  a message that belonged in a window is not on disk (dropped because the writer fell behind, per topic;
  trimmed to stay within ``~max_buffer_mb``, side messages after an open window's end too while the driving topic
  is silent; intake queue full: ``health``), messages restamped (header stamp
  off the clock), each classifier's and envelope trigger's drift (WARN when it flags far more of the driving
  than of its training data, with the remedies: ``drift.DriftMonitor``), the windows the keep budget
  ``~max_windows_per_hour`` skipped (WARN once it skips: the robot's normal may have drifted), every
  ``~diagnostic_period`` seconds (wall time).

Services
  ``~trigger`` (std_srvs/Trigger): save a window around the newest odometry message now.
  ``~trigger_window`` (cc_log/TriggerWindow): the same with a reason and, optionally, the seconds before and
  after to keep.
  ``~enable`` (std_srvs/SetBool): resume (true) or pause (false) logging.

Parameters
  every option with a ``smart`` node parameter in docs/OPTIONS.md (declared in ``cc_log.logger.options``; ``--help``
  lists them with their defaults): ``~config`` (the configuration file: topics, triggers, windows, format,
  limits; the parameters override its keys), ``~model`` and the classifier's ``~retrigger``, ``~classify_every``,
  ``~recent``, ``~learn_online``, the envelope trigger's ``~on_drift``, the windows' ``~pre``, ``~post``,
  ``~max_window``, ``~topic_limits``, the memory budget ``~max_buffer_mb``, the disk's ``~max_disk_mb``,
  ``~max_files`` and ``~min_free_mb``, ``~directory`` and ``~name_prefix`` (files
  ``<name_prefix>_<UTC>_<reason>``), the intake's bounds, ``~tcp_nodelay`` and ``~fast_receive``, the context
  track and the upload command. Each resolved value is logged once (``~quiet``:
  warnings and errors only).

Every parameter is type-checked: a wrong type or value prints one line ``/smart_logger: ~<name>: ...`` and
the node exits 1. A ``~directory`` that cannot be used falls back (see above) with WARN on /diagnostics.

On start, leftovers of a crash in ``~directory`` (``cc_log_*.tmp-*``) are recovered into window files or,
when they cannot be, reported (logwarn and /diagnostics) and left in place: never deleted silently. A write
that fails (disk full, directory not writable) is reported (ERROR on /diagnostics, a FAILED event) and the
window is kept in memory and retried every few seconds (``window_writer``); when space is short the quota
makes room first. At shutdown held windows are retried for ``CLOSE_RETRY`` seconds.

Subscriber callbacks only put the message on an intake queue (``intake``); one feeder thread hands the
messages, as their serialized bytes and connection headers, to the triggers and the window buffer in batches
of up to half a second (``SmartLogger.on_records``: decoded only where a field is read; a manual trigger first
waits for the messages received before it), whose writer thread decodes (json-xz), compresses and writes.
Stamps are header stamps (receipt time for messages without one; the driving topic's set the clock, and a
message of another topic stamped more than 5 s off it is placed at its arrival), so ``use_sim_time`` (the
intake hands nothing over before the first /clock) and ``rosbag play --clock`` work, and time jumping
backwards (a bag played again) restarts the buffer instead of failing; the silence ticker runs on wall time.
"""
import math
import sys
import threading
import time

import rospy
from std_srvs.srv import SetBool, SetBoolResponse, Trigger, TriggerResponse

from cc_log.base import event_kinds, raw_message, routes
from cc_log.learning import drift
from cc_log.logger import health, smart, smart_events, trigger_topics
from cc_log.nodes import intake
from cc_log.storage import window_info
from cc_log.storage.formats import json_xz
from cc_log.learning.model import AnomalyModel
from cc_log.base.safe_input import printable
from cc_log.nodes.node_common import (
    CLOSE_RETRY, CLOSE_TIMEOUT, ConfigError, Diagnostics, Params, fail, format_options, init_node,
    named_subscribed, node_config, node_name, recover_leftovers, resolve_directory, TopicSilenceWatch, writer_status)
from cc_log.nodes.node_extras import NodeExtras, context_rates
from cc_log.storage.log_format import file_prefix
from cc_log.triggers import ClassifierTrigger

NODE_NAME = 'smart_logger'
OPTIONS_NODE = 'smart'  # its parameters in logger.options
TICK_PERIOD = 0.5                    # seconds (ROS time) between ticks for the triggers that watch for silence


def time_of(stamp):
    """rospy.Time of float seconds (zero for None or NaN)."""
    if stamp is None or not math.isfinite(stamp) or stamp < 0:
        return rospy.Time()
    return rospy.Time.from_sec(stamp)


# -- the node ------------------------------------------------------------------------------------------

class SmartNode(object):
    """Parameters, subscribers, publishers, services and diagnostics around a SmartLogger."""

    def __init__(self):
        from cc_log.msg import AnomalyEvent  # generated message and service: only in a built workspace
        from cc_log.srv import TriggerWindow
        self._event_class = AnomalyEvent
        params = Params()
        for warning in params.unknown():  # a typo in a parameter's name: said, not silently ignored
            rospy.logwarn(warning)

        def given(name):
            """The parameter ``name`` when it is set, else None (the configuration's value holds)."""
            return params.option(name) if params.given(name) else None
        cfg = node_config(params, params.configuration('smart'), dict(
            (name, given(name)) for name in ('model', 'retrigger', 'classify_every', 'recent', 'learn_online',
                                             'on_drift')))
        if not cfg.triggers:
            raise ConfigError('~model: required (the envelope file of cclog learn-envelope, or the model file written '
                              'by learn mode), or triggers in ~config')
        try:
            triggers = cfg.build_triggers(AnomalyModel.load, raw_message.installed_class, rospy.resolve_name)
            options = cfg.logger_options(triggers, rospy.resolve_name)
            options['format_options'] = format_options(params, cfg)
        except ValueError as error:
            raise ConfigError(str(error))
        classifiers = [t for t in triggers if isinstance(t, ClassifierTrigger)]
        window = given('window')
        named = [t for t in classifiers if t.name == 'classifier']
        if window is not None and named and window != named[0].config.span:
            raise ConfigError('~window: %s does not match the model\'s window %s (the window is part of '
                              'the model; leave ~window unset)' % (window, named[0].config.window))
        self.model = classifiers[0].model if classifiers else None
        for trigger in triggers:
            rospy.loginfo('trigger %s: %s', trigger.name, trigger.describe())
        self.directory, self.directory_warning = resolve_directory(params.text('directory', ''))
        prefix = file_prefix(params.option('name_prefix'))
        self.leftovers = recover_leftovers(self.directory, prefix=prefix)
        enabled = params.option('enabled')
        period = params.option('diagnostic_period')
        intake_max_messages = params.option('intake_max_messages')
        intake_max_mb = params.option('intake_max_mb')
        context = context_rates(params, options['driving_topic'])  # the context track's topics ...
        if options['side_topics'] is not None:  # ... at their full rate in the windows too
            options['side_topics'] = sorted(set(options['side_topics']).union(context[0]) - {options['driving_topic']})
        try:
            self.logger = smart.SmartLogger(None, self.directory, enabled=enabled, close_retry=CLOSE_RETRY,
                                            prefix=prefix, **options)
        except ValueError as error:
            raise ConfigError('~%s' % error)
        types = trigger_topics.topic_types(triggers)
        if self.logger.driving_topic in types and raw_message.installed_class(types[self.logger.driving_topic]) is None:
            raise ConfigError('~model: message type %s is not installed' % types[self.logger.driving_topic])
        self._refused = 0
        self._last_trigger = 'none'
        self.events = rospy.Publisher('~anomalies', AnomalyEvent, queue_size=100)
        self.logger.on_event(self._publish_event)
        # the live flag rate against the trained one, of each classifier and envelope trigger
        self.drift = drift.monitor_classifiers(classifiers) + drift.monitor_envelopes(triggers)
        self.learners = [(t.name, t.learner) for t in classifiers if t.learner is not None]
        if self.learners:
            self.logger.on_event(self._flag_learners)
        self.extras = NodeExtras(params, self.logger.writer, self.directory, self.logger.driving_topic, context)
        self.intake = intake.Intake(self.extras.sink(self.logger), self.logger.driving_topic,
                                    sorted(set(self.logger.side_topics or cfg.named_topics()).union(
                                        types, self.extras.topics) - {self.logger.driving_topic}),
                                    max_messages=intake_max_messages, max_bytes=int(intake_max_mb * 1000 ** 2),
                                    on_new_topic=self._advise_format,
                                    tcp_nodelay=params.option('tcp_nodelay'),
                                    fast_receive=params.option('fast_receive'))
        self.extras.watch(cfg.selection, self.intake, self.intake.side_topics + [self.intake.driving_topic])
        self.services = [rospy.Service('~trigger', Trigger, self._trigger),
                         rospy.Service('~trigger_window', TriggerWindow, self._trigger_window),
                         rospy.Service('~enable', SetBool, self._enable)]
        self._ticker = WallTicker(TICK_PERIOD, self._tick)
        driving = self.intake.driving_topic
        self.silence = TopicSilenceWatch(driving, types.get(self.logger.driving_topic), self.intake.counts,
                                         named_subscribed(cfg, self.intake.side_topics), types)
        self.diagnostics = Diagnostics('cc_log: %s' % rospy.get_name().lstrip('/'), period, self._status,
                                       self.intake.counts, self.intake.sizes)
        rospy.loginfo('watching %s; keeping %s; %s', self.intake.driving_topic,
                      ', '.join(self.intake.side_topics) or 'no other topics',
                      'enabled' if enabled else 'disabled until ~enable')

    def _publish_event(self, event):
        if event.kind == event_kinds.DELETED:
            rospy.logwarn('window file %s: %s', event.error, event.path)
            return
        if event.kind == event_kinds.SPLIT:
            rospy.loginfo('window file closed at ~split_mb: %s (%d bytes); the window goes on in the next',
                          event.path, event.bytes)
            return
        reason = smart_events.reason_text(event)
        msg = self._event_class(event=event.kind, trigger=event.trigger, reason=reason, score=event.score,
                                threshold=event.threshold, start=time_of(event.start), end=time_of(event.end),
                                messages=event.messages, path=event.path, bytes=event.bytes)
        msg.header.stamp = time_of(event.stamp)
        if event.kind == event_kinds.WRITTEN:
            rospy.loginfo('window written: %s (%d messages, %d bytes)', event.path, event.messages, event.bytes)
        elif event.kind == event_kinds.FAILED:
            rospy.logerr('window of %d messages not written: %s', event.messages, event.error)
        else:
            rospy.loginfo('window opened (%s: %s, score %.4g)', printable(event.trigger), reason, event.score)
            self._last_trigger = '%s: %s at %s' % (printable(event.trigger), printable(event.reason),
                                                   window_info.utc_text(event.stamp))
        try:
            self.events.publish(msg)
        except rospy.ROSException:  # shutting down
            pass

    def _advise_format(self, topic, msg_type):
        """At a topic's first message: WARN once when it is written as json-xz and its type is heavy."""
        written_as = routes.format_of(topic, self.logger.routes, self.logger.format)
        advice = json_xz.heavy_topic_advice(topic, msg_type, written_as)
        if advice:
            rospy.logwarn(advice)

    def _flag_learners(self, event):
        """Online learning: nothing from around a window any trigger opened is learned."""
        if event.kind == event_kinds.OPENED:
            for name, learner in self.learners:
                learner.flag(event.stamp, own=event.trigger == name)

    def _trigger(self, request):
        self.intake.sync()  # the messages received before the call are fed: the window is around the newest
        ok, message = self.logger.trigger_now('manual')
        return TriggerResponse(success=ok, message=message)

    def _trigger_window(self, request):
        self.intake.sync()
        ok, message = self.logger.trigger_now(request.reason, request.before, request.after)
        return ok, message

    def _tick(self):
        """Message time passes even when no message comes: triggers watching for silence hear of it."""
        try:
            self.logger.tick(rospy.get_rostime().to_sec())
        except Exception as error:  # the timer thread must go on
            rospy.logerr_throttle(10.0, 'tick: %s: %s' % (type(error).__name__, error))

    def _enable(self, request):
        self.logger.set_enabled(request.data)
        state = 'enabled' if request.data else 'disabled'
        rospy.loginfo('smart logger %s', state)
        return SetBoolResponse(success=True, message=state)

    def _status(self):
        stats = self.logger.stats()
        if stats['messages_refused'] > self._refused:
            self._refused = stats['messages_refused']
            rospy.logwarn_throttle(10.0, stats['last_refused'])
        level, message = health.smart_head(stats)
        level, message, disk = writer_status(level, message, self.logger.writer, self.leftovers,
                                             self.directory_warning)
        level, message, extra = self.extras.status(level, message)
        level, message = self.silence.status(level, message)
        overflowed = self.intake.overflowed
        drifting = [(health.WARN, text) for drift_level, text in (monitor.status() for monitor in self.drift)
                    if drift_level]
        level, message = health.worst(level, message, health.not_kept(stats, overflowed) + drifting
                                      + health.skipped(stats))
        raw, stored = stats['raw_json_bytes'], stats['stored_bytes']
        values = [
            ('enabled', stats['enabled']),
            ('windows opened', stats['windows_opened']),
            ('windows saved', stats['windows_saved']),
            ('windows skipped (keep budget)', health.skipped_value(stats)),
            ('last trigger', self._last_trigger),
            ('messages seen', stats['messages_seen']),
            ('messages kept', stats['messages_kept']),
            ('messages not kept (outside every window)', stats['messages_not_kept']),
            ('messages buffered', stats['messages_buffered']),
            ('buffered bytes (estimated)', stats['buffered_bytes']),
            ('max buffer bytes', self.logger.buffer_budget or 'no budget'),
            ('messages trimmed (buffer budget)', stats['buffer_trimmed']),
            ('messages trimmed (topic limits)', stats['topic_trimmed']),
            ("messages trimmed (after an open window's end)", stats['buffer_trimmed_silent']),
            ('messages lost', stats['messages_lost'] + self.intake.dropped),
            ('raw JSON bytes', raw),
            ('stored bytes', stored),
            ('stored / raw', '%.4f' % (float(stored) / raw) if raw else 'n/a'),
            ('classifier mean us', '%.1f' % stats['classifier_mean_us']),
            ('classifier max us', '%.1f' % stats['classifier_max_us']),
            ('classifier CPU s', '%.3f' % (stats['classifier_mean_us'] * stats['classifier_calls'] * 1e-6)),
            ('feeder CPU s', '%.3f' % self.intake.cpu_seconds),
            ('writer CPU s', '%.3f' % self.logger.writer.cpu_seconds),
            ('anomalous messages', stats['anomalous_messages']),
            ('writer queue', stats['queue_depth']),
            ('writer queue bytes', stats['bytes_queued']),
            ('messages dropped (writer behind)', stats['messages_shed']),
            ('dropped per topic (writer behind)', health.per_topic(stats['shed_by_topic'])),
            ('messages restamped (header stamp off the clock)', stats['messages_restamped']),
            ('restamped per topic', health.per_topic(stats['restamped_by_topic'])),
            ('intake queue', self.intake.queue.qsize()),
            ('intake dropped (queue full)', overflowed),
            ('classify every', str(self.logger.classify_every)),
            ('triggers fired', ', '.join('%s: %d' % (name, counters['fired'])
                                         for name, counters in sorted(stats['triggers'].items()))),
            ('fires dropped (no message yet)', stats['fires_dropped']),
            ('time resets', stats['time_resets']),
            ('messages refused', stats['messages_refused']),
            ('messages refused (unsafe definition)', self.intake.decoder.refused),
        ] + [('drift %s' % monitor.name, monitor.status()[1]) for monitor in self.drift] \
            + extra + disk + self._online_status(stats)
        return level, message, values

    def _online_status(self, stats):
        """Diagnostics of online learning: per classifier that learns, what it has seen and refitted."""
        values = []
        for name, _ in self.learners:
            online = stats['triggers'][name]['online']
            last = online['last_refit']
            values += [('%s: online vectors seen' % name, online['vectors_seen']),
                       ('%s: online vectors learned' % name, online['vectors_learned']),
                       ('%s: online vectors refused (near a flag)' % name, online['vectors_refused']),
                       ('%s: online vectors learned from its own flags (drift)' % name, online['vectors_adapted']),
                       ('%s: online adapting to drift' % name, 'yes' if online['adapting'] else 'no'),
                       ('%s: online refits' % name, online['refits']),
                       ('%s: online resumed' % name, online['resumed'] or 'no'),
                       ('%s: online last refit' % name, time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(last))
                        if last else 'never'),
                       ('%s: online last error' % name, online['last_error'] or 'none')]
        return values

    def shutdown(self):
        """Feed what is queued, write the last windows, stop diagnostics."""
        self._ticker.stop()
        self.silence.stop()
        self.intake.stop()
        if not self.logger.close(CLOSE_TIMEOUT):
            stats = self.logger.stats()
            rospy.logerr('%d windows (%d messages) still unwritten after %g s: lost', stats['windows_queued'],
                         stats['messages_queued'], CLOSE_TIMEOUT)
        stats = self.logger.stats()
        if stats['messages_shed'] or stats['messages_lost']:
            rospy.logwarn('messages of windows not written: %d dropped while the writer fell behind (%s), %d lost '
                          'writing', stats['messages_shed'], health.per_topic(stats['shed_by_topic']),
                          stats['messages_lost'])
        self.extras.close()
        for _, learner in self.learners:  # a refit being saved finishes (the save is atomic either way)
            learner.wait(CLOSE_TIMEOUT)
        self.diagnostics.stop()


class WallTicker(object):
    """Calls ``callback()`` every ``period`` seconds of wall time on a daemon thread until ``stop``: unlike
    rospy.Timer, it lives on when the ROS clock jumps back (a bag played in a loop with ``--clock``)."""

    def __init__(self, period, callback):
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(period, callback), name='cc_log ticker')
        self._thread.daemon = True
        self._thread.start()

    def _run(self, period, callback):
        while not self._stop.wait(period):
            callback()

    def stop(self):
        self._stop.set()
        self._thread.join(1.0)


def main(argv=None):
    """Run the node; return the exit status (1 with one line on stderr for bad configuration)."""
    argv = sys.argv if argv is None else argv
    try:
        init_node(NODE_NAME, argv)
        node = SmartNode()
    except ConfigError as error:
        return fail(node_name(NODE_NAME, argv), error)
    rospy.spin()
    node.shutdown()
    return 0
