#!/usr/bin/python3
"""Test node of record_side_by_side.test: recorders side by side, reading their command line only.

Starts two `record` processes without a name (rosbag's anonymous ``record_<id>``) and one with
``__name:=record_fixed`` (whose namespace holds leftovers of an earlier run, set by the .test file), waits
(for conditions) until each has written a file, and checks: distinct ``/record_*`` nodes all alive, none of
them has a parameter on the master (the leftovers are the only ones under ``/record_fixed`` and were not
read: no subscription of their topics), and each exits 0 on SIGINT leaving the master as it found it; then two
smart-mode recorders (a configuration of their own, no model) side by side, each writing windows of its topics.
"""
import os
import sys
import unittest

import rosgraph
import rospy
import rostest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rostest_fixtures import start, stop, subscribed, wait_for  # noqa: E402

from cc_log.storage import log_format  # noqa: E402

PKG = 'cc_log'
LEFTOVERS = ['/record_fixed/context_topics', '/record_fixed/topics']


def record_nodes():
    """Names of the nodes the master knows that start with /record_."""
    _, subscribers, _ = rosgraph.Master('/record_side_check').getSystemState()
    return sorted(set(node for _, nodes in subscribers for node in nodes if node.startswith('/record_')))


def params_under(node):
    return sorted(name for name in rosgraph.Master('/record_side_check').getParamNames()
                  if name.startswith(node + '/'))


class RecordSideBySideTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('record_side_check')

    def test_recorders_side_by_side(self):
        directory = rospy.get_param('~directory')
        model = os.path.join(directory, 'none.json')
        common = ['--split', '--duration', '3', '--model', model]
        folders = [os.path.join(directory, name) for name in ('a', 'b', 'fixed')]
        nodes = []
        processes = [start('record', '/odom', '-o', folders[0] + '/', *common),
                     start('record', '/imu/data', '-o', folders[1] + '/', *common),
                     start('record', '/odom', '-o', folders[2] + '/', *(common + ['__name:=record_fixed']))]
        try:
            for folder in folders:
                wait_for(lambda: log_format.window_files(folder), 60, 'a file in %s' % folder)
            self.assertEqual([p.poll() for p in processes], [None, None, None])  # none killed another
            nodes[:] = record_nodes()
            self.assertEqual(len(nodes), 3, nodes)
            self.assertIn('/record_fixed', nodes)
            for node in nodes:
                self.assertEqual(params_under(node), LEFTOVERS if node == '/record_fixed' else [], node)
            self.assertFalse(subscribed('/stale_topic', '/record_fixed'))
            self.assertFalse(subscribed('/stale_context', '/record_fixed'))
        finally:
            results = [stop(process) for process in processes]
        for code, _, err in results:
            self.assertEqual(code, 0, err[-2000:])
        for node in nodes:  # nothing set on exit either
            self.assertEqual(params_under(node), LEFTOVERS if node == '/record_fixed' else [], node)

    def test_smart_recorders_side_by_side(self):
        """Two smart-mode recorders (one per sensor group, a window every 4 s each: no model needed) run side by
        side, each writes its own windows of its own topics, and each exits 0 on SIGINT."""
        directory = os.path.join(rospy.get_param('~directory'), 'smart')
        os.makedirs(directory)
        config = os.path.join(directory, 'periodic.yaml')
        with open(config, 'w') as stream:
            stream.write('driving_topic: odom\nwindows: {pre: 1s, post: 1s}\n'
                         'triggers: [{name: every4s, kind: periodic, every: 4s}]\n')
        folders = [os.path.join(directory, name) for name in ('odom', 'imu')]
        before = set(record_nodes())
        processes = [start('record', topic, '-o', folder + '/', '--mode', 'smart', '--config', config)
                     for topic, folder in zip(('/odom', '/imu/data'), folders)]
        try:
            for folder in folders:
                wait_for(lambda: len(log_format.window_files(folder)) >= 2, 60, 'two smart windows in %s' % folder)
            self.assertEqual([p.poll() for p in processes], [None, None])
            self.assertEqual(len(set(record_nodes()) - before), 2, record_nodes())
            for folder, topic in zip(folders, ('/odom', '/imu/data')):
                metadata, _ = log_format.read_window(log_format.window_files(folder)[0])
                self.assertEqual(metadata['trigger'], 'every4s')
                self.assertEqual(sorted(metadata['topics']), sorted({'/odom', topic}))
        finally:
            results = [stop(process) for process in processes]
        for code, _, err in results:
            self.assertEqual(code, 0, err[-2000:])


if __name__ == '__main__':
    rostest.rosrun(PKG, 'record_side_by_side', RecordSideBySideTest, sys.argv)
