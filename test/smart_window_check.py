#!/usr/bin/python3
"""Test node of smart_window.test: the live smart logger on a recorded run with a known anomaly.

Before the node starts, a model is trained on the first 40 s of the real Husky bag (with injected
bursts as anomalous examples). The node is started as a real process (rosrun's script) with the driving
topic remapped, then this node publishes the run message by message:

1. a run with one injected burst: exactly one window file appears, holding exactly the published
   odometry from ``pre`` before the first anomalous message to ``post`` after the last, plus exactly the
   IMU messages published in that time span (the IMU is a context topic: recorded always and, at its full
   rate, in the windows, as BWI's amcl_pose and /diagnostics are); AnomalyEvents OPENED and WRITTEN are
   published;
2. ``~trigger``: a manual window of ``pre`` + 1 + ``post`` consecutive published messages;
3. ``~enable`` false: another burst leaves no window; diagnostics count what was seen and WARN while paused.
"""
import copy
import os
import re
import shutil
import sys
import tempfile
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu
from std_srvs.srv import SetBool, Trigger

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rostest_fixtures as fx  # noqa: E402

from cc_log.storage import log_format  # noqa: E402
from cc_log.base import msg_codec  # noqa: E402
from cc_log.msg import AnomalyEvent  # noqa: E402

PKG = 'cc_log'
NODE = 'smart_logger'
PRE = POST = 15
RATE = 300.0  # messages per second (both topics), wall time
RUN = slice(400, 700)        # phase 1: burst at local index 100
TRIGGER = slice(700, 800)    # phase 2: nominal; trigger after 40 messages
DISABLED = slice(800, 1000)  # phase 3: burst at local index 100 while disabled


class SmartWindowTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('smart_window_check')
        cls.tmp = tempfile.mkdtemp(prefix='cc_log_smart_window_')
        cls.out = os.path.join(cls.tmp, 'windows')
        odom, cls.imu = fx.husky()
        cls.odom = odom
        cls.model = fx.train_model(odom)
        cls.model_path = os.path.join(cls.tmp, 'model.json')
        cls.model.save(cls.model_path)
        # one continuous stream: the run with a burst, nominal driving, a second burst
        stream = odom[RUN.start:DISABLED.stop]
        stream = fx.inject(stream, 100)
        stream = fx.inject(stream, DISABLED.start - RUN.start + 100)
        cls.stream = stream
        cls.flags = fx.flagged(cls.model, stream)
        cls.fires = fx.fired(cls.model, stream)
        cls.events, cls.diagnostics = [], []
        rospy.Subscriber('/%s/anomalies' % NODE, AnomalyEvent, cls.events.append, queue_size=None)
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.diagnostics.append, queue_size=None)
        cls.odom_pub = rospy.Publisher('husky_odom', Odometry, queue_size=10000)
        cls.imu_pub = rospy.Publisher('imu', Imu, queue_size=10000)
        cls.node = fx.start('smart_logger.py', '__name:=' + NODE, 'odom:=husky_odom', '_model:=' + cls.model_path,
                            '_directory:=' + cls.out, '_pre:=%d' % PRE, '_post:=%d' % POST,
                            '_context_topics:=imu',  # recorded always, and kept in the windows at its full rate
                            '_diagnostic_period:=0.3')
        rospy.wait_for_service('/%s/trigger' % NODE, timeout=30)
        fx.wait_for(lambda: cls.odom_pub.get_num_connections() and cls.imu_pub.get_num_connections(), 20,
                    'the smart logger to subscribe')

    @classmethod
    def tearDownClass(cls):
        code, out, err = fx.stop(cls.node)
        sys.stderr.write(err[-3000:])
        shutil.rmtree(cls.tmp, ignore_errors=True)

    # -- helpers --------------------------------------------------------------------------------------

    def publish(self, part):
        """Publish stream[part] and the IMU messages of its time span, merged in stamp order."""
        odom = self.stream[part.start - RUN.start:part.stop - RUN.start]
        imu = fx.imu_between(self.imu, odom[0], odom[-1]) if part is RUN else []
        merged = sorted([(r.stamp, 0, r) for r in odom] + [(r.stamp, 1, r) for r in imu], key=lambda x: x[:2])
        for _, kind, record in merged:
            (self.odom_pub if kind == 0 else self.imu_pub).publish(record.msg)
            time.sleep(1.0 / RATE)
        return odom, imu

    def files(self):
        return log_format.window_files(self.out)

    def status_of(self, node):
        """The newest /diagnostics values of ``node`` (a dict; empty before the first)."""
        return fx.status_values(self.diagnostics, node)[2]

    def written(self):
        return [e for e in self.events if e.event == AnomalyEvent.WRITTEN]

    # -- tests, in order ------------------------------------------------------------------------------

    def test_0_bad_configuration_is_one_line_and_an_exit_status(self):
        code, out, err = fx.finish(fx.start('smart_logger.py', '__name:=smart_logger_no_model'))
        self.assertEqual(code, 1)
        self.assertEqual(err.strip().count('\n'), 0, err)
        self.assertIn('~model', err)
        code, out, err = fx.finish(fx.start('smart_logger.py', '__name:=smart_logger_bad_window',
                                            '_model:=' + self.model_path, '_window:=30'))
        self.assertEqual(code, 1)
        self.assertIn('~window', err)
        self.assertEqual(err.strip().count('\n'), 0, err)
        # every parameter type-checked, one line each: no TypeError, OverflowError, nor a directory "[1, 2]"
        cwd = os.path.join(self.tmp, 'cwd')
        os.makedirs(cwd)
        for number, (args, expected) in enumerate((
                (('_model:=[1]',), '~model: [1] is not a string'),
                (('_model:=' + self.model_path, '_post:=99999999999999999999'), '~post: 99999999999999999999 is'),
                (('_model:=' + self.model_path, '_directory:=[1,2]'), '~directory: [1, 2] is not a string'),
                (('_model:=' + self.model_path, '_max_buffer_mb:=-5'),
                 '~max_buffer_mb: -5 is outside 0.001..1e+06 MB (or 0: off)'),
                (('_model:=' + self.model_path, '_recent:=30'),
                 'triggers[0] (classifier): recent: 30 is longer than the feature window 20'))):
            code, out, err = fx.finish(fx.start('smart_logger.py', '__name:=smart_logger_bad_%d' % number, *args,
                                                cwd=cwd))
            self.assertEqual((code, err.strip().count('\n')), (1, 0), err)
            self.assertIn(expected, err)
        code, out, err = fx.finish(fx.start('collect_logger.py', '__name:=collect_logger_bad', '_stride:=[5]',
                                            cwd=cwd))
        self.assertEqual((code, err.strip().count('\n')), (1, 0), err)
        self.assertIn('~stride: [5] is not a message count', err)
        self.assertEqual(os.listdir(cwd), [])

    def test_0_online_learning_refits_beside_the_model_and_reports_it(self):
        # a second node on its own topic, with online learning on and a short refit period (configuration)
        model_path = os.path.join(self.tmp, 'learn.json')
        self.model.save(model_path)
        with open(model_path, 'rb') as stream:
            original = stream.read()
        config = os.path.join(self.tmp, 'learn.yaml')
        with open(config, 'w') as stream:
            stream.write('triggers:\n  - {name: classifier, kind: classifier, model: %s, topics: [learn_odom], '
                         'learn_online: true, learn_every: 20, learn_guard: 1s}\n' % model_path)
        name = 'smart_logger_learning'
        node = fx.start('smart_logger.py', '__name:=' + name, '_config:=' + config,
                        '_directory:=' + os.path.join(self.tmp, 'learn_windows'), '_diagnostic_period:=0.2')
        try:
            publisher = rospy.Publisher('learn_odom', Odometry, queue_size=10000)
            fx.wait_for(lambda: publisher.get_num_connections(), 30, 'the learning node to subscribe')
            for record in self.odom[:400]:
                publisher.publish(record.msg)
                time.sleep(1.0 / RATE)

            def values():
                return self.status_of(name)
            fx.wait_for(lambda: int(values().get('classifier: online refits', 0)) >= 1, 30, 'a refit on /diagnostics')
            status = values()
            self.assertGreater(int(status['classifier: online vectors learned']), 20)
            self.assertEqual(status['classifier: online last error'], 'none')
            self.assertIn(status['classifier: online adapting to drift'], ('yes', 'no'))
            self.assertGreaterEqual(int(status['classifier: online vectors learned from its own flags (drift)']), 0)
            self.assertNotEqual(status['classifier: online last refit'], 'never')
            self.assertEqual(status['classifier: online resumed'], 'no')
            refitted = os.path.join(self.tmp, 'learn.online.json')
            self.assertTrue(os.path.exists(refitted))
            with open(model_path, 'rb') as stream:
                self.assertEqual(stream.read(), original)  # the original model is never written
        finally:
            code, _, err = fx.stop(node)
        self.assertEqual(code, 0, err[-2000:])
        # restarted, the node goes on from the refit it saved (widening the original, which stays untouched)
        node = fx.start('smart_logger.py', '__name:=' + name, '_config:=' + config,
                        '_directory:=' + os.path.join(self.tmp, 'learn_windows'), '_diagnostic_period:=0.2')
        try:
            fx.wait_for(lambda: values().get('classifier: online resumed', '').startswith('resumed from '), 30,
                        'the restarted node to resume its refit')
            self.assertIn(refitted, values()['classifier: online resumed'])
        finally:
            code, _, err = fx.stop(node)
        self.assertEqual(code, 0, err[-2000:])

    def test_0_a_paused_simulated_clock_does_not_stop_diagnostics(self):
        # /use_sim_time and no /clock: rospy time stays 0, diagnostics still come every period of wall time
        name = 'collect_logger_paused_clock'
        rospy.set_param('/use_sim_time', True)  # read by the node when it starts: kept until it publishes
        node = fx.start('collect_logger.py', '__name:=' + name, '_directory:=' + os.path.join(self.tmp, name),
                        '_diagnostic_period:=0.2')
        try:
            def stamps():
                return [array.header.stamp for array in self.diagnostics for item in array.status
                        if item.name == 'cc_log: ' + name]
            fx.wait_for(lambda: len(stamps()) >= 5, 30, 'five diagnostics of ' + name)
            self.assertEqual({stamp.to_sec() for stamp in stamps()}, {0.0})  # the node's clock never moved
        finally:
            rospy.set_param('/use_sim_time', False)
            fx.stop(node)

    def test_0_keep_budget_spent_skips_a_repeated_anomaly_and_warns(self):
        # the run with its burst, then the very same run 100 s later (whole seconds: the same rows, the same
        # scores): with a budget of one window an hour, the repeat is no more anomalous than the kept window
        name, topic = 'smart_logger_budget', 'budget_odom'
        out = os.path.join(self.tmp, 'budget')
        first = self.stream[:RUN.stop - RUN.start]
        again = [copy.deepcopy(record.msg) for record in first]
        for msg in again:
            msg.header.stamp.secs += 100
        publisher = rospy.Publisher(topic, Odometry, queue_size=10000)
        node = fx.start('smart_logger.py', '__name:=' + name, 'odom:=' + topic, '_model:=' + self.model_path,
                        '_directory:=' + out, '_classify_every:=1', '_max_windows_per_hour:=1',
                        '_diagnostic_period:=0.2')
        try:
            fx.wait_for(lambda: publisher.get_num_connections(), 20, name + ' to subscribe')
            for msg in [record.msg for record in first] + again:
                publisher.publish(msg)
                time.sleep(1.0 / RATE)
            fx.wait_for(lambda: fx.status_values(self.diagnostics, name)[2].get('messages seen') == str(
                2 * len(first)), 10, 'diagnostics with every message')
            fx.wait_for(lambda: fx.status_values(self.diagnostics, name)[2].get(
                'windows skipped (keep budget)', '').startswith('1 (scores '), 10, 'the repeat skipped')
            level, message, values = fx.status_values(self.diagnostics, name)
            self.assertEqual(level, DiagnosticStatus.WARN, message)
            self.assertIn('1 window(s) skipped (keep budget 1/h; scores ', message)
            self.assertIn("the keep budget is spent: the robot's normal may have drifted (cclog replay reports "
                          'drift)', message)
            self.assertEqual(values['windows opened'], '1')
        finally:
            fx.stop(node)
            publisher.unregister()

    def test_0_an_envelope_file_as_model_watches_the_odometry_it_was_learned_on(self):
        # the envelope of the first 40 s (with its joint check), learned on /envelope_odom; ~model:=envelope.json
        # builds the envelope trigger on that topic (no classifier); the run's burst opens one window saying why
        from cc_log.learning import envelope
        from cc_log.features.envelope import envelope_windows, odometry_samples
        name, topic = 'smart_logger_envelope', '/envelope_odom'
        out = os.path.join(self.tmp, 'envelope')
        samples = odometry_samples(self.odom[fx.TRAIN])
        learned = envelope.learn([envelope_windows(*samples)[1]], topic, 1.0, 0.25, samples[0][-1] - samples[0][0])
        self.assertIsNotNone(learned.joint)
        path = os.path.join(self.tmp, 'envelope.json')
        learned.save(path)
        run = self.stream[:RUN.stop - RUN.start]
        burst = run[100].stamp
        events = []
        rospy.Subscriber('/%s/anomalies' % name, AnomalyEvent, events.append, queue_size=None)
        publisher = rospy.Publisher(topic, Odometry, queue_size=10000)
        node = fx.start('smart_logger.py', '__name:=' + name, '_model:=' + path, '_directory:=' + out,
                        '_pre:=1s', '_post:=1s', '_diagnostic_period:=0.2')
        try:
            fx.wait_for(lambda: publisher.get_num_connections(), 20, name + ' to subscribe to ' + topic)
            for record in run:
                publisher.publish(record.msg)
                time.sleep(1.0 / RATE)
            fx.wait_for(lambda: [e for e in events if e.event == AnomalyEvent.WRITTEN], 20, 'the window written')
            fx.wait_for(lambda: fx.settled(self.diagnostics, name, len(run)), 20, name + ' to settle')
            files = log_format.window_files(out)
            self.assertEqual(len(files), 1, files)
            metadata, records = log_format.read_window(files[0])
            self.assertEqual((metadata['reason'], metadata['names']), ('envelope', ['envelope']))
            self.assertEqual({r.topic for r in records}, {topic})
            self.assertLessEqual(records[0].stamp, burst)
            fired = metadata['triggers'][0]
            self.assertTrue(burst <= fired['stamp'] <= burst + 0.5 and fired['score'] < 0, fired)
            info = metadata['trigger_info']['envelope']
            self.assertEqual((info['kind'], info['factor'], info['joint_factor']), ('envelope', 2.0, 4.0))
            self.assertEqual(info['joint'], {'typical': learned.joint.typical, 'farthest': learned.joint.farthest})
            self.assertTrue(fired['why'] and fired['why'][0]['ratio'] > 2, fired)
            opened = [e for e in events if e.event == AnomalyEvent.OPENED]
            self.assertEqual(len(opened), 1)
            self.assertAlmostEqual(opened[0].header.stamp.to_sec(), fired['stamp'], places=6)
            # the envelope's drift on /diagnostics: its windows of the 30 s run, judged only after a minute
            said = self.status_of(name).get('drift envelope', '')
            self.assertTrue(said.startswith('drift: not judged yet (2'), self.status_of(name))
        finally:
            fx.stop(node)
            publisher.unregister()

    def test_0_unusable_directory_is_a_warning_naming_the_directory_in_use(self):
        blocker = os.path.join(self.tmp, 'a_file')
        with open(blocker, 'w') as stream:
            stream.write('x')
        home = os.path.join(self.tmp, 'home')
        in_use = os.path.join(home, '.ros', 'cc_log')
        for script, name, extra in (('smart_logger.py', 'smart_logger_fallback', ('_model:=' + self.model_path,)),
                                    ('collect_logger.py', 'collect_logger_fallback', ())):
            node = fx.start(script, '__name:=' + name, '_directory:=' + os.path.join(blocker, 'logs'),
                            '_diagnostic_period:=0.2', *extra,
                            env={'HOME': home, 'ROS_HOME': os.path.join(home, '.ros')})  # ROS's home, as the run's
            try:
                fx.wait_for(lambda: fx.status_values(self.diagnostics, name)[0] is not None, 30,
                            'diagnostics of ' + name)
                level, message, values = fx.status_values(self.diagnostics, name)
                self.assertEqual(level, DiagnosticStatus.WARN, message)
                self.assertIn('cannot be used', message)
                self.assertTrue(message.endswith('logging to ' + in_use), message)
                self.assertEqual(values['directory'], in_use)
            finally:
                fx.stop(node)

    def test_0_a_silent_driving_topic_warns_naming_the_topics_of_its_type(self):
        # odometry flows on /husky_odom (this node's publisher) while these nodes watch /silent_odom; the IMU is
        # published as /imu/data while they are told to keep /IMU/data (names are case-sensitive)
        imu_data = rospy.Publisher('/imu/data', Imu, queue_size=100)
        scripts = (('smart_logger.py', 'smart_logger_silent', ('_model:=' + self.model_path,)),
                   ('collect_logger.py', 'collect_logger_silent', ()))
        nodes = [(name, fx.start(script, '__name:=' + name, 'odom:=silent_odom', '_diagnostic_period:=0.2',
                                 '_directory:=' + os.path.join(self.tmp, name), '_formt:=json-xz',
                                 '_topics:=/IMU/data', *extra))
                 for script, name, extra in scripts]
        named_silence = re.compile(r'no message on /IMU/data for \d+ s; published: /imu/data \(sensor_msgs/Imu\)')

        def silence_said(name):
            status = fx.status_values(self.diagnostics, name)
            return status if 'no nav_msgs/Odometry on /silent_odom' in status[1] and '/IMU/data' in status[1] \
                else None
        try:
            for name, _ in nodes:
                level, message, _ = fx.wait_for(lambda: silence_said(name), 30, 'the silences said by ' + name)
                self.assertEqual(level, DiagnosticStatus.WARN, message)
                self.assertIn('nav_msgs/Odometry is published on ', message)
                self.assertIn('/husky_odom', message)
                self.assertIn(' on /IMU/data (published: /imu/data (sensor_msgs/Imu)', message)
            publisher = rospy.Publisher('silent_odom', Odometry, queue_size=100)
            imu_named = rospy.Publisher('/IMU/data', Imu, queue_size=100)
            records = iter(self.odom * 10)
            imu = iter(self.imu * 10)

            def settled_ok():
                publisher.publish(next(records).msg)  # odometry now comes on the driving topic
                imu_named.publish(next(imu).msg)  # and the IMU on the name the nodes keep
                return all(fx.status_values(self.diagnostics, name)[:2] == (DiagnosticStatus.OK, expected)
                           for (name, _), expected in zip(nodes, ('logging', 'collecting')))
            fx.wait_for(settled_ok, 30, 'both nodes back to OK once odometry and /IMU/data arrive')
        finally:
            outputs = [fx.stop(node) for _, node in nodes]
            imu_data.unregister()
        for code, out, err in outputs:
            self.assertEqual(code, 0, err[-2000:])
            self.assertEqual((out + err).count('no nav_msgs/Odometry on /silent_odom'), 1, out + err)  # once, no flood
            self.assertEqual(len(named_silence.findall(out + err)), 1, out + err)  # the log: once, naming /imu/data
            self.assertEqual((out + err).count('no message on /IMU/data'), 1, out + err)
            self.assertIn('messages arrive on /IMU/data', out + err)
            self.assertIn('unknown parameter ~formt (did you mean ~format?)', out + err)

    def test_1_anomaly_writes_exactly_the_expected_window(self):
        # the offline classifier sees only the burst (messages 100..126 of the run: its 20-row windows)
        run_flags = [i for i in self.flags if i < RUN.stop - RUN.start]
        self.assertTrue(run_flags and 100 <= min(run_flags) and max(run_flags) <= 100 + fx.BURST + 1 + 19,
                        run_flags)
        # the node fires at the burst's onset, then while the newest rows see it (retrigger 'event')
        run_fires = [i for i in self.fires if i < RUN.stop - RUN.start]
        self.assertTrue(run_fires[0] == min(run_flags) and run_fires[-1] <= max(run_flags), (run_fires, run_flags))
        (lo, hi), = fx.expected_windows(run_fires, RUN.stop - RUN.start, PRE, POST)
        odom, imu = self.publish(RUN)
        fx.wait_for(lambda: self.written(), 20, 'the window to be written')
        fx.wait_for(lambda: fx.settled(self.diagnostics, NODE, len(odom) + len(imu)), 20,
                    'the node to feed every message and write what it opened')
        files = self.files()
        self.assertEqual(len(files), 1, files)
        metadata, records = log_format.read_window(files[0])
        kept_odom = [r for r in records if r.topic == '/husky_odom']
        kept_imu = [r for r in records if r.topic == '/imu']
        self.assertEqual(len(kept_odom), hi - lo + 1)
        for kept, sent in zip(kept_odom, odom[lo:hi + 1]):
            self.assertEqual(msg_codec.to_dict(kept.msg), msg_codec.to_dict(sent.msg))
        expected_imu = fx.imu_between(imu, odom[lo], odom[hi])
        self.assertEqual([msg_codec.to_dict(r.msg) for r in kept_imu], [msg_codec.to_dict(r.msg) for r in expected_imu])
        self.assertEqual(len(records), len(kept_odom) + len(kept_imu))
        self.assertEqual(metadata['reason'], 'classifier')
        # events: OPENED at the first anomalous message, then WRITTEN with the file
        opened = [e for e in self.events if e.event == AnomalyEvent.OPENED]
        self.assertEqual(len(opened), 1)
        self.assertAlmostEqual(opened[0].header.stamp.to_sec(), odom[min(run_flags)].stamp, places=6)
        self.assertAlmostEqual(opened[0].start.to_sec(), odom[lo].stamp, places=6)
        self.assertLess(opened[0].score, opened[0].threshold)
        written, = self.written()
        self.assertEqual((written.path, written.messages, written.bytes),
                         (files[0], len(records), os.path.getsize(files[0])))
        self.assertAlmostEqual(written.start.to_sec(), records[0].stamp, places=6)
        self.assertAlmostEqual(written.end.to_sec(), records[-1].stamp, places=6)
        # the classifier's drift: judged only after a minute of decisions, said on /diagnostics
        self.assertTrue(self.status_of(NODE)['drift classifier'].startswith('drift: not judged yet'),
                        self.status_of(NODE))

    def test_2_trigger_service_writes_a_window(self):
        self.assertFalse([i for i in self.flags if TRIGGER.start - RUN.start <= i < TRIGGER.stop - RUN.start])
        before = set(self.files())
        odom = self.stream[TRIGGER.start - RUN.start:TRIGGER.stop - RUN.start]
        for record in odom[:40]:
            self.odom_pub.publish(record.msg)
            time.sleep(1.0 / RATE)
        run = self.stream[:RUN.stop - RUN.start]
        received = len(run) + len(fx.imu_between(self.imu, run[0], run[-1])) + 40

        fx.wait_for(lambda: fx.received(self.diagnostics, NODE) >= received, 10, 'the node receiving the 40 messages')
        # the service first feeds what the node received (its feeder drains in batches of up to 0.5 s), so the
        # window is around the newest of the 40
        response = rospy.ServiceProxy('/%s/trigger' % NODE, Trigger)()
        self.assertTrue(response.success, response.message)
        for record in odom[40:]:
            self.odom_pub.publish(record.msg)
            time.sleep(1.0 / RATE)
        fx.wait_for(lambda: len(self.written()) == 2, 20, 'the manual window')
        new = sorted(set(self.files()) - before)
        self.assertEqual(len(new), 1, new)
        metadata, records = log_format.read_window(new[0])
        self.assertEqual(metadata['reason'], 'manual')
        self.assertEqual(len(records), PRE + 1 + POST)
        stamps = [r.stamp for r in odom]
        first = stamps.index(records[0].stamp)
        self.assertEqual([r.stamp for r in records], stamps[first:first + PRE + 1 + POST])
        self.assertEqual(metadata['triggers'][0]['stamp'], records[PRE].stamp)
        self.assertEqual(odom[39].stamp, records[PRE].stamp)

    def test_3_disabled_logger_writes_no_window(self):
        disabled_flags = [i for i in self.flags if i >= DISABLED.start - RUN.start]
        self.assertTrue(disabled_flags, 'the second burst must be anomalous when enabled')
        response = rospy.ServiceProxy('/%s/enable' % NODE, SetBool)(False)
        self.assertTrue(response.success)
        before, events = self.files(), len(self.events)
        self.publish(DISABLED)
        # diagnostics: disabled, every message seen, the two windows saved
        run = self.stream[:RUN.stop - RUN.start]
        total = len(run) + len(fx.imu_between(self.imu, run[0], run[-1]))
        total += (TRIGGER.stop - TRIGGER.start) + (DISABLED.stop - DISABLED.start)

        def values():
            return self.status_of(NODE)
        fx.wait_for(lambda: values().get('messages seen') == str(total), 5, 'diagnostics with every message')
        self.assertEqual(self.files(), before)  # every message of the burst was taken: no window came of it
        self.assertEqual(len(self.events), events)
        status = values()
        self.assertEqual(status['enabled'], 'False')
        level, message, _ = fx.status_values(self.diagnostics, NODE)
        self.assertEqual(level, DiagnosticStatus.WARN, message)  # paused: nothing is kept, said as a WARN
        self.assertTrue(message.startswith('paused (~enable false)'), message)
        self.assertGreater(int(status['messages not kept (outside every window)']), 0)
        self.assertEqual(status['windows saved'], '2')
        self.assertEqual(status['windows skipped (keep budget)'], '0 (no keep budget)')
        self.assertEqual(status['write errors'], '0')
        self.assertGreater(int(status['raw JSON bytes']), int(status['stored bytes']) > 0)
        self.assertGreater(int(status['free disk bytes']), 0)
        # each subscribed topic's rate (wall time): a number in every status, above 0 while it was published
        rates = [{key: float(value) for key, value in item.items() if key.startswith('rate ')}
                 for item in (dict((kv.key, kv.value) for kv in status.values)
                              for array in self.diagnostics for status in array.status
                              if status.name == 'cc_log: %s' % NODE)]
        self.assertEqual(set(rates[-1]), {'rate /husky_odom Hz', 'rate /imu Hz'})
        for key in rates[-1]:
            self.assertTrue(all(item[key] >= 0 for item in rates), key)
            self.assertGreater(max(item[key] for item in rates), 0, key)
        sizes = [float(kv.value) for array in self.diagnostics for status in array.status
                 if status.name == 'cc_log: %s' % NODE for kv in status.values if kv.key == 'MB/s /husky_odom']
        self.assertTrue(sizes and max(sizes) > 0, sizes)  # MB per second of each topic too
        self.assertTrue(status['last trigger'].startswith('manual: manual at '), status['last trigger'])
        self.assertTrue(rospy.ServiceProxy('/%s/enable' % NODE, SetBool)(True).success)

    def test_4_cclog_top_shows_the_node_per_topic(self):
        code, out, err = fx.finish(fx.start('cclog', 'top', '--once'), 60)
        self.assertEqual(code, 0, err)
        lines = out.splitlines()
        self.assertTrue(any(line.startswith(NODE + '  [') for line in lines), out)
        header = next(i for i, line in enumerate(lines) if line.split() == ['topic', 'Hz', 'MB/s', 'dropped'])
        self.assertEqual(sorted(line.split()[0] for line in lines[header + 1:header + 3]), ['/husky_odom', '/imu'])


if __name__ == '__main__':
    rostest.rosrun(PKG, 'smart_window', SmartWindowTest)
