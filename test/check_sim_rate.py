#!/usr/bin/python3
"""rostest node (test/sim_bwibot.test): sim_bwibot publishes odom at ~hz, steadily, stamped with the wall
clock, IMU alongside, and its ground truth on sim/anomaly (and in ~truth_file) around a visible anomaly."""
import json
import math
import os
import sys
import threading
import time
import unittest

import rospy
import rostest
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Image, Imu, LaserScan
from std_msgs.msg import String

from cc_log import sim

PKG = 'cc_log'


class SimBwibotRate(unittest.TestCase):

    def setUp(self):
        self.lock = threading.Lock()
        self.odom, self.imu, self.events = [], [], []
        self.frames = {'camera/image_raw': [], 'scan': []}
        rospy.Subscriber('camera/image_raw', Image, self.frames['camera/image_raw'].append, queue_size=100)
        rospy.Subscriber('scan', LaserScan, self.frames['scan'].append, queue_size=100)
        rospy.Subscriber('odom', Odometry, self.on_odom, queue_size=1000)
        rospy.Subscriber('imu/data', Imu, self.on_imu, queue_size=1000)
        rospy.Subscriber('sim/anomaly', String, self.on_event, queue_size=100)

    def on_odom(self, msg):
        with self.lock:
            self.odom.append((time.time(), msg))

    def on_imu(self, msg):
        with self.lock:
            self.imu.append(msg)

    def on_event(self, msg):
        with self.lock:
            self.events.append(json.loads(msg.data))

    def wait(self, condition, timeout):
        deadline = time.time() + timeout
        while time.time() < deadline and not rospy.is_shutdown():
            with self.lock:
                if condition():
                    return True
            time.sleep(0.05)
        return False

    def test_rate_stamps_and_truth(self):
        hz = float(rospy.get_param('~hz', 100.0))
        hzerror = float(rospy.get_param('~hzerror', 5.0))
        duration = float(rospy.get_param('~duration', 5.0))
        truth_file = rospy.get_param('~truth_file', '')
        self.assertTrue(self.wait(lambda: self.odom, 10.0), 'no odometry on %s' % rospy.resolve_name('odom'))
        start = time.time()
        self.assertTrue(self.wait(lambda: time.time() - start >= duration, duration + 1.0))
        with self.lock:
            window = [(arrival, msg) for arrival, msg in self.odom if arrival >= start]
            imu_count = len(self.imu)
        arrivals = [a for a, m in window]
        stamps = [m.header.stamp.to_sec() for a, m in window]
        self.assertGreater(len(window), 10)
        received = (len(arrivals) - 1) / (arrivals[-1] - arrivals[0])
        stamped = (len(stamps) - 1) / (stamps[-1] - stamps[0])
        rospy.loginfo('odom: %.2f Hz received, %.2f Hz by stamps, %d messages', received, stamped, len(window))
        self.assertLess(abs(received - hz), hzerror, 'received %.2f Hz, expected %g +- %g' % (received, hz, hzerror))
        self.assertLess(abs(stamped - hz), hzerror, 'stamped %.2f Hz, expected %g +- %g' % (stamped, hz, hzerror))
        # steady: stamp spacing close to 1/hz, no stalls; stamps are the wall clock, increasing
        gaps = sorted(b - a for a, b in zip(stamps, stamps[1:]))
        self.assertGreater(gaps[0], 0.0, 'stamps do not increase')
        self.assertLess(abs(gaps[len(gaps) // 2] - 1.0 / hz), 0.1 / hz, 'median spacing %.4f s' % gaps[len(gaps) // 2])
        self.assertLess(gaps[int(0.95 * (len(gaps) - 1))], 2.0 / hz, '95th percentile spacing %.4f s' % gaps[-1])
        self.assertLess(gaps[-1], 0.1, 'a stall of %.3f s' % gaps[-1])
        self.assertLess(max(abs(a - s) for a, s in zip(arrivals, stamps)), 0.25, 'stamps are not the wall clock')
        msg = window[-1][1]
        self.assertEqual((msg.header.frame_id, msg.child_frame_id), ('odom', 'base_link'))
        self.assertGreater(msg.pose.covariance[0], 0.0)
        self.assertGreater(msg.twist.covariance[35], 0.0)
        if rospy.get_param('~imu', False):
            self.assertGreater(imu_count, 0.9 * len(self.odom) - 10, 'IMU: %d messages' % imu_count)
        # ground truth: one anomaly starts and ends, the pose jumps between its stamps, the file agrees
        self.assertTrue(self.wait(lambda: any(e['event'] == 'end' for e in self.events), 20.0),
                        'no anomaly ended on sim/anomaly: %s' % self.events)
        with self.lock:
            events = list(self.events)
        self.assertEqual([e['event'] for e in events][:2], ['start', 'end'])
        begin, end = events[0], events[1]
        self.assertEqual(begin['type'], end['type'])
        self.assertEqual(begin['start'], end['start'])
        self.assertLess(end['start'] + 1.0, end['end'])
        # the odometry of the tick that ended it is published right after the event: wait for it
        self.assertTrue(self.wait(lambda: self.odom[-1][1].header.stamp.to_sec() > end['end'] + 0.05, 2.0))
        with self.lock:
            odom = [m for a, m in self.odom]
        # from the message before the start (the first jump) to the one at the end (the jump back)
        first = max(i for i, m in enumerate(odom) if m.header.stamp.to_sec() < end['start'])
        inside = [m for m in odom[first:] if m.header.stamp.to_sec() <= end['end']]
        self.assertGreater(len(inside), 50)
        if end['type'] == 'localization_jump':
            jumps = [math.hypot(b.pose.pose.position.x - a.pose.pose.position.x,
                                b.pose.pose.position.y - a.pose.pose.position.y)
                     - abs(b.twist.twist.linear.x) * (b.header.stamp.to_sec() - a.header.stamp.to_sec())
                     for a, b in zip(inside, inside[1:])]
            self.assertGreater(max(jumps), 0.3, 'no pose jump inside the localization jump')
        if truth_file:
            self.assertTrue(self.wait(lambda: _readable(truth_file), 2.0), 'no %s' % truth_file)
            truth = sim.load_truth(truth_file)
            self.assertEqual(truth[0], {'type': end['type'], 'start': end['start'], 'end': end['end']})
            os.remove(truth_file)

    def test_camera_at_15_hz_and_scan_at_10_hz(self):
        if not rospy.get_param('~sensors', False):
            return
        self.assertTrue(self.wait(lambda: all(self.frames.values()), 10.0), 'no camera/image_raw or no scan')
        with self.lock:
            before = dict((topic, len(frames)) for topic, frames in self.frames.items())
        start = time.time()
        self.assertTrue(self.wait(lambda: time.time() - start >= 4.0, 5.0))
        for topic, hz in (('camera/image_raw', 15.0), ('scan', 10.0)):
            frames = self.frames[topic][before[topic]:]
            stamped = (len(frames) - 1) / (frames[-1].header.stamp.to_sec() - frames[0].header.stamp.to_sec())
            self.assertLess(abs(stamped - hz), 1.0, '%s: %.2f Hz by stamps' % (topic, stamped))
            self.assertGreater(len(frames), 0.8 * hz * 4.0, '%s: %d messages in 4 s' % (topic, len(frames)))
        image = self.frames['camera/image_raw'][-1]
        self.assertEqual((image.width, image.height, image.encoding, len(image.data)), (320, 240, 'rgb8', 230400))
        self.assertEqual(len(self.frames['scan'][-1].ranges), 481)


def _readable(path):
    try:
        sim.load_truth(path)
        return True
    except (IOError, OSError, ValueError, KeyError):
        return False


if __name__ == '__main__':
    rospy.init_node('check_sim_rate')
    rostest.rosrun(PKG, 'check_sim_rate', SimBwibotRate, sys.argv)
