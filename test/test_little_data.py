"""Learning from little data: 20 s of real nominal driving through ``cclog collect`` and ``cclog learn``."""
import pytest

from cc_log.logger import collector
from cc_log.learning import learning

from test_cli import HUSKY, HUSKY_ODOM, fails, ok_json

rosbag = pytest.importorskip('rosbag')


@pytest.fixture
def short_bag(real_bag, tmp_path):
    """The first 20 s of the Husky run's odometry (10 Hz) in a bag of its own."""
    path = str(tmp_path / 'short.bag')
    with rosbag.Bag(real_bag(HUSKY)) as source, rosbag.Bag(path, 'w') as out:
        start = source.get_start_time()
        for topic, msg, t in source.read_messages(topics=[HUSKY_ODOM]):
            if t.to_sec() - start > 20.0:
                break
            out.write(topic, msg, t)
    return path


def test_collect_chooses_a_smaller_stride_for_a_short_run_and_learn_trains_on_it(short_bag, tmp_path):
    collect = ok_json('collect', short_bag, '--topic', HUSKY_ODOM, '--out', tmp_path / 'train', '--window', '5s')
    assert collect['stride'] < collector.DEFAULT_STRIDE
    assert collect['vectors'] >= 100  # 15 s of whole 5 s windows at 10 Hz: about 150 vectors at stride 1
    learn = ok_json('learn', '--train', tmp_path / 'train', '--model', tmp_path / 'model.json')
    assert learn['info']['vectors_nominal'] == collect['vectors'] and learn['config']['window'] == '5s'
    assert (tmp_path / 'model.json').exists()


def test_a_given_stride_is_kept_and_too_few_vectors_say_how_to_get_more(short_bag, tmp_path):
    collect = ok_json('collect', short_bag, '--topic', HUSKY_ODOM, '--out', tmp_path / 'train', '--window', '5s',
                      '--stride', '25')
    assert collect['stride'] == 25 and 0 < collect['vectors'] < learning.MIN_VECTORS
    line = fails('learn', '--train', tmp_path / 'train', '--model', tmp_path / 'model.json')
    assert 'need at least %d' % learning.MIN_VECTORS in line and '--stride 1' in line


def test_auto_stride():
    assert collector.auto_stride(500, 25) == 25
    assert collector.auto_stride(6, 25) == 1
    assert collector.auto_stride(100, 25) == 12
    assert collector.auto_stride(0, 25) == 1
