#!/usr/bin/python3
"""Test node of manual_trigger.test: ``cclog trigger --reason bump --before 1 --after 1`` saves a window.

A model is trained on the first 40 s of the real Husky bag; the smart logger runs as a real process with it,
writing json-xz and keeping a camera topic.

0. A camera (sensor_msgs/Image) written as json-xz: the node warns once, at its first message, that json-xz
   carries about 16 MB/s per core and the camera is better kept as bag-lz4.
1. This node publishes 20 s of nominal odometry (nothing the classifier flags): 5 s, then ``cclog trigger`` (a
   real process, no ``--node``: it finds the one smart logger), then the rest. One window is written: reason
   "bump", around the newest message at the call, 1 s of stamps before it and 1 s after.
"""
import os
import shutil
import sys
import tempfile
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rostest_fixtures as fx  # noqa: E402

from cc_log.storage import log_format  # noqa: E402
from cc_log.msg import AnomalyEvent  # noqa: E402

PKG = 'cc_log'
NODE = 'smart_logger'
RATE = 200.0             # messages per second, wall time
STREAM = slice(700, 900)  # nominal driving, 20 s of stamps at 10 Hz
CALL_AT = 50              # messages published before the call
PERIOD = 0.1              # s between the run's odometry stamps (10 Hz)
IMAGES = 3                # camera frames published (before the odometry)
ADVICE = ('json-xz carries about 16 MB/s per core: /camera/image_raw (sensor_msgs/Image) is better kept as '
          'bag-lz4 (a route: ')


class ManualTriggerTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('manual_trigger_check')
        cls.tmp = tempfile.mkdtemp(prefix='cc_log_manual_trigger_')
        cls.out = os.path.join(cls.tmp, 'windows')
        odom, _ = fx.husky()
        model = fx.train_model(odom)
        model_path = os.path.join(cls.tmp, 'model.json')
        model.save(model_path)
        cls.stream = odom[STREAM]
        cls.fires = fx.fired(model, cls.stream)
        cls.events, cls.diagnostics, cls.logs = [], [], []
        rospy.Subscriber('/rosout', Log, cls.logs.append, queue_size=None)
        rospy.Subscriber('/%s/anomalies' % NODE, AnomalyEvent, cls.events.append, queue_size=None)
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.diagnostics.append, queue_size=None)
        cls.odom_pub = rospy.Publisher('husky_odom', Odometry, queue_size=10000)
        cls.camera_pub = rospy.Publisher('camera/image_raw', Image, queue_size=10)
        cls.node = fx.start('smart_logger.py', '__name:=' + NODE, 'odom:=husky_odom', '_model:=' + model_path,
                            '_directory:=' + cls.out, '_diagnostic_period:=0.3', '_format:=json-xz',
                            '_topics:=camera/image_raw')
        rospy.wait_for_service('/%s/trigger_window' % NODE, timeout=30)
        fx.wait_for(lambda: cls.odom_pub.get_num_connections() and cls.camera_pub.get_num_connections(), 20,
                    'the smart logger to subscribe')

    @classmethod
    def tearDownClass(cls):
        code, out, err = fx.stop(cls.node)
        sys.stderr.write(err[-3000:])
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def publish(self, records):
        for record in records:
            self.odom_pub.publish(record.msg)
            time.sleep(1.0 / RATE)

    def written(self):
        return [e for e in self.events if e.event == AnomalyEvent.WRITTEN]

    def test_0_a_camera_written_as_json_xz_is_warned_once(self):
        for _ in range(IMAGES):
            self.camera_pub.publish(Image(height=480, width=640, encoding='rgb8', step=1920, data=bytes(921600)))
        fx.wait_for(lambda: fx.received(self.diagnostics, NODE) >= IMAGES, 20, 'the node receiving the frames')

        def advised():
            return [log for log in self.logs if log.name == '/' + NODE and log.msg.startswith(ADVICE)]
        fx.wait_for(advised, 10, 'the json-xz advice on /rosout')
        self.assertEqual(advised()[0].level, Log.WARN)
        self.assertEqual(len(advised()), 1)  # once, not per frame

    def test_1_cclog_trigger_writes_a_window_with_the_reason_and_seconds(self):
        self.assertEqual(self.fires, [], 'the stream must be nominal: only the manual trigger may open a window')
        self.publish(self.stream[:CALL_AT])
        fx.wait_for(lambda: fx.received(self.diagnostics, NODE) >= IMAGES + CALL_AT, 20,
                    'the node receiving the messages')
        code, out, err = fx.finish(fx.start('cclog', 'trigger', '--reason', 'bump', '--before', '1', '--after', '1'),
                                   60)
        self.assertEqual(code, 0, err)
        self.assertTrue(out.startswith('/%s/trigger_window: window triggered at ' % NODE), out)
        self.publish(self.stream[CALL_AT:])
        fx.wait_for(self.written, 20, 'the window to be written')
        files = log_format.window_files(self.out)
        self.assertEqual(len(files), 1, files)
        metadata, records = log_format.read_window(files[0])
        self.assertEqual(metadata['reason'], 'bump')
        written = self.written()
        self.assertEqual([(e.reason, e.messages) for e in written], [('bump', len(records))])
        records = [r for r in records if r.topic == '/husky_odom']  # (frames near the window's span are in it)
        called = self.stream[CALL_AT - 1].stamp  # the newest message when the service was called
        self.assertEqual(metadata['triggers'][0]['stamp'], called)
        stamps = [r.stamp for r in self.stream]
        first = stamps.index(records[0].stamp)
        self.assertEqual([r.stamp for r in records], stamps[first:first + len(records)])  # consecutive
        self.assertGreaterEqual(records[0].stamp, called - 1.0 - 1e-6)  # 1 s before, to within one message
        self.assertLess(records[0].stamp, called - 1.0 + PERIOD + 1e-6)
        self.assertLessEqual(records[-1].stamp, called + 1.0 + 1e-6)  # 1 s after, to within one message
        self.assertGreater(records[-1].stamp, called + 1.0 - PERIOD - 1e-6)


if __name__ == '__main__':
    rostest.rosrun(PKG, 'manual_trigger', ManualTriggerTest)
