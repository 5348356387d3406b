#!/usr/bin/python3
"""Test node of reliability_crash.test: SIGKILL the live smart node while it writes windows.

The smart node runs as a real process with a model that calls every message anomalous, so a window is open
all the time and is written in parts every ``max_window`` messages (bag-lz4: rosbag writes chunk by chunk,
the slowest format, the most exposed to a kill). This node publishes odometry and IMU as fast as the node
takes them, SIGKILLs the node (its pid: we started it) at a random moment, three times in a row, restarting
it on the same directory each time:

- every final window file decodes completely (log_format.read_window), whatever the kill interrupted;
- a leftover ``*.tmp-<pid>`` of the kill is recovered by the next start (renamed, rebuilt from its chunks, or, when it
  cannot be, reported and kept), never silently deleted: the final files after the restart hold at least
  every message the leftovers held;
- on the last start, two planted leftovers (a complete window under a temporary name and a bag cut off by a
  SIGKILL of its writer) are recovered with what they held, logged, and counted on /diagnostics.
"""
import math
import os
import random
import shutil
import signal
import sys
import tempfile
import time
import unittest

import numpy as np
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rostest_fixtures as fx  # noqa: E402

from cc_log.learning import learning  # noqa: E402
from cc_log.storage import log_format, recovery  # noqa: E402
from cc_log.features import FeatureConfig, vector_length  # noqa: E402

PKG = 'cc_log'
NODE = 'smart_logger_crash'
CONFIG = FeatureConfig('motion', '20')
ROUNDS = 3


def make_model(path, always):
    """A model trained on random vectors, with a threshold that calls everything anomalous (``always``)
    or nothing."""
    rng = np.random.RandomState(0)
    model, _ = learning.train(rng.normal(size=(60, vector_length(CONFIG))), None, CONFIG)
    model.threshold = 1e9 if always else -1e9
    model.save(path)
    return path


class Streamer(object):
    """Odometry and IMU with increasing header stamps from now on."""

    def __init__(self, odom_topic='odom_in', imu_topic='imu_in'):
        self.odom_pub = rospy.Publisher(odom_topic, Odometry, queue_size=100000)
        self.imu_pub = rospy.Publisher(imu_topic, Imu, queue_size=100000)
        self.i = 0
        self.t0 = time.time()

    def connected(self):
        return self.odom_pub.get_num_connections() > 0 and self.imu_pub.get_num_connections() > 0

    def messages(self, i, stamp):
        odom = Odometry()
        odom.header.seq = i
        odom.header.stamp = rospy.Time.from_sec(stamp)
        odom.header.frame_id = 'odom'
        odom.child_frame_id = 'base_link'
        odom.pose.pose.position.x = 0.01 * i
        odom.pose.pose.orientation.w = 1.0
        odom.twist.twist.linear.x = 1.0 + 0.1 * math.sin(i * 0.05)
        odom.twist.twist.angular.z = 0.1 * math.cos(i * 0.03)
        imu = Imu()
        imu.header.seq = i
        imu.header.stamp = rospy.Time.from_sec(stamp + 0.0005)
        imu.header.frame_id = 'imu'
        imu.orientation.w = 1.0
        imu.linear_acceleration.z = 9.81
        imu.angular_velocity.z = odom.twist.twist.angular.z
        return odom, imu

    def publish(self, seconds, rate, imu=True):
        """Publish odometry (and IMU) at ``rate`` Hz of header time, paced in wall time; return the count."""
        start = time.time()
        sent = 0
        while time.time() - start < seconds:
            due = int((time.time() - start) * rate) + 1
            while sent < due:
                odom, imu_msg = self.messages(self.i, self.t0 + self.i / rate)
                self.odom_pub.publish(odom)
                if imu:
                    self.imu_pub.publish(imu_msg)
                self.i += 1
                sent += 1
            time.sleep(0.001)
        return sent


class CrashTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('reliability_crash_check')
        cls.tmp = tempfile.mkdtemp(prefix='cc_log_crash_')
        cls.out = os.path.join(cls.tmp, 'windows')
        cls.model = make_model(os.path.join(cls.tmp, 'model.json'), always=True)
        cls.diagnostics = []
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.diagnostics.append, queue_size=None)
        cls.stream = Streamer()
        cls.node = None

    @classmethod
    def tearDownClass(cls):
        if cls.node is not None and cls.node.poll() is None:
            code, out, err = fx.stop(cls.node)
            sys.stderr.write(err[-2000:])
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def tearDown(self):
        if self.node is not None and self.node.poll() is None:
            fx.stop(self.node)
        type(self).node = None

    def start(self, directory=None):
        del self.diagnostics[:]  # only the new node's diagnostics count
        type(self).node = fx.start('smart_logger.py', '__name:=' + NODE, 'odom:=odom_in', '_topics:=imu_in',
                                   '_model:=' + self.model, '_directory:=' + (directory or self.out),
                                   '_format:=bag-lz4',
                                   '_pre:=10', '_post:=10', '_max_window:=400', '_diagnostic_period:=0.2')
        # a killed node stays registered with the master: wait for diagnostics of the new one (it publishes
        # them once its subscribers exist, after recovering leftovers)
        fx.wait_for(lambda: fx.status_values(self.diagnostics, NODE)[0] is not None, 30, 'the smart node to start')
        fx.wait_for(lambda: self.stream.connected() and fx.subscribed('/imu_in', '/' + NODE), 30,
                    'the smart node to subscribe')
        time.sleep(0.5)

    def check_final_files(self):
        files = log_format.window_files(self.out)
        for path in files:
            metadata, records = log_format.read_window(path)  # raises ValueError naming the file
            self.assertEqual(len(records), metadata['count'], path)
            self.assertTrue(records, path)
        return files

    def test_sigkill_mid_run_three_times(self):
        rng = random.Random(1)
        leftovers_held = {}
        for round_number in range(ROUNDS):
            before = set(log_format.window_files(self.out))
            self.start()
            if round_number:
                # the leftovers of the previous kill are gone: recovered into final files or kept and reported
                remaining = [leftover for leftover in leftovers_held if os.path.exists(leftover)]
                recovered = sorted(set(log_format.window_files(self.out)) - before)
                for leftover, count in leftovers_held.items():
                    if count:  # complete: renamed, same messages
                        self.assertNotIn(leftover, remaining)
                if remaining:  # kept only when reported as unrecoverable
                    fx.wait_for(lambda: 'leftovers unrecoverable' in fx.status_values(self.diagnostics, NODE)[2], 10,
                                'diagnostics')
                    values = fx.status_values(self.diagnostics, NODE)[2]
                    if int(values['leftovers unrecoverable']) < len(remaining):
                        code, out, err = fx.stop(self.node)
                        sys.stderr.write('node output:\n%s\n%s\n%s\n' % (out[-3000:], err[-3000:], values))
                    self.assertGreaterEqual(int(values['leftovers unrecoverable']), len(remaining))
                sys.stderr.write('round %d start: recovered into %s, kept %s\n' % (round_number, recovered, remaining))
            self.stream.publish(1.5 + rng.random() * 1.5, 1000.0)
            os.kill(self.node.pid, signal.SIGKILL)
            self.node.wait(10)
            self.node.communicate()
            self.assertEqual(self.node.returncode, -signal.SIGKILL)
            files = self.check_final_files()
            self.assertGreater(len(files), len(before), 'windows were written before the kill')
            leftovers_held = {}
            for leftover in recovery.scan(self.out):
                try:
                    _, records = log_format.read_window(leftover)
                    leftovers_held[leftover] = len(records)
                except ValueError:
                    leftovers_held[leftover] = 0  # cut off: rebuilt from its chunks on the next start
            sys.stderr.write('round %d: %d final files, leftovers %s\n' % (round_number, len(files), leftovers_held))

    def test_start_recovers_planted_leftovers_and_reports_them(self):
        self.out = os.path.join(self.tmp, 'planted')
        os.makedirs(self.out, exist_ok=True)
        # 1. a complete window under its temporary name (the crash came after the fsync)
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        from test_reliability import window
        path, _ = log_format.write_window(window(300, start=10 ** 6), self.out, 'json-xz')
        complete = path + log_format.TMP_MARK + '999999999'
        os.rename(path, complete)
        # 2. a bag of one chunk whose writer was SIGKILLed after the chunk's data, before rosbag wrote its
        #    sizes into the chunk header (rosbag reindex finds no message in it)
        from test_reliability import crashing_writer
        written = crashing_writer(self.out, messages=1000, kill_at=1)
        leftovers = recovery.scan(self.out)
        self.assertIn(complete, leftovers)
        self.assertEqual(len(leftovers), 2)
        before = set(log_format.window_files(self.out))
        self.start(self.out)
        fx.wait_for(lambda: fx.status_values(self.diagnostics, NODE)[2].get('leftovers recovered') is not None, 10,
                    'diagnostics')
        level, message, values = fx.status_values(self.diagnostics, NODE)
        self.assertEqual(int(values['leftovers recovered']), 2)
        self.assertEqual(values['leftovers unrecoverable'], '0')
        self.assertEqual(recovery.scan(self.out), [])
        new = sorted(set(log_format.window_files(self.out)) - before)
        self.assertIn(path, new)
        self.assertEqual(len(log_format.read_window(path)[1]), 300)
        recovered = [p for p in new if p.endswith(recovery.RECOVERED_SUFFIX + '.bag')]
        self.assertTrue(recovered, new)
        metadata, records = log_format.read_window(recovered[-1])
        self.assertTrue(metadata['recovered'])
        self.assertEqual(len(records), written)
        self.assertEqual(values['leftover messages recovered'], str(written))
        self.assertEqual(values['leftover bytes unrecoverable'], '0')
        code, out, err = fx.stop(self.node)
        type(self).node = None
        self.assertIn('crash leftover', out + err)


if __name__ == '__main__':
    rostest.rosrun(PKG, 'reliability_crash', CrashTest)
