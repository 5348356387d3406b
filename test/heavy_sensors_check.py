#!/usr/bin/python3
"""Test node of heavy_sensors.test: a camera in the windows of the live node, one clock, under use_sim_time.

The node is started before any /clock: it subscribes at once, but hands nothing over before the first /clock,
so a message received at time 0 is named by the sim clock, not 1970 (a context track of the odometry is on).
This node then publishes /clock (2015, as a bag played with ``--clock``), odometry and a heartbeat stamped by it,
and a 15 Hz camera stamped by the wall clock (another clock, years away):

1. ``~trigger_window``: one bag file, whose camera frames are those that arrived in the window's span (by the
   node's clock), counted as restamped on /diagnostics; the context file is named from 2015, not 1970;
2. the clock jumps back 100 s (a looping bag), messages go on for a while, then everything but /clock stops:
   the heartbeat's silence rule still fires (its ticker survived the jump), with no message to carry time.
"""
import os
import shutil
import sys
import tempfile
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Image
from std_msgs.msg import Empty

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rostest_fixtures as fx  # noqa: E402

from cc_log.storage import log_format  # noqa: E402
from cc_log.msg import AnomalyEvent  # noqa: E402
from cc_log.srv import TriggerWindow  # noqa: E402

PKG = 'cc_log'
NODE = 'smart_logger'
START = 1432235498.0   # the sim clock starts here (a 2015 bag)
STEP = 0.01            # sim seconds per /clock message
CONFIG = """
driving_topic: odom
topics: [camera/image_raw]
topic_limits: {camera/image_raw: {pre: 0.5s}}
windows: {pre: 1s, post: 1s}
triggers:
  - {name: heartbeat_dead, kind: rule, topic: heartbeat, silent: 1s, hold_off: 1s}
"""


class Publisher(object):
    """/clock from ``START`` in STEP steps at ~2x real time; odometry (50 Hz) and a heartbeat (10 Hz) stamped by it,
    a 320x240 camera (15 Hz) stamped by the wall clock, until ``messages`` is cleared."""

    def __init__(self):
        self.clock = rospy.Publisher('/clock', Clock, queue_size=10)
        self.odom = rospy.Publisher('/odom', Odometry, queue_size=100)
        self.heartbeat = rospy.Publisher('/heartbeat', Empty, queue_size=10)
        self.camera = rospy.Publisher('/camera/image_raw', Image, queue_size=30)
        self.now = START
        self.ticks = 0
        self.messages = threading.Event()
        self.messages.set()
        self.running = True
        self.frame = Image(height=240, width=320, encoding='rgb8', step=960, data=bytes(range(256)) * 900)
        self.thread = threading.Thread(target=self.run)
        self.thread.daemon = True

    def run(self):
        while self.running and not rospy.is_shutdown():
            self.now += STEP
            self.ticks += 1
            self.clock.publish(Clock(clock=rospy.Time.from_sec(self.now)))
            if self.messages.is_set():
                if self.ticks % 2 == 0:
                    msg = Odometry()
                    msg.header.stamp = rospy.Time.from_sec(self.now)
                    msg.twist.twist.linear.x = 0.5
                    self.odom.publish(msg)
                if self.ticks % 10 == 0:
                    self.heartbeat.publish(Empty())
                if self.ticks % 7 == 0:
                    self.frame.header.stamp = rospy.Time.from_sec(time.time())  # another clock
                    self.camera.publish(self.frame)
            time.sleep(STEP / 2)


