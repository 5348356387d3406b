#!/usr/bin/python3
"""Test node of safe_decoding.test: the live smart node never runs a message definition (issue 11).

A crafted json-xz window is planted in the logging directory as a crash leftover, then the smart node starts
as a real process and this node publishes odometry and, on a side topic, messages of a type the node does
not have installed whose definition makes genpy run ``touch <marker>``. The leftover is reported and kept,
the side topic's messages are refused and counted on /diagnostics with one warning, the node keeps running
and stops cleanly, and the marker never appears.
"""
import os
import shutil
import sys
import tempfile
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rostest_fixtures as fx  # noqa: E402
from reliability_crash_check import Streamer, make_model  # noqa: E402
from test_reliability import as_leftover  # noqa: E402
from test_safe_decoding import crafted_class, crafted_window  # noqa: E402

from cc_log.storage import log_format  # noqa: E402
from cc_log.base import msg_codec  # noqa: E402

PKG = 'cc_log'
NODE = 'smart_logger_safe'
REFUSED = 'messages refused (unsafe definition)'


class SafeDecodingTest(unittest.TestCase):

    def test_crafted_definitions_never_run_in_the_node(self):
        rospy.init_node('safe_decoding_check')
        tmp = tempfile.mkdtemp(prefix='cc_log_safe_decoding_')
        self.addCleanup(shutil.rmtree, tmp, True)
        marker = os.path.join(tmp, 'marker')
        directory = os.path.join(tmp, 'windows')
        leftover = as_leftover(log_format.write_window(crafted_window(marker=marker), directory, 'json-xz')[0])
        model = make_model(os.path.join(tmp, 'model.json'), always=False)
        diagnostics = []
        rospy.Subscriber('/diagnostics', DiagnosticArray, diagnostics.append, queue_size=None)
        evil_class = crafted_class(marker, msg_codec.generated_class('cc_log_test/Evil', 'float64 x\n'))
        evil = rospy.Publisher('side', evil_class, queue_size=1000)
        streamer = Streamer('odom_in', 'imu_in')
        node = fx.start('smart_logger.py', '__name:=' + NODE, 'odom:=odom_in', '_model:=' + model,
                        '_directory:=' + directory, '_topics:=side', '_diagnostic_period:=0.2')
        try:
            fx.wait_for(lambda: streamer.odom_pub.get_num_connections() and evil.get_num_connections(), 30,
                        'the smart logger to subscribe')
            for i in range(50):
                evil.publish(x=float(i))
            streamer.publish(0.5, 200, imu=False)
            fx.wait_for(lambda: fx.status_values(diagnostics, NODE)[2].get(REFUSED) == '50', 20,
                        '50 refused messages on /diagnostics')
            values = fx.status_values(diagnostics, NODE)[2]
            self.assertEqual(values['leftovers unrecoverable'], '1')
            self.assertIsNone(node.poll())
        finally:
            code, out, err = fx.stop(node)
        self.assertEqual(code, 0, err[-3000:])
        self.assertEqual((out + err).count('messages refused, never decoded'), 1, err[-3000:])
        self.assertIn('topic /odom: message definition of nav_msgs/Odometry', out + err)  # the leftover
        self.assertTrue(os.path.exists(leftover))
        self.assertFalse(os.path.exists(marker), 'code from a message definition ran in the node')


if __name__ == '__main__':
    rostest.rosrun(PKG, 'safe_decoding', SafeDecodingTest)
