#!/usr/bin/python3
"""Test node of triggers.test: the live smart logger with a configuration of several triggers.

Before the node starts, two models are trained on the first 40 s of the real Husky bag (odometry motion,
and IMU shocks, each with injected examples as anomalous vectors) and a configuration file names them with a
rule on a DiagnosticArray topic (``/robot_diagnostics``: the node's own statuses go to /diagnostics, where this
node reads how many messages it has received before it asks for a window or counts the windows). The node is
started as a real process with ``_config:=``; this node then publishes:

1. nominal odometry while a status on the rule's topic switches to ERROR and flaps: exactly one window, ``pre``
   before and ``post`` after the odometry message the first ERROR followed, named after the rule, its reason
   the status;
2. a burst in the odometry and a shock in the IMU overlapping in time: the two classifiers' windows merge
   into one file whose metadata names both;
3. ``~trigger_window`` with a reason and its own span: a window of that span and reason;
4. the same configuration replayed offline with ``cclog replay --config`` on a bag, and the live node fed
   that bag with ``rosbag play --clock``: the same windows.
"""
import copy
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import unittest

import numpy as np
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rostest_fixtures as fx  # noqa: E402

from cc_log.learning import learning  # noqa: E402
from cc_log.storage import log_format  # noqa: E402
from cc_log.logger.collector import VectorStream  # noqa: E402
from cc_log.features import FeatureConfig  # noqa: E402
from cc_log.msg import AnomalyEvent  # noqa: E402
from cc_log.srv import TriggerWindow  # noqa: E402
from cc_log.base.records import Record  # noqa: E402

PKG = 'cc_log'
NODE = 'smart_logger'
PRE = POST = 15
RATE = 200.0                   # odometry messages per second (wall time)
IMU_CONFIG = FeatureConfig('imu', '20')
NOMINAL = slice(700, 800)      # odometry the motion model calls nominal (smart_window.test's manual phase)
OVERLAP = slice(400, 600)      # the burst at local index 100, the IMU shock 0.5 s later
ERROR_AT = 40                  # the first ERROR follows this odometry message of NOMINAL
RULE_TOPIC = '/robot_diagnostics'  # the rule's DiagnosticArray topic
LEAD = 10                      # odometry messages each side message is published ahead of its stamp's place


def shock(records, first, count=3, amplitude=25.0):
    """Copies of IMU records with a shock: the acceleration jumps by +-amplitude for ``count`` messages."""
    out = [Record(r.stamp, r.topic, copy.deepcopy(r.msg)) for r in records]
    for k in range(first, first + count):
        out[k].msg.linear_acceleration.x += amplitude * (-1) ** k
    return out


def imu_vectors(records):
    stream = VectorStream(IMU_CONFIG, 1)
    return [(i, v) for i, v in ((i, stream.add(r.msg, r.stamp)) for i, r in enumerate(records)) if v is not None]


def train_imu_model(imu):
    train = imu[:1200]  # the first 40 s
    nominal = np.array([v for _, v in imu_vectors(train)])
    anomalous = np.array([v for start in range(60, 1100, 100) for i, v in
                          imu_vectors(shock(train[start:start + 40], 10)) if i <= 29])  # windows holding it
    model, _ = learning.train(nominal, anomalous, IMU_CONFIG)
    return model


def diagnostics(stamp, level):
    array = DiagnosticArray()
    array.header.stamp = rospy.Time.from_sec(stamp)
    array.status = [DiagnosticStatus(level=level, name='motors', message='overcurrent' if level else 'ok')]
    return array


class TriggersTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('triggers_check')
        cls.tmp = tempfile.mkdtemp(prefix='cc_log_triggers_')
        cls.out = os.path.join(cls.tmp, 'windows')
        cls.odom, cls.imu = fx.husky()
        motion = fx.train_model(cls.odom)
        imu_model = train_imu_model(cls.imu)
        cls.paths = {'motion': os.path.join(cls.tmp, 'motion.json'), 'imu': os.path.join(cls.tmp, 'imu.json')}
        motion.save(cls.paths['motion'])
        imu_model.save(cls.paths['imu'])
        cls.motion, cls.imu_model = motion, imu_model
        cls.config = os.path.join(cls.tmp, 'robot.yaml')
        with open(cls.config, 'w') as stream:
            stream.write(CONFIG % (PRE, POST, cls.paths['motion'], cls.paths['imu']))
        cls.events = []
        rospy.Subscriber('/%s/anomalies' % NODE, AnomalyEvent, cls.events.append, queue_size=None)
        cls.odom_pub = rospy.Publisher('/husky_odom', Odometry, queue_size=10000)
        cls.imu_pub = rospy.Publisher('/imu', Imu, queue_size=10000)
        cls.diag_pub = rospy.Publisher(RULE_TOPIC, DiagnosticArray, queue_size=1000)
        cls.diagnostics, cls.sent = [], 0
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.diagnostics.append, queue_size=None)
        cls.node = fx.start('smart_logger.py', '__name:=' + NODE, '_config:=' + cls.config, '_directory:=' + cls.out,
                            '_diagnostic_period:=0.1')
        rospy.wait_for_service('/%s/trigger_window' % NODE, timeout=30)
        fx.wait_for(lambda: all(pub.get_num_connections() for pub in (cls.odom_pub, cls.imu_pub, cls.diag_pub)),
                    20, 'the smart logger to subscribe')

    @classmethod
    def tearDownClass(cls):
        code, out, err = fx.stop(cls.node)
        sys.stderr.write(err[-3000:])
        shutil.rmtree(cls.tmp, ignore_errors=True)

    # -- helpers --------------------------------------------------------------------------------------

    def publish(self, items, pause=1.0 / RATE):
        """Publish (publisher, msg) in order, ``pause`` s apart (wall time)."""
        for publisher, msg in items:
            publisher.publish(msg)
            type(self).sent += 1
            time.sleep(pause)

    def publish_ahead(self, items, pause=1.0 / RATE):
        """Publish ``(stamp, publisher, msg)`` (in stamp order), each side message LEAD odometry messages ahead of
        its stamp's place. Another connection may be read before or after the odometry's: a side message taken
        before the odometry stamped before it waits for it (its Fire applies there, ``fire_order``), but one taken
        after odometry stamped later fires late; published this far ahead, none is taken late under load."""
        ahead, odom = {}, []
        for stamp, publisher, msg in items:
            if publisher is self.odom_pub:
                odom.append((publisher, msg))
            else:
                ahead.setdefault(max(len(odom) - LEAD, 0), []).append((publisher, msg))
        order = [item for k, item in enumerate(odom) for item in ahead.get(k, []) + [item]]
        self.publish(order + ahead.get(len(odom), []), pause)

    def wait_received(self):
        """Until the node has received every message published so far (its /diagnostics)."""
        fx.wait_for(lambda: fx.received(self.diagnostics, NODE) >= self.sent, 10, 'the node to receive %d messages'
                    % self.sent)

    def written(self):
        return [e for e in self.events if e.event == AnomalyEvent.WRITTEN]

    def new_windows(self, before, count, what):
        fx.wait_for(lambda: len(self.written()) >= before + count, 30, what)
        fx.wait_for(lambda: fx.settled(self.diagnostics, NODE, self.sent), 10,
                    'the node to feed every message and write every window it opened')
        paths = [e.path for e in self.written()[before:]]
        self.assertEqual(len(paths), count, paths)
        return [(path,) + log_format.read_window(path) for path in paths]

    # -- tests, in order ------------------------------------------------------------------------------

    def test_1_a_diagnostics_rule_saves_exactly_one_window_with_its_span_and_reason(self):
        odom = self.odom[NOMINAL]
        self.assertFalse(fx.flagged(self.motion, odom))
        items = []
        for i, record in enumerate(odom):
            items.append((record.stamp, self.odom_pub, record.msg))
            if i % 5 == 0 or ERROR_AT <= i <= ERROR_AT + 20:
                # ERROR at message 40, flapping OK / ERROR for 2 s, OK after: one window (hold-off 5 s)
                level = 2 if i == ERROR_AT or (ERROR_AT < i <= ERROR_AT + 20 and i % 3 == 0) else 0
                items.append((record.stamp + 0.05, self.diag_pub, diagnostics(record.stamp + 0.05, level)))
        self.publish([(self.odom_pub, odom[0].msg)])
        self.wait_received()  # the node sees the first odometry before the stream goes on
        self.publish_ahead(items[1:])
        [(path, metadata, records)] = self.new_windows(0, 1, 'the rule window')
        kept = [r for r in records if r.topic == '/husky_odom']
        self.assertEqual([r.stamp for r in kept], [r.stamp for r in odom[ERROR_AT - PRE:ERROR_AT + POST + 1]])
        self.assertEqual((metadata['trigger'], metadata['names']), ('motor_error', ['motor_error']))
        self.assertEqual(metadata['reason'], 'motors: ERROR overcurrent')
        self.assertEqual(len(metadata['triggers']), 1)
        self.assertEqual(metadata['triggers'][0]['stamp'], odom[ERROR_AT].stamp)
        self.assertTrue(path.endswith('_motor-error.bag'), path)
        opened = [e for e in self.events if e.event == AnomalyEvent.OPENED]
        self.assertEqual([(e.trigger, e.reason) for e in opened], [('motor_error', 'motors: ERROR overcurrent')])

    def test_2_imu_and_odometry_classifiers_merge_overlapping_windows_into_one_file_naming_both(self):
        odom = fx.inject(self.odom[OVERLAP], 100)
        first, last = odom[0].stamp, odom[-1].stamp
        imu = [r for r in self.imu if first <= r.stamp <= last]
        at = next(i for i, r in enumerate(imu) if r.stamp >= odom[100].stamp + 0.5)
        imu = shock(imu, at)
        odom_flags = fx.flagged(self.motion, odom)
        imu_flags = [i for i, v in imu_vectors(imu) if self.imu_model.is_anomalous(v)[0]]
        self.assertTrue(odom_flags and min(odom_flags) >= 100, odom_flags)
        self.assertTrue(imu_flags and min(imu_flags) >= at, imu_flags)
        merged = sorted([(r.stamp, 0, r.msg) for r in odom] + [(r.stamp, 1, r.msg) for r in imu], key=lambda x: x[:2])
        before = len(self.written())
        self.publish_ahead([(stamp, self.odom_pub if kind == 0 else self.imu_pub, msg) for stamp, kind, msg in merged],
                           pause=0.5 / RATE)
        [(path, metadata, records)] = self.new_windows(before, 1, 'the merged window')
        self.assertEqual(metadata['trigger'], 'odom_motion')
        self.assertEqual(sorted(metadata['names']), ['imu_shock', 'odom_motion'])
        kept = [r.stamp for r in records if r.topic == '/husky_odom']
        stamps = [r.stamp for r in odom]
        self.assertEqual(kept, stamps[stamps.index(kept[0]):stamps.index(kept[-1]) + 1])  # contiguous
        self.assertEqual(kept[0], stamps[min(odom_flags) - PRE])
        self.assertGreaterEqual(kept[-1], stamps[max(odom_flags)])
        shocks = [t['stamp'] for t in metadata['triggers'] if t['name'] == 'imu_shock']
        self.assertEqual(len(shocks), 1)  # onset only
        self.assertLess(abs(shocks[0] - imu[min(imu_flags)].stamp), 0.2)
        self.assertEqual(metadata['trigger_info']['imu_shock']['model']['feature_set'], 'imu')
        self.assertTrue(any(r.topic == '/imu' for r in records))
        # the classifier says why: in the metadata (its first and most anomalous firings) and on ~anomalies
        said = [t['why'] for t in metadata['triggers'] if t['name'] == 'odom_motion' and 'why' in t]
        self.assertTrue(said and all(1 <= len(why) <= 3 and why[0]['text'] for why in said), said)
        opened = [e for e in self.events if e.event == AnomalyEvent.OPENED and e.trigger == 'odom_motion']
        self.assertTrue(opened and opened[-1].reason.startswith('classifier; why: '), [e.reason for e in opened])

    def test_3_trigger_window_with_a_reason_and_its_own_span(self):
        odom = self.odom[NOMINAL.stop:NOMINAL.stop + 60 + POST]  # a window is handed on pre + post after its end
        self.assertFalse(fx.flagged(self.motion, self.odom[NOMINAL.stop - 30:NOMINAL.stop + 60 + POST]))
        before = len(self.written())
        self.publish([(self.odom_pub, r.msg) for r in odom[:30]])
        self.wait_received()  # the request applies to the newest message received
        response = rospy.ServiceProxy('/%s/trigger_window' % NODE, TriggerWindow)(
            reason='operator saw a wobble', before=0.5, after=1.0)
        self.assertTrue(response.success, response.message)
        self.publish([(self.odom_pub, r.msg) for r in odom[30:]])
        [(path, metadata, records)] = self.new_windows(before, 1, 'the requested window')
        kept = [r.stamp for r in records if r.topic == '/husky_odom']
        newest = odom[29].stamp
        self.assertEqual(kept, [r.stamp for r in odom if newest - 0.5 <= r.stamp <= newest + 1.0])
        self.assertEqual((metadata['trigger'], metadata['reason']), ('manual', 'operator saw a wobble'))
        written = self.written()[-1]
        self.assertEqual((written.trigger, written.reason), ('manual', 'operator saw a wobble'))
        bad = rospy.ServiceProxy('/%s/trigger_window' % NODE, TriggerWindow)(reason='x', before=-1.0, after=0.0)
        self.assertFalse(bad.success)
        self.assertIn('before', bad.message)

    def test_4_replay_with_the_configuration_equals_the_live_node_fed_the_same_bag(self):
        fx.stop(self.node)  # the live node of the tests above would take the bag too
        odom = fx.inject(self.odom[OVERLAP.start:OVERLAP.stop + 200], 100)
        imu = [r for r in self.imu if odom[0].stamp <= r.stamp <= odom[-1].stamp]
        bag = os.path.join(self.tmp, 'run.bag')
        diag = [Record(r.stamp + 0.05, RULE_TOPIC, diagnostics(r.stamp + 0.05, 2 if i == 250 else 0))
                for i, r in enumerate(odom) if i % 10 == 0]
        import rosbag
        merged = sorted([(r.stamp, '/husky_odom', r.msg) for r in odom] + [(r.stamp, '/imu', r.msg) for r in imu]
                        + [(r.stamp, RULE_TOPIC, r.msg) for r in diag], key=lambda x: x[0])
        with rosbag.Bag(bag, 'w') as out:
            for stamp, topic, msg in merged:
                out.write(topic, msg, t=rospy.Time.from_sec(stamp))
        config = os.path.join(self.tmp, 'replay.yaml')
        with open(config, 'w') as stream:  # the IMU kept, not classified: its messages interleave with odometry
            stream.write(CONFIG.replace("  - {name: imu_shock", "  # - {name: imu_shock")
                         % (PRE, POST, self.paths['motion'], self.paths['imu']))
        offline = subprocess.run([sys.executable, fx.script('cclog'), 'replay', bag, '--config', config, '--out',
                                  os.path.join(self.tmp, 'offline'), '--json'], capture_output=True, text=True,
                                 timeout=120)
        self.assertEqual(offline.returncode, 0, offline.stderr)
        offline = [log_format.read_window(w['path']) for w in json.loads(offline.stdout)['windows']]
        self.assertGreaterEqual(len(offline), 2)
        self.assertEqual({name for metadata, _ in offline for name in metadata['names']},
                         {'odom_motion', 'motor_error'})
        live_dir = os.path.join(self.tmp, 'live')
        rospy.set_param('/use_sim_time', True)
        node = fx.start('smart_logger.py', '__name:=smart_logger_play', '_config:=' + config,
                        '_directory:=' + live_dir, '_diagnostic_period:=0.1')
        try:
            fx.wait_for(lambda: fx.subscribed('/husky_odom', '/smart_logger_play'), 30, 'the node to subscribe')
            # the node is the only subscriber left: rosbag waits for it on every topic
            play = subprocess.run(['rosbag', 'play', '--clock', '-q', '--wait-for-subscribers', bag],
                                  capture_output=True, text=True, timeout=120)
            self.assertEqual(play.returncode, 0, play.stderr)
            fx.wait_for(lambda: fx.received(self.diagnostics, 'smart_logger_play') >= len(merged), 20,
                        'the node to receive the whole bag')
        finally:
            code, out, err = fx.stop(node)
            rospy.set_param('/use_sim_time', False)
        self.assertEqual(code, 0, err[-2000:])
        live = [log_format.read_window(path) for path in log_format.window_files(live_dir)]

        def summary(windows):
            return sorted((m['start'], m['end'], m['counts'], [(t['stamp'], t['name'], t['reason']) for t in
                                                               m['triggers']]) for m, _ in windows)
        self.assertEqual(summary(live), summary(offline))


CONFIG = """
topics: [/imu]
driving_topic: /husky_odom
windows: {pre: %d, post: %d}
triggers:
  - {name: odom_motion, kind: classifier, model: %s, topics: [/husky_odom], classify_every: '1'}
  - {name: imu_shock, kind: classifier, model: %s, topics: [/imu], classify_every: '1', retrigger: onset}
  - {name: motor_error, kind: rule, topic: /robot_diagnostics, level: ERROR, status: 'motor*', hold_off: 5s}
"""


if __name__ == '__main__':
    rostest.rosrun(PKG, 'triggers', TriggersTest)