class HeavySensors(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('heavy_sensors_check')
        cls.directory = tempfile.mkdtemp(prefix='cc_log_heavy_')
        config = os.path.join(cls.directory, 'robot.yaml')
        with open(config, 'w') as out:
            out.write(CONFIG)
        cls.diagnostics, cls.events = [], []
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.diagnostics.append)
        rospy.Subscriber('/%s/anomalies' % NODE, AnomalyEvent, cls.events.append)
        cls.windows = os.path.join(cls.directory, 'windows')
        cls.node = fx.start('smart_logger.py', '__name:=%s' % NODE, '_config:=%s' % config,
                            '_directory:=%s' % cls.windows, '_context_topics:=odom', '_diagnostic_period:=0.2')
        cls.publisher = Publisher()

    @classmethod
    def tearDownClass(cls):
        cls.publisher.running = False
        fx.stop(cls.node)
        shutil.rmtree(cls.directory, ignore_errors=True)

    def values(self):
        return fx.status_values(self.diagnostics, NODE)[2]

    def test_1_a_camera_on_another_clock_in_a_window_of_the_sim_clock(self):
        # subscribed before any /clock (rosbag play --wait-for-subscribers), and a message comes before it
        fx.wait_for(lambda: fx.subscribed('/odom', '/' + NODE) and fx.subscribed('/camera/image_raw', '/' + NODE),
                    60, 'the node to subscribe before the clock starts')
        fx.wait_for(lambda: self.publisher.odom.get_num_connections() > 0, 30, 'the odometry connection')
        self.publisher.odom.publish(Odometry())  # no stamp, no clock yet: received at time 0
        fx.wait_for(lambda: int(self.values().get('intake queue', 0)) >= 1, 30, 'the node to hold it')
        self.assertEqual(self.values()['messages seen'], '0')  # nothing handed over before the clock
        self.assertFalse(os.path.isdir(os.path.join(self.windows, 'context')))
        self.publisher.thread.start()
        rospy.wait_for_service('/%s/trigger_window' % NODE, timeout=60)
        fx.wait_for(lambda: int(self.values().get('messages restamped (header stamp off the clock)', 0)) > 30, 60,
                    'camera frames to come')
        trigger_window = rospy.ServiceProxy('/%s/trigger_window' % NODE, TriggerWindow)
        response = trigger_window(reason='look', before=1.0, after=1.0)
        self.assertTrue(response.success, response.message)
        path = fx.wait_for(lambda: log_format.window_files(self.windows), 60, 'the window file')[0]
        self.assertTrue(path.endswith('.bag') and '_manual' in path, path)
        self.assertEqual(len(log_format.window_files(self.windows)), 1)
        metadata, records = log_format.read_window(path)
        self.assertLessEqual(metadata['end'] - metadata['start'], 2.2)  # pre + post of the sim clock
        self.assertGreater(metadata['start'], START)
        frames = [r.stamp for r in records if r.topic == '/camera/image_raw']
        trigger = metadata['triggers'][0]['stamp']
        # the camera's own 0.5 s before the trigger and the window's 1 s after, a frame every 0.07 s of sim time
        self.assertTrue(18 <= len(frames) <= 23, frames)
        self.assertTrue(all(trigger - 0.5 - 1e-6 <= stamp <= trigger + 1.0 + 1e-6 for stamp in frames), frames)
        self.assertEqual(metadata['counts']['/odom'], 101)  # 1 s before and after at 50 Hz
        context = os.path.join(self.windows, 'context')
        names = fx.wait_for(lambda: os.path.isdir(context) and os.listdir(context), 30, 'the context file')
        self.assertTrue(all('_2015' in name for name in names), names)  # named by the sim clock, not 1970

    def test_2_the_silence_check_lives_on_after_the_clock_jumps_back(self):
        seen = len(self.events)
        self.publisher.now -= 100.0  # a bag played again with --clock
        fx.wait_for(lambda: int(self.values().get('time resets', 0)) >= 1, 60, 'the node to see the clock go back')
        self.publisher.messages.clear()  # only /clock from now on: nothing but the ticker carries time
        event = fx.wait_for(lambda: [e for e in self.events[seen:]
                                     if e.event == AnomalyEvent.OPENED and e.trigger == 'heartbeat_dead'], 60,
                            'the heartbeat silence rule to fire')[0]
        self.assertIn('silent', event.reason)


if __name__ == '__main__':
    rostest.rosrun(PKG, 'heavy_sensors', HeavySensors)
