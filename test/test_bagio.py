"""Reading bags: one clear ValueError for every bag that cannot be used; records and feature vectors."""
import shutil

import numpy as np
import pytest

from cc_log.storage.bag import bagio
from cc_log.features import FeatureConfig, OdometryFeatures, vector_length, window_vector

HUSKY = 'husky_outdoor_2015.bag'
HUSKY_ODOM = '/husky_velocity_controller/odom'
SEQUOR = 'sequor_E2_normal_safe_escape_straight.bag'


def one_line_error(call, *args):
    with pytest.raises(ValueError) as error:
        result = call(*args)
        if hasattr(result, '__next__'):
            next(result)
    message = str(error.value)
    assert '\n' not in message
    return message


def test_missing_non_bag_and_directory(tmp_path):
    missing = str(tmp_path / 'missing.bag')
    assert one_line_error(bagio.open_bag, missing) == '%s: no such bag file' % missing
    assert 'no such bag file' in one_line_error(bagio.read_messages, missing, [HUSKY_ODOM])
    text = tmp_path / 'notes.bag'
    text.write_text('not a bag at all\n')
    assert 'not a ROS bag' in one_line_error(bagio.open_bag, str(text))
    assert 'directory' in one_line_error(bagio.open_bag, str(tmp_path))


@pytest.mark.parametrize('kilobytes', [1, 64, 700, 1400])
def test_truncated_bag(real_bag, tmp_path, kilobytes):
    source = real_bag(HUSKY)
    path = tmp_path / 'cut.bag'
    with open(source, 'rb') as stream:
        path.write_bytes(stream.read(kilobytes * 1024))
    message = one_line_error(bagio.open_bag, str(path))
    assert message.startswith(str(path) + ': ') and ('truncated' in message or 'unindexed' in message)


def test_topic_checks(real_bag):
    path = real_bag(HUSKY)
    bag = bagio.open_bag(path)
    try:
        assert bagio.check_topic(bag, HUSKY_ODOM) == 'nav_msgs/Odometry'
        assert bagio.check_topic(bag, HUSKY_ODOM, 'nav_msgs/Odometry') == 'nav_msgs/Odometry'
        message = one_line_error(bagio.check_topic, bag, '/odom')
        assert '/odom is not in the bag' in message
        for topic in ('/fix', '/imu/data', HUSKY_ODOM):
            assert topic in message
        message = one_line_error(bagio.check_topic, bag, '/imu/data', 'nav_msgs/Odometry')
        assert 'sensor_msgs/Imu' in message and 'nav_msgs/Odometry' in message
    finally:
        bag.close()
    assert 'not in the bag' in one_line_error(bagio.read_messages, path, ['/nope'])


def test_read_messages_in_bag_order_with_header_stamps(real_bag):
    records = list(bagio.read_messages(real_bag(HUSKY), [HUSKY_ODOM, '/imu/data']))
    assert len(records) == 3952 + 11865
    odom = [r for r in records if r.topic == HUSKY_ODOM]
    assert odom[0].stamp == pytest.approx(odom[0].msg.header.stamp.to_sec())
    assert all(b.stamp >= a.stamp for a, b in zip(odom, odom[1:]))
    assert {r.topic for r in records} == {HUSKY_ODOM, '/imu/data'}


def test_feature_vectors_match_a_direct_computation(real_bag):
    config = FeatureConfig('motion', '50')
    stamps, X = bagio.feature_vectors(real_bag(HUSKY), HUSKY_ODOM, config, stride=10)
    assert X.shape == ((3952 - 49 + 9) // 10, vector_length(config)) and len(stamps) == len(X)
    assert np.all(np.isfinite(X))
    features = OdometryFeatures(config)
    rows = [features.row(r.msg, r.stamp) for r in bagio.read_messages(real_bag(HUSKY), [HUSKY_ODOM])]
    assert np.allclose(X[0], window_vector(rows[:50], config)) and np.allclose(X[3], window_vector(rows[30:80], config))
    with pytest.raises(ValueError, match='Odometry'):
        bagio.feature_vectors(real_bag(HUSKY), '/imu/data', config)


def test_feature_vectors_never_span_a_gap(real_bag):
    """Sequor trials are hours apart: every vector comes from one trial and a whole window of it."""
    path = real_bag(SEQUOR)
    config = FeatureConfig('motion', '1s')
    stamps, X = bagio.feature_vectors(path, '/odom', config)
    trials = {}
    for record in bagio.read_messages(path, ['/label']):
        trials.setdefault(record.msg.data, []).append(record.stamp)
    spans = [(min(s), max(s)) for s in trials.values()]
    assert len(spans) == 20 and len(stamps) > 0
    for stamp in stamps:
        start, _ = next(span for span in spans if span[0] <= stamp <= span[1])
        assert stamp - start >= 1.0 - 1e-9
    # every trial of 1 s or more gives vectors
    assert len({next(i for i, s in enumerate(spans) if s[0] <= t <= s[1]) for t in stamps}) == \
        sum(1 for s in spans if s[1] - s[0] >= 1.0)
    with pytest.raises(ValueError, match='stride'):
        bagio.feature_vectors(path, '/odom', config, stride=0)


def test_copy_of_a_real_bag_reads(real_bag, tmp_path):
    path = str(tmp_path / 'copy.bag')
    shutil.copy(real_bag(SEQUOR), path)
    bag = bagio.open_bag(path)
    assert bagio.topics_of(bag)['/odom'] == 'nav_msgs/Odometry'
    bag.close()
