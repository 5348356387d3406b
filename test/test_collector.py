"""Collect mode and learn mode on real Husky records (no roscore): rotation, vectors, learn entry."""
import os

import numpy as np
import pytest

from cc_log.learning import learning
from cc_log.base import msg_codec
from cc_log.offline import learn_main
from cc_log.storage import log_format
from cc_log.logger.collector import Collector, Rotation, VectorStream, collect_bag
from cc_log.features import FeatureConfig

bagio = pytest.importorskip('cc_log.storage.bag.bagio')  # needs rosbag (a sourced ROS environment)

HUSKY = 'husky_outdoor_2015.bag'
ODOM = '/husky_velocity_controller/odom'
IMU = '/imu/data'


@pytest.fixture(scope='module')
def husky_path():
    from conftest import REAL_DATA
    path = os.path.join(REAL_DATA, HUSKY)
    if not os.path.exists(path):
        pytest.fail('real data missing: %s' % path)
    return path


@pytest.fixture(scope='module')
def husky(husky_path):
    """The first 60 s of odometry and IMU, in bag order."""
    records = list(bagio.read_messages(husky_path, [ODOM, IMU]))
    return [r for r in records if r.stamp < records[0].stamp + 60.0]


def files_of(directory):
    return [(path,) + tuple(log_format.read_window(path)) for path in log_format.window_files(directory)]


def run(collector, records):
    for record in records:
        collector.on_message(record.topic, record.msg, record.stamp)
    assert collector.close(60)
    return collector.stats()


def test_rotation_by_count_keeps_every_message_once(husky, tmp_path):
    collector = Collector(str(tmp_path), 'json-xz', '500', driving_topic=ODOM, side_topics=[IMU], window='20',
                          stride=10)
    stats = run(collector, husky)
    files = files_of(str(tmp_path))
    sizes = [len(records) for _, _, records in files]
    assert sizes[:-1] == [500] * (len(files) - 1) and 0 < sizes[-1] <= 500
    kept = [r for _, _, records in files for r in records]
    expected = sorted(husky, key=lambda r: r.stamp)
    assert [(r.stamp, r.topic) for r in kept] == [(r.stamp, r.topic) for r in expected]
    assert all(msg_codec.to_dict(a.msg) == msg_codec.to_dict(b.msg) for a, b in zip(kept, expected))
    assert all(metadata['reason'] == 'collect' for _, metadata, _ in files)
    pieces = [log_format.parse_piece(os.path.basename(path)) for path, _, _ in files]  # each file a window of its own
    assert all(piece.name.endswith('_collect') and piece.route is None and piece.number == 0 for piece in pieces)
    assert len(log_format.window_sets([path for path, _, _ in files])) == len(files)
    assert [metadata['part'] for _, metadata, _ in files] == list(range(1, len(files) + 1))  # said, not in its name
    assert stats['files_written'] == len(files) and stats['messages_kept'] == len(husky) == stats['messages_seen']
    assert stats['stored_bytes'] == sum(os.path.getsize(path) for path, _, _ in files)
    assert stats['raw_json_bytes'] == sum(msg_codec.row_json_bytes(r.msg) for r in husky)
    assert stats['write_errors'] == stats['messages_lost'] == stats['messages_buffered'] == 0


def test_rotation_by_duration_and_by_size(husky, tmp_path):
    collector = Collector(str(tmp_path / 'time'), 'bag-lz4', '10s', driving_topic=ODOM, side_topics=[IMU],
                          window='20')
    run(collector, husky)
    files = files_of(str(tmp_path / 'time'))
    assert len(files) in (6, 7)
    for _, _, records in files:
        assert records[-1].stamp - records[0].stamp < 10.0
    assert sum(len(records) for _, _, records in files) == len(husky)

    collector = Collector(str(tmp_path / 'size'), 'json-xz', '100kB', driving_topic=ODOM, side_topics=[IMU],
                          window='20')
    run(collector, husky)
    files = files_of(str(tmp_path / 'size'))
    assert len(files) > 1
    for _, _, records in files:
        assert sum(msg_codec.row_json_bytes(r.msg) for r in records) <= 100000
    assert sum(len(records) for _, _, records in files) == len(husky)


def test_memory_budget_starts_a_new_file_before_rotation_is_due(husky, tmp_path):
    collector = Collector(str(tmp_path), 'json-xz', '60s', driving_topic=ODOM, side_topics=[IMU], window='20',
                          max_buffer_mb=0.2)
    peaks = []
    for record in husky:
        collector.on_message(record.topic, record.msg, record.stamp)
        peaks.append(collector.stats()['buffered_bytes'])
    assert collector.close(60)
    files = files_of(str(tmp_path))
    assert max(peaks) <= 0.2e6 and len(files) > 5  # one 60 s file without the budget
    assert sum(len(records) for _, _, records in files) == len(husky) == collector.stats()['messages_kept']


def test_vectors_equal_the_offline_ones(husky, husky_path, tmp_path):
    """Live collect mode and bagio.feature_vectors (cclog collect, learning) compute the same vectors."""
    odom = [r for r in husky if r.topic == ODOM]
    collector = Collector(str(tmp_path), 'json-xz', '60s', driving_topic=ODOM, side_topics=[IMU], window='20',
                          stride=7, label='nominal')
    stats = run(collector, husky)
    vectors, config, stamps = learning.load_vectors(str(tmp_path / 'features'), with_stamps=True)
    assert config == FeatureConfig('motion', '20') and list(vectors) == ['nominal']
    offline_stamps, offline = bagio.feature_vectors(husky_path, ODOM, config, 7)
    n = len(vectors['nominal'])
    assert n == stats['vectors_written'] == len([s for s in offline_stamps if s <= odom[-1].stamp])
    assert np.array_equal(stamps['nominal'], offline_stamps[:n])
    assert np.allclose(vectors['nominal'], offline[:n], rtol=0, atol=1e-12)


