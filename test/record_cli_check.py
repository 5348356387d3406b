#!/usr/bin/python3
"""Test node of record_cli.test: `rosrun cc_log record` with rosbag record's flags (see the .test file).

Waits (for conditions) until two split files are written, then checks they are LZ4 bags in the directory of
-o holding both topics over about 5 s each, that the context track closed a file, and that the node
(named as launched) publishes its status with the free-space floor of -L.
"""
import os
import socket
import sys
import unittest

import rosbag
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import String

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rostest_fixtures import finish, start, stop, subscribed, wait_for  # noqa: E402

from cc_log.storage import context_track, log_format  # noqa: E402

PKG = 'cc_log'


class RecordCliTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('record_cli_check')

    def test_record(self):
        directory = rospy.get_param('~directory')
        statuses = []
        rospy.Subscriber('/diagnostics', DiagnosticArray, lambda msg: statuses.extend(msg.status))
        files = wait_for(lambda: len(log_format.window_files(directory)) >= 2 and log_format.window_files(directory),
                         60, 'two split files')
        for path in files[:2]:
            self.assertTrue(path.endswith('.bag'), path)
            with rosbag.Bag(path) as bag:
                self.assertEqual(bag.get_compression_info().compression, 'lz4')
                topics = bag.get_type_and_topic_info().topics
                self.assertIn('/odom', topics)
                self.assertIn('/imu/data', topics)
                self.assertAlmostEqual(bag.get_end_time() - bag.get_start_time(), 5.0, delta=0.5)
        wait_for(lambda: log_format.window_files(os.path.join(directory, context_track.SUBDIRECTORY)), 30,
                 'a context file')
        mine = wait_for(lambda: [s for s in statuses if s.name == 'cc_log: record'], 10, 'the node\'s status')
        values = dict((v.key, v.value) for v in mine[-1].values)
        self.assertIn('context topics', values)
        self.assertEqual(values['min free bytes'], str(1 << 20))  # -L 1M
        self.assertIn('no model yet', mine[-1].message)

    def test_record_all_but_excluded(self):
        directory = os.path.join(rospy.get_param('~directory'), 'all')
        [path] = wait_for(lambda: log_format.window_files(directory)[:1], 60, 'a file of record -a')
        with rosbag.Bag(path) as bag:
            topics = set(bag.get_type_and_topic_info().topics)
        self.assertIn('/odom', topics)  # subscribed at start or by the watcher when it appeared
        self.assertFalse([topic for topic in topics if topic.startswith('/imu')], topics)  # -x '/imu.*'

    def test_limit_of_a_node_s_topics(self):
        """-l 3 --node: the topics this test node subscribes to (/diagnostics), then it stops by itself."""
        rospy.Subscriber('/diagnostics', DiagnosticArray, lambda msg: None)
        directory = os.path.join(rospy.get_param('~directory'), 'limit')
        wait_for(lambda: subscribed('/diagnostics', rospy.get_name()), 10, 'this node subscribed')
        process = start('record', '--node', rospy.get_name(), '-l', '3', '-o', directory + '/',
                        '--model', os.path.join(directory, 'none.json'))
        code, out, err = finish(process, 60)
        self.assertEqual(code, 0, err[-2000:])
        self.assertIn('--limit 3 reached on /diagnostics', out)
        [path] = log_format.window_files(directory)
        with rosbag.Bag(path) as bag:
            self.assertGreaterEqual(bag.get_message_count('/diagnostics'), 3)

    def test_duration_without_split_stops(self):
        """--duration 4 without --split: it stops by itself after 4 s; -p: the directory on begin_write."""
        directory = os.path.join(rospy.get_param('~directory'), 'duration')
        announced = []
        listener = rospy.Subscriber('/begin_write', String, lambda msg: announced.append(msg.data))
        began = rospy.get_time()
        process = start('record', '/odom', '--duration', '4', '-o', directory + '/', '-p',
                        '--model', os.path.join(directory, 'none.json'))
        try:
            self.assertEqual(wait_for(lambda: announced, 30, 'begin_write'), [directory])
        finally:
            listener.unregister()  # not a topic of this node for --node below
        code, out, err = finish(process, 60)
        self.assertEqual(code, 0, err[-2000:])
        self.assertIn('--duration 4s reached', out)
        self.assertGreaterEqual(out.count('[INFO]'), 10)  # what -q leaves out (test_prefix_max_splits_quiet)
        self.assertGreaterEqual(rospy.get_time() - began, 4.0)
        [path] = log_format.window_files(directory)
        with rosbag.Bag(path) as bag:
            self.assertAlmostEqual(bag.get_end_time() - bag.get_start_time(), 4.0, delta=1.0)

    def test_prefix_max_splits_quiet_tcpnodelay(self):
        """-o DIR/run: files DIR/run_<UTC>_<reason>.bag; --max-splits 2: the newest two kept (the oldest deleted
        as new ones are written); -q: no INFO line (there are more than 10 without it); --tcpnodelay: the
        publisher's socket to it has TCP_NODELAY (rospy sets it for a subscriber that asks)."""
        directory = os.path.join(rospy.get_param('~directory'), 'prefix')
        probe = rospy.Publisher('/record_cli_probe', String, queue_size=1)
        process = start('record', '/odom', '/record_cli_probe', '-o', os.path.join(directory, 'run'), '--split',
                        '--duration', '1', '--max-splits', '2', '-q', '--tcpnodelay', '--model',
                        os.path.join(directory, 'none.json'), '__name:=record_prefix')
        try:
            mine = wait_for(lambda: [c for c in probe.impl.connections if c.endpoint_id == '/record_prefix'], 30,
                            'the recorder subscribed to the probe')
            self.assertEqual(mine[0].socket.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY), 1)
            for other in [c for c in probe.impl.connections if c.endpoint_id != '/record_prefix']:  # record -a
                self.assertEqual(other.socket.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY), 0)
        except BaseException:
            stop(process)
            raise
        finally:
            probe.unregister()  # not a topic of this node for --node
        seen = set()

        def written(count):
            seen.update(log_format.window_files(directory, 'run_'))
            return len(seen) >= count
        try:
            wait_for(lambda: written(4), 60, 'four files of -o PREFIX')
        finally:
            code, out, err = stop(process)
        self.assertEqual(code, 0, err[-2000:])
        files = log_format.window_files(directory, 'run_')
        self.assertEqual(len(files), 2, files)
        self.assertEqual(files, sorted(seen.union(files))[-2:])  # the newest
        self.assertEqual(log_format.window_files(directory), [])  # no cc_log_* file
        with rosbag.Bag(files[-1]) as bag:
            self.assertGreater(bag.get_message_count('/odom'), 0)
        self.assertNotIn('[INFO]', out + err)


if __name__ == '__main__':
    rostest.rosrun(PKG, 'record_cli', RecordCliTest, sys.argv)
