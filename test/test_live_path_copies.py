"""The live path's work per message, counted (not timed): records fed through ``SmartLogger.on_records`` as the
intake hands them over (rospy's serialized bytes) are decoded only where a trigger reads them (the driving
topic), never on the other topics, and their payloads reach the bag writer as the very objects fed (no copy
inside cc_log before the one into the LZ4 chunk). Pure: no roscore; the records come from a simulated bag read
by rosbag."""
import pytest

from cc_log import sim
from cc_log.learning import learning
from cc_log.base.records import Record
from cc_log.logger.smart import SmartLogger
from cc_log.features import FeatureConfig
from cc_log.storage import log_format, window_info
from cc_log.storage.bag import bag_writer

bagio = pytest.importorskip('cc_log.storage.bag.bagio')  # needs rosbag (a sourced ROS environment)
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402


class Payload(bytes):
    """Serialized bytes as the intake hands them over; a copy of them (bytes(p), p[:], a join) is plain bytes."""


class LargePayload(bytearray):
    """... as the intake's reader hands over a message larger than its buffer (nodes/tcpros_receive); a copy is
    a plain bytearray or bytes."""


@pytest.fixture(scope='module')
def case(tmp_path_factory):
    """Records of a 1-minute simulated bag (100 Hz odometry + IMU, one anomaly) with Payload bytes, and a motion
    model trained on a nominal run."""
    tmp = tmp_path_factory.mktemp('live_path')
    train, path = str(tmp / 'train.bag'), str(tmp / 'run.bag')
    sim.simulate_to_bag(train, sim.SimConfig(seed=2, minutes=2, anomalies=0))
    sim.simulate_to_bag(path, sim.SimConfig(seed=1, minutes=1, anomalies=1, imu=True))
    config = FeatureConfig('motion', '300')
    _, X = bagio.feature_vectors(train, sim.ODOM_TOPIC, config, stride=10)
    model, _ = learning.train(X, config=config)
    return model, list(bagio.read_raw(path, [sim.ODOM_TOPIC, sim.IMU_TOPIC]))


def counting(counts, key, method):
    def counted(self, *args, **kwargs):
        counts[key] += 1
        return method(self, *args, **kwargs)
    return counted


@pytest.mark.parametrize('payload', [Payload, LargePayload])
def test_the_live_path_decodes_only_the_driving_topic_and_copies_no_payload(case, tmp_path, monkeypatch, payload):
    model, read = case
    records = [Record(record.stamp, record.topic, None, 0, payload(record.raw), record.connection) for record in read]
    counts = {'odometry': 0, 'imu': 0}
    for key, cls in (('odometry', Odometry), ('imu', Imu)):
        for name in ('deserialize', 'deserialize_numpy'):
            monkeypatch.setattr(cls, name, counting(counts, key, getattr(cls, name)))
    written = []
    write = bag_writer.BagStream.write

    def writes(self, topic, secs, nsecs, data, header):
        written.append((topic, data))
        return write(self, topic, secs, nsecs, data, header)
    monkeypatch.setattr(bag_writer.BagStream, 'write', writes)
    logger = SmartLogger(model, str(tmp_path), 'bag-lz4', '2s', '2s', driving_topic=sim.ODOM_TOPIC,
                         side_topics=[sim.IMU_TOPIC], background=False)
    middle = len(records) // 2
    for k in range(0, len(records), 64):
        logger.on_records(records[k:k + 64])
        if k <= middle < k + 64:
            ok, why = logger.trigger_now('manual')
            assert ok, why
    logger.close()
    decoded = dict(counts)
    paths = log_format.window_files(str(tmp_path))
    assert paths
    # the writer decodes a sample of each topic of a window for its metadata (window_info.Contents): exactly it
    sample = sum(sampled(log_format.read_metadata(path)['counts'][sim.IMU_TOPIC]) for path in paths)
    assert decoded['imu'] == sample  # and none on the message path
    assert decoded['odometry'] > len(paths) * window_info.JSON_SAMPLE_FIRST  # the classifier reads the driving topic
    fed = {id(record.raw) for record in records}
    imu = {id(record.raw) for record in records if record.topic == sim.IMU_TOPIC}
    payloads = [data for topic, data in written if topic in (sim.ODOM_TOPIC, sim.IMU_TOPIC)]
    assert payloads and all(id(data) in fed for data in payloads)  # the very objects fed: none copied
    assert all(type(data) is payload for data in payloads)
    assert any(id(data) in imu for data in payloads)  # side-topic payloads were written, undecoded


def sampled(count):
    """How many of a topic's ``count`` records of a window the metadata's summary decodes."""
    return sum(1 for seen in range(count)
               if seen < window_info.JSON_SAMPLE_FIRST or seen % window_info.JSON_SAMPLE_EVERY == 0)
