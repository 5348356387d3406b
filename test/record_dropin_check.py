#!/usr/bin/python3
"""Test node of record_dropin.test: record.launch included with bwi_logging's arguments (see the .test file).

Waits (for conditions, never a fixed time) until three context files are closed, then checks: their
odometry is exactly one message per second over at least 30 s and each file is LZ4-compressed; collect mode
wrote files; /diagnostics says there is no model yet; every closed file was handed to the upload command
exactly once, and the failing uploads show as WARN on /diagnostics.
"""
import math
import os
import sys
import unittest

import rosbag
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rostest_fixtures import wait_for  # noqa: E402

from cc_log.storage import context_track, log_format  # noqa: E402

PKG = 'cc_log'
CONTEXT_FILES = 4  # of 10 s each: the first may start late; three full ones hold 30 s


class RecordDropinTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('record_dropin_check')
        cls.directory = rospy.get_param('~directory')
        cls.context = os.path.join(cls.directory, context_track.SUBDIRECTORY)
        cls.statuses = []
        rospy.Subscriber('/diagnostics', DiagnosticArray, lambda msg: cls.statuses.extend(msg.status))
        cls.live = []  # BWI's odom_1hz, live: the odometry at 1 Hz
        rospy.Subscriber('/odom_1hz', Odometry, lambda msg: cls.live.append(msg.header.stamp.to_sec()))

    def status(self):
        return [s for s in self.statuses if s.name == 'cc_log: cc_log']

    def test_dropin(self):
        closed = wait_for(lambda: len(log_format.window_files(self.context)) >= CONTEXT_FILES and
                          log_format.window_files(self.context), 120, '%d closed context files' % CONTEXT_FILES)
        stamps = []
        for path in closed:
            with rosbag.Bag(path) as bag:
                self.assertEqual(bag.get_compression_info().compression, 'lz4', path)
                self.assertNotIn('/odom', bag.get_type_and_topic_info().topics, path)  # BWI's name, as BWI's bags
                stamps += [msg.header.stamp.to_sec() for _, msg, _ in bag.read_messages(topics=['/odom_1hz'])]
        stamps.sort()
        self.assertGreaterEqual(stamps[-1] - stamps[0], 30.0)
        seconds = [math.floor(stamp) for stamp in stamps]
        self.assertEqual(len(seconds), len(set(seconds)), 'more than one odometry message in a second')
        gaps = [b - a for a, b in zip(stamps, stamps[1:])][1:]  # the first kept may be late in its second
        self.assertTrue(all(0.98 <= gap <= 1.02 for gap in gaps), 'odometry not at 1 Hz: %s' % gaps)
        live = wait_for(lambda: self.live[1:] if len(self.live) >= 4 else None, 30, 'the live /odom_1hz topic')
        gaps = [b - a for a, b in zip(live, live[1:])]  # one message per second of stamps (100 Hz: +-10 ms)
        self.assertEqual(len(live), len(set(math.floor(stamp) for stamp in live)), live)
        self.assertTrue(all(0.95 <= gap <= 1.05 for gap in gaps), '/odom_1hz not at 1 Hz: %s' % gaps)
        # collect mode (no model at ~model) wrote files, and says why it collects
        files = wait_for(lambda: log_format.window_files(self.directory), 30, 'a collect-mode file')
        messages = [s.message for s in self.status()]
        self.assertTrue(any('no model yet' in m for m in messages), messages[-3:])
        # every closed file was uploaded once; the probe fails for context files: WARN on /diagnostics
        listing = os.path.join(self.directory, 'uploads.txt')
        expected = set(closed) | set(files)

        def uploaded():
            lines = open(listing).read().splitlines() if os.path.exists(listing) else []
            return lines if expected <= set(lines) else None
        lines = wait_for(uploaded, 30, 'uploads of %s' % sorted(expected))
        self.assertEqual(len(lines), len(set(lines)), 'a file was uploaded twice: %s' % lines)
        for line in lines:
            self.assertTrue(os.path.exists(line) and log_format.TMP_MARK not in line, line)
        warn = wait_for(lambda: [s for s in self.status() if s.level == DiagnosticStatus.WARN and
                                 'uploads failed' in s.message], 10, 'a WARN about failed uploads')
        values = dict((v.key, v.value) for v in warn[-1].values)
        self.assertIn('upload refused', values['last upload error'])
        self.assertIn('exit status 3', values['last upload error'])
        # the upload queue on /diagnostics: nothing dropped, nothing waiting once every file is uploaded
        self.assertEqual((values['uploads queued'], values['uploads dropped']), ('0', '0'))
        self.assertIn(values['uploads running'], ('0', '1', '2'))


if __name__ == '__main__':
    rostest.rosrun(PKG, 'record_dropin', RecordDropinTest, sys.argv)
