#!/usr/bin/python3
"""Test node of latched_topics.test: latched topics in the windows of the live smart logger.

A latched ``/tf_static`` (tf2_msgs/TFMessage) is published once, before either node starts. Two smart
loggers run as real processes, one writing json-xz windows and one bag-lz4 windows, each keeping
``/tf_static``; this node then publishes real Husky odometry (restamped to the current time, as a robot's)
and asks each node for three windows (``~trigger``) far enough apart to stay separate. Every window of both
formats must start with the ``/tf_static`` message, once, and every topic of a window must keep the publisher's
callerid and latching (``latching: 1`` on ``/tf_static``): a bag-lz4 window in its connection headers, a json-xz
window in its topic sections.
"""
import os
import shutil
import sys
import tempfile
import time
import unittest

import rosbag
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from std_srvs.srv import Trigger

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rostest_fixtures as fx  # noqa: E402

from cc_log.storage import log_format  # noqa: E402
from cc_log.base import msg_codec  # noqa: E402
from cc_log.msg import AnomalyEvent  # noqa: E402

PKG = 'cc_log'
NAME = 'latched_topics_check'
NODES = {'json-xz': 'smart_json', 'bag-lz4': 'smart_bag'}
PRE = POST = 10
RATE = 100.0     # odometry messages per second (wall time)
WINDOWS = 3
CONFIG = """
topics: [/tf_static]
driving_topic: /odom
windows: {pre: %d, post: %d}
triggers:
  - {name: bumper, kind: rule, topic: /bumper, arrival: true}
""" % (PRE, POST)


def tf_message_class():
    """tf2_msgs/TFMessage built from its definition (tf2_msgs need not be installed)."""
    definition = 'geometry_msgs/TransformStamped[] transforms\n%s\nMSG: geometry_msgs/TransformStamped\n%s' % (
        '=' * 80, TransformStamped._full_text)
    return msg_codec.generated_class('tf2_msgs/TFMessage', definition)


def text(value):
    return value.decode() if isinstance(value, bytes) else value


class LatchedTopicsTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node(NAME)
        cls.tmp = tempfile.mkdtemp(prefix='cc_log_latched_')
        config = os.path.join(cls.tmp, 'latched.yaml')
        with open(config, 'w') as stream:
            stream.write(CONFIG)
        tf_static = tf_message_class()
        transform = TransformStamped()
        transform.header.frame_id, transform.child_frame_id = 'base_link', 'imu_link'
        transform.transform.rotation.w = 1.0
        cls.tf_pub = rospy.Publisher('/tf_static', tf_static, queue_size=1, latch=True)
        cls.tf_pub.publish(tf_static(transforms=[transform]))  # once, before the nodes start
        cls.odom_pub = rospy.Publisher('/odom', Odometry, queue_size=10000)
        cls.events = {fmt: [] for fmt in NODES}
        cls.diagnostics = []
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.diagnostics.append, queue_size=None)
        cls.nodes = {}
        for fmt, name in NODES.items():
            rospy.Subscriber('/%s/anomalies' % name, AnomalyEvent, cls.events[fmt].append, queue_size=None)
            cls.nodes[fmt] = fx.start('smart_logger.py', '__name:=' + name, '_config:=' + config,
                                      '_format:=' + fmt, '_directory:=' + os.path.join(cls.tmp, fmt),
                                      '_diagnostic_period:=0.1')
        for name in NODES.values():
            rospy.wait_for_service('/%s/trigger' % name, timeout=30)
        fx.wait_for(lambda: cls.odom_pub.get_num_connections() == len(NODES) and
                    cls.tf_pub.get_num_connections() == len(NODES), 20, 'the smart loggers to subscribe')
        cls.odom = fx.husky()[0][700:700 + WINDOWS * 60 + POST]

    @classmethod
    def tearDownClass(cls):
        for process in cls.nodes.values():
            code, out, err = fx.stop(process)
            sys.stderr.write(err[-2000:])
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def publish(self, records):
        for record in records:
            record.msg.header.stamp = rospy.Time.now()
            self.odom_pub.publish(record.msg)
            time.sleep(1.0 / RATE)

    def test_a_latched_message_published_once_starts_every_window_and_keeps_its_connection_header(self):
        for k in range(WINDOWS):
            self.publish(self.odom[k * 60:k * 60 + 30])
            for name in NODES.values():  # the request applies to the newest message received: /tf_static, 30 more
                fx.wait_for(lambda: fx.received(self.diagnostics, name) >= 1 + k * 60 + 30, 10,
                            '%s to receive the odometry' % name)
            for name in NODES.values():
                response = rospy.ServiceProxy('/%s/trigger' % name, Trigger)()
                self.assertTrue(response.success, response.message)
            self.publish(self.odom[k * 60 + 30:k * 60 + 60])
        self.publish(self.odom[WINDOWS * 60:WINDOWS * 60 + POST])  # a window is handed on pre + post after its end
        for fmt in NODES:
            fx.wait_for(lambda: len([e for e in self.events[fmt] if e.event == AnomalyEvent.WRITTEN]) >= WINDOWS,
                        30, '%d %s windows' % (WINDOWS, fmt))
        for fmt, events in self.events.items():
            paths = [e.path for e in events if e.event == AnomalyEvent.WRITTEN]
            self.assertEqual(len(paths), WINDOWS, paths)
            for path in paths:
                metadata, records = log_format.read_window(path)
                self.assertEqual(records[0].topic, '/tf_static', path)
                self.assertEqual(records[0].msg.transforms[0].child_frame_id, 'imu_link')
                self.assertEqual(metadata['counts']['/tf_static'], 1, path)
                self.assertEqual(metadata['counts']['/odom'], PRE + POST + 1, path)
                if fmt == 'bag-lz4':
                    with rosbag.Bag(path) as bag:
                        headers = {c.topic: {text(k): text(v) for k, v in c.header.items()}
                                   for c in bag._connections.values()}
                else:  # json-xz keeps callerid and latching; records read back carry them
                    headers = {record.topic: record.connection for record in records}
                self.assertEqual(headers['/tf_static']['latching'], '1')
                self.assertEqual(headers['/odom']['latching'], '0')
                for topic in ('/tf_static', '/odom'):
                    self.assertEqual(headers[topic]['callerid'], rospy.get_name())


if __name__ == '__main__':
    rostest.rosrun(PKG, 'latched_topics', LatchedTopicsTest)
