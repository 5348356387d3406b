#!/usr/bin/python3
"""Test node of collect_learn_smart.test: the three modes end to end, on simulated time.

With /use_sim_time and ``rosbag play --clock`` (bags cut from the real Husky run):

1. collect: the collect logger records a nominal bag; its rotated window files hold every message once
   and its feature vectors equal the offline ones (bagio.feature_vectors);
2. learn: learn.py trains on the collected vectors (plus burst examples written with collect_bag),
   validates on a disjoint directory, prints the report and saves the model;
3. smart: the smart logger with that model watches a run with an injected anomaly, played twice, so the
   clock jumps backwards between the plays: one window per play, each exactly around the anomaly.
"""
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

import rosbag
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rostest_fixtures as fx  # noqa: E402

from cc_log.storage.bag import bagio  # noqa: E402
from cc_log.learning import learning  # noqa: E402
from cc_log.base import msg_codec  # noqa: E402
from cc_log.storage import log_format  # noqa: E402
from cc_log.logger.collector import collect_bag  # noqa: E402
from cc_log.learning.model import AnomalyModel  # noqa: E402
from cc_log.msg import AnomalyEvent  # noqa: E402

PKG = 'cc_log'
PRE = POST = 10
RATE = '10'  # rosbag play speed-up


def play(bag):
    """rosbag play --clock at RATE, waiting for a subscriber on each topic; returns when the bag is done."""
    subprocess.check_call(['rosbag', 'play', '--clock', '-q', '-r', RATE, '--wait-for-subscribers', bag],
                          stdout=subprocess.DEVNULL, timeout=40)


class CollectLearnSmartTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('collect_learn_smart_check')
        assert rospy.get_param('/use_sim_time') is True
        cls.tmp = tempfile.mkdtemp(prefix='cc_log_e2e_')
        odom, imu = fx.husky()
        cls.odom = odom
        nominal = odom[0:400]
        cls.nominal_bag = fx.write_bag(os.path.join(cls.tmp, 'nominal.bag'), nominal,
                                       fx.imu_between(imu, nominal[0], nominal[-1]))
        cls.bursts_bag = fx.write_bag(os.path.join(cls.tmp, 'bursts.bag'),
                                      fx.burst_segments(odom, (40, 110, 180, 250, 320)))
        check = odom[700:1300]
        cls.check_bag = fx.write_bag(os.path.join(cls.tmp, 'check.bag'), check)
        cls.check_bursts_bag = fx.write_bag(os.path.join(cls.tmp, 'check_bursts.bag'),
                                            fx.burst_segments(odom, range(1000, 1300, 40)))
        cls.anomalous_run = fx.inject(odom[400:700], 100)
        cls.run_bag = fx.write_bag(os.path.join(cls.tmp, 'run.bag'), cls.anomalous_run)
        cls.collect_dir = os.path.join(cls.tmp, 'collect')
        cls.model_path = os.path.join(cls.tmp, 'model.json')

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def test_1_collect(self):
        diagnostics = []
        rospy.Subscriber('/diagnostics', DiagnosticArray, diagnostics.append, queue_size=None)
        node = fx.start('collect_logger.py', '__name:=collect_logger', '_directory:=' + self.collect_dir,
                        '_window:=20', '_stride:=1', '_rotate:=15s', '_topics:=imu/data',
                        '_diagnostic_period:=0.2')
        fx.wait_for(lambda: fx.subscribed('/odom', '/collect_logger') and fx.subscribed('/imu/data', '/collect_logger'),
                    20, 'the collect logger to subscribe')
        play(self.nominal_bag)
        with rosbag.Bag(self.nominal_bag) as bag:
            count = bag.get_message_count()
        fx.wait_for(lambda: fx.received(diagnostics, 'collect_logger') >= count, 20, 'the collect logger to receive '
                    'the bag')
        code, out, err = fx.stop(node)
        self.assertEqual(code, 0, err[-2000:])
        files = log_format.window_files(self.collect_dir)
        self.assertGreaterEqual(len(files), 3)  # 40 s in 15 s files
        kept = [r for path in files for r in log_format.read_window(path)[1]]
        sent = list(bagio.read_messages(self.nominal_bag, ['/odom', '/imu/data']))
        self.assertEqual(len(kept), len(sent))
        self.assertEqual(sorted((r.stamp, r.topic) for r in kept), sorted((r.stamp, r.topic) for r in sent))
        for path in files:
            _, records = log_format.read_window(path)
            self.assertLess(records[-1].stamp - records[0].stamp, 15.0)
        vectors, config, stamps = learning.load_vectors(os.path.join(self.collect_dir, 'features'), with_stamps=True)
        offline_stamps, offline = bagio.feature_vectors(self.nominal_bag, '/odom', config, 1)
        self.assertEqual(list(vectors), ['nominal'])
        self.assertEqual(list(stamps['nominal']), list(offline_stamps))
        self.assertTrue((abs(vectors['nominal'] - offline) < 1e-12).all())

    def test_2_learn(self):
        features = os.path.join(self.collect_dir, 'features')
        collect_bag(self.bursts_bag, '/odom', features, label='anomalous', window='20', stride=1)
        validate = os.path.join(self.tmp, 'validate')
        collect_bag(self.check_bag, '/odom', validate, label='nominal', window='20', stride=1)
        collect_bag(self.check_bursts_bag, '/odom', validate, label='anomalous', window='20', stride=1)
        code, out, err = fx.finish(fx.start('learn.py', '--train', features, '--validate', validate,
                                            '--model', self.model_path), timeout=40)
        self.assertEqual(code, 0, err)
        for line in ('Total', 'TP', 'FP', 'FN', 'TN', 'Precision', 'Recall', 'Training time', self.model_path):
            self.assertIn(line, out)
        tp = int(out.split('\nTP')[1].split()[0])
        self.assertGreater(tp, 0, out)
        model = AnomalyModel.load(self.model_path)
        self.assertEqual(model.config.window, '20')

    def test_3_smart(self):
        model = AnomalyModel.load(self.model_path)
        flags = fx.flagged(model, self.anomalous_run)
        self.assertTrue(flags and 100 <= min(flags) and max(flags) <= 100 + fx.BURST + 1 + 19, flags)
        expected = fx.expected_windows(fx.fired(model, self.anomalous_run), len(self.anomalous_run), PRE, POST)
        out_dir = os.path.join(self.tmp, 'smart')
        events = []
        rospy.Subscriber('/smart_logger/anomalies', AnomalyEvent, events.append, queue_size=None)
        node = fx.start('smart_logger.py', '__name:=smart_logger', '_model:=' + self.model_path,
                        '_directory:=' + out_dir, '_pre:=%d' % PRE, '_post:=%d' % POST, '_format:=bag-lz4')
        fx.wait_for(lambda: fx.subscribed('/odom', '/smart_logger'), 20, 'the smart logger to subscribe')
        written = lambda: [e for e in events if e.event == AnomalyEvent.WRITTEN]  # noqa: E731
        for count in (1, 2):  # the second play takes the clock backwards
            play(self.run_bag)
            fx.wait_for(lambda: len(written()) >= count * len(expected), 20, 'window %d' % count)
        code, out, err = fx.stop(node)
        self.assertEqual(code, 0, err[-2000:])
        files = log_format.window_files(out_dir)
        self.assertEqual(len(files), 2 * len(expected), files)
        for path in files:
            _, records = log_format.read_window(path)
            (lo, hi), = expected
            self.assertEqual([msg_codec.to_dict(r.msg) for r in records],
                             [msg_codec.to_dict(r.msg) for r in self.anomalous_run[lo:hi + 1]])


if __name__ == '__main__':
    rostest.rosrun(PKG, 'collect_learn_smart', CollectLearnSmartTest)
