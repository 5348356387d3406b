"""SmartLogger's cheaper per-message paths give the same results as the reference functions."""
import glob
import math
import os

import pytest

from cc_log import features
from cc_log.base import msg_codec
from cc_log.logger import smart

REAL = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..', 'shared', 'data', 'real')


def test_raw_bytes_equal_row_json_bytes_on_real_bags():
    rosbag = pytest.importorskip('rosbag')
    bags = sorted(glob.glob(os.path.join(REAL, '**', '*.bag'), recursive=True))
    if not bags:
        pytest.skip('no real bags')
    counter = msg_codec.RowJsonCounter()
    checked = 0
    for path in bags:
        with rosbag.Bag(path) as bag:
            for _, msg, _ in bag.read_messages():
                assert counter.count(msg) == msg_codec.row_json_bytes(msg), (path, msg._type)
                checked += 1
    assert checked > 1000


def test_raw_bytes_edge_values():
    from nav_msgs.msg import Odometry
    counter = msg_codec.RowJsonCounter()
    msg = Odometry()
    msg.header.frame_id = 'odom \u00e9"\\'
    assert counter.count(msg) == msg_codec.row_json_bytes(msg)
    for value in (float('nan'), float('inf'), -0.0, 1, 1e300, 2.5e-17):
        msg.pose.pose.position.x = value
        assert counter.count(msg) == msg_codec.row_json_bytes(msg), value
        cov = [0.0] * 36
        cov[3] = value
        msg.pose.covariance = cov
        assert counter.count(msg) == msg_codec.row_json_bytes(msg), value
    msg.pose.covariance = [0.0] * 35  # wrong length: falls back to msg_codec
    assert counter.count(msg) == msg_codec.row_json_bytes(msg)


def test_row_values_equal_row():
    from nav_msgs.msg import Odometry
    a, b = features.OdometryFeatures(), features.OdometryFeatures()
    msg = Odometry()
    msg.pose.pose.orientation.w = 1.0
    for i in range(30):
        msg.pose.pose.position.x = 0.1 * i * i
        msg.twist.twist.linear.x = 0.2 * i if i != 7 else float('nan')
        row = a.row(msg, 10.0 + 0.05 * i)
        values = b.row_values(msg, 10.0 + 0.05 * i)
        assert list(row) == list(values)
        assert all(math.isfinite(x) for x in values)


class _CountingModel(object):
    def __init__(self, window='10'):
        self.config = features.FeatureConfig('motion', window)
        self.threshold = 0.0
        self.vectors = []

    def is_anomalous(self, vector):
        self.vectors.append(vector)
        return False, 1.0


def _feed(logger, n, rate):
    from nav_msgs.msg import Odometry
    msg = Odometry()
    msg.pose.pose.orientation.w = 1.0
    rows = []
    for i in range(n):
        msg.pose.pose.position.x = 0.01 * i
        msg.twist.twist.linear.x = math.sin(i)
        stamp = 100.0 + i / rate
        logger.on_message('odom', msg, stamp)
        rows.append(stamp)
    logger.close()


@pytest.mark.parametrize('every, window, rate, expected', [
    ('1', '10', 100.0, 91), ('5', '10', 100.0, 19), ('50ms', '10', 100.0, 19), ('50ms', '10', 10.0, 91),
    ('50ms', '0.5s', 100.0, 10)])
def test_classify_every(tmp_path, every, window, rate, expected):
    model = _CountingModel(window)
    logger = smart.SmartLogger(model, str(tmp_path), classify_every=every, background=False)
    _feed(logger, 100, rate)
    assert logger.stats()['classifier_calls'] == len(model.vectors) == expected


def test_classify_every_vectors_equal_window_vector(tmp_path):
    """The ring-array window gives window_vector of the same rows (every message scored)."""
    from nav_msgs.msg import Odometry
    model = _CountingModel('10')
    logger = smart.SmartLogger(model, str(tmp_path), classify_every='1', background=False)
    reference = features.OdometryFeatures(model.config)
    msg = Odometry()
    msg.pose.pose.orientation.w = 1.0
    rows, expected = [], []
    for i in range(40):
        msg.twist.twist.angular.z = math.cos(i)
        logger.on_message('odom', msg, 5.0 + 0.01 * i)
        rows.append(reference.row(msg, 5.0 + 0.01 * i))
        if len(rows) >= 10:
            expected.append(features.window_vector(rows[-10:], model.config))
    logger.close()
    assert len(model.vectors) == len(expected)
    for got, want in zip(model.vectors, expected):
        assert max(abs(got - want)) < 1e-9


def test_classify_every_zero_refused(tmp_path):
    with pytest.raises(ValueError, match='classify_every'):
        smart.SmartLogger(_CountingModel(), str(tmp_path), classify_every='0')