def test_collect_bag_writes_vectors_per_label(husky_path, tmp_path):
    summary = collect_bag(husky_path, ODOM, str(tmp_path), label='drive', window='2s', stride=50)
    assert summary['directory'] == str(tmp_path / 'drive')
    vectors, config = learning.load_vectors(str(tmp_path))
    assert config.window == '2s' and len(vectors['drive']) == summary['vectors'] > 50


def test_time_jumping_back_starts_a_new_file(husky, tmp_path):
    odom = [r for r in husky if r.topic == ODOM][:100]
    collector = Collector(str(tmp_path), 'json-xz', '1000', driving_topic=ODOM, window='20')
    stats = run(collector, odom + odom)
    files = files_of(str(tmp_path))
    assert stats['time_resets'] == 1
    assert [[r.stamp for r in records] for _, _, records in files] == [[r.stamp for r in odom]] * 2


def test_bad_configuration_names_the_parameter(tmp_path):
    for kwargs, name in (({'rotate': '0'}, 'rotate'), ({'rotate': 'often'}, 'rotate'), ({'fmt': 'zip'}, 'format'),
                         ({'label': '../up'}, 'label'), ({'stride': '1s'}, 'stride'), ({'stride': 0}, 'stride'),
                         ({'window': '0'}, 'window'), ({'feature_set': 'pixels'}, 'feature_set')):
        with pytest.raises(ValueError) as error:
            Collector(str(tmp_path), **kwargs)
        assert str(error.value).startswith(name), str(error.value)
    assert Rotation.parse('20MB') == Rotation(None, 20000000)
    assert VectorStream(FeatureConfig('motion', '5'), 3).stride == 3


# -- learn mode ---------------------------------------------------------------------------------------------

def test_learn_trains_validates_and_saves(husky_path, tmp_path, capsys):
    records = list(bagio.read_messages(husky_path, [ODOM]))
    config = FeatureConfig('motion', '20')
    stamps, X = bagio.feature_vectors(husky_path, ODOM, config, 2)
    half = len(X) // 2
    for stamp, vector in zip(stamps[:half], X[:half]):
        learning.write_vector(str(tmp_path / 'train'), 'nominal', stamp, vector, config)
    for stamp, vector in zip(stamps[half + 20:], X[half + 20:]):
        learning.write_vector(str(tmp_path / 'check'), 'nominal', stamp, vector, config)
    model_path = str(tmp_path / 'model.json')
    status = learn_main.main(['--train', str(tmp_path / 'train'), '--validate', str(tmp_path / 'check'),
                              '--model', model_path, '__name:=learn'])
    out = capsys.readouterr().out
    assert status == 0 and os.path.exists(model_path)
    assert 'Precision' in out and 'Recall' in out and model_path in out
    from cc_log.learning.model import AnomalyModel
    model = AnomalyModel.load(model_path)
    assert model.config == config and len(records) > 0
    tn = int(out.split('TN')[1].split()[0])
    assert tn + int(out.split('FP')[1].split()[0]) == len(X) - half - 20


def test_learn_refuses_overlapping_sets(husky_path, tmp_path, capsys):
    config = FeatureConfig('motion', '20')
    stamps, X = bagio.feature_vectors(husky_path, ODOM, config, 10)
    for stamp, vector in zip(stamps, X):
        learning.write_vector(str(tmp_path / 'all'), 'nominal', stamp, vector, config)
    for stamp, vector in zip(stamps[:5], X[:5]):
        learning.write_vector(str(tmp_path / 'copy'), 'nominal', stamp, vector, config)
    model = str(tmp_path / 'model.json')
    assert learn_main.main(['--train', str(tmp_path / 'all'), '--validate', str(tmp_path / 'all'),
                            '--model', model]) == 1
    assert 'validate:' in capsys.readouterr().err
    assert learn_main.main(['--train', str(tmp_path / 'all'), '--validate', str(tmp_path / 'copy'),
                            '--model', model]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and '5 vector(s)' in err
    assert learn_main.main(['--train', str(tmp_path / 'missing'), '--validate', str(tmp_path / 'copy'),
                            '--model', model]) == 1
    assert not os.path.exists(model)


def test_json_xz_precision_rounds_collected_windows(husky, tmp_path):
    """format_options (the configuration's json_xz.precision) reach every collected window."""
    from cc_log.storage.formats import json_xz
    precision = {'linear_acceleration.*': 1e-3, 'pose.pose.position.*': 1e-4}
    collector = Collector(str(tmp_path), 'json-xz', '500', driving_topic=ODOM, side_topics=[IMU], window='20',
                          stride=10, format_options={'precision': precision})
    run(collector, husky)
    files = files_of(str(tmp_path))
    assert files and all(metadata['precision'] == precision for _, metadata, _ in files)
    kept = [r for _, _, records in files for r in records]
    errors = json_xz.max_errors(sorted(husky, key=lambda r: r.stamp), kept)
    assert 0 < errors[IMU]['linear_acceleration.x'] <= 0.5e-3 * 1.001
    assert 0 < errors[ODOM]['pose.pose.position.x'] <= 0.5e-4 * 1.001
    assert errors[IMU]['angular_velocity.x'] == errors[ODOM]['twist.twist.linear.x'] == 0.0
