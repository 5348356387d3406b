"""How much rospy reads from a topic's socket at a time: small reads for light topics (a 1 MB read costs more
than a 700-byte odometry message), large ones only where the messages are large. Pure: no roscore (a rospy
Subscriber and a TCPROS connection object are made, never connected)."""
import pytest

rospy = pytest.importorskip('rospy')
from rospy.impl.tcpros_base import TCPROSTransport  # noqa: E402
from rospy.impl.tcpros_pubsub import TCPROSSub  # noqa: E402

from cc_log.buffer.window_prep import HEAVY_BYTES  # noqa: E402
from cc_log.nodes import intake  # noqa: E402


@pytest.mark.parametrize('msg_type, size', [('nav_msgs/Odometry', 700), ('sensor_msgs/Imu', 300),
                                            ('diagnostic_msgs/DiagnosticArray', 4000),
                                            ('my_msgs/Custom', HEAVY_BYTES - 1)])
def test_light_topics_are_read_in_small_reads(msg_type, size):
    assert intake.receive_bytes(msg_type, size) == intake.SMALL_RECEIVE_BYTES == 1 << 16


@pytest.mark.parametrize('msg_type, size', [('sensor_msgs/Image', 100), ('sensor_msgs/CompressedImage', 30000),
                                            ('sensor_msgs/PointCloud2', 10), ('sensor_msgs/LaserScan', 6000),
                                            ('my_msgs/Custom', HEAVY_BYTES)])
def test_heavy_types_and_large_messages_are_read_in_large_reads(msg_type, size):
    assert intake.receive_bytes(msg_type, size) == intake.LARGE_RECEIVE_BYTES == 1 << 20


def test_set_receive_bytes_sizes_the_open_connections_and_those_to_come():
    topic = '/cc_log_test_reads'
    subscriber = rospy.Subscriber(topic, rospy.AnyMsg, lambda msg: None, queue_size=None,
                                  buff_size=intake.SMALL_RECEIVE_BYTES)
    try:
        connection = TCPROSTransport(TCPROSSub(topic, rospy.AnyMsg, buff_size=subscriber.impl.buff_size), topic)
        subscriber.impl.connections.append(connection)
        assert connection.protocol.buff_size == intake.SMALL_RECEIVE_BYTES
        intake.set_receive_bytes(subscriber, intake.LARGE_RECEIVE_BYTES)
        assert subscriber.impl.buff_size == intake.LARGE_RECEIVE_BYTES  # connections to come
        assert connection.protocol.buff_size == intake.LARGE_RECEIVE_BYTES  # read before its next recv
        subscriber.impl.connections.remove(connection)
    finally:
        subscriber.unregister()


class Sink(object):
    """Takes the intake's batches (as SmartLogger.on_records)."""

    def __init__(self):
        self.records = []

    def on_records(self, records):
        self.records.extend(records)


def test_the_feeder_sizes_a_topics_reads_by_its_first_message_and_makes_them_large_at_a_heavy_one():
    import threading
    from cc_log.base.raw_message import class_header
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Image
    topics = {'/cc_log_test_odom': Odometry, '/cc_log_test_camera': Image, '/cc_log_test_grows': Odometry}
    sink = Sink()
    feeder = intake.Intake.__new__(intake.Intake)  # the feeder's part, with real subscribers, never connected
    feeder.sink, feeder.decoder, feeder.dropped = sink, intake.MessageDecoder(), 0
    feeder._typed, feeder._large_reads, feeder._lock = set(), set(), threading.Lock()
    feeder.subscribers = {topic: rospy.Subscriber(topic, rospy.AnyMsg, lambda msg: None, queue_size=None,
                                                  buff_size=intake.SMALL_RECEIVE_BYTES) for topic in topics}
    batch = []
    for topic, size in (('/cc_log_test_odom', 700), ('/cc_log_test_camera', 1000), ('/cc_log_test_grows', 700),
                        ('/cc_log_test_odom', 700), ('/cc_log_test_grows', HEAVY_BYTES)):
        msg = rospy.AnyMsg()
        msg._buff, msg._connection_header = bytes(size), class_header(topic, topics[topic])
        batch.append((topic, msg, rospy.Time(1, 0)))
    try:
        assert feeder._feed_records(batch) is True
        reads = {topic: subscriber.impl.buff_size for topic, subscriber in feeder.subscribers.items()}
    finally:
        for subscriber in feeder.subscribers.values():
            subscriber.unregister()
    assert len(sink.records) == 5 and feeder.dropped == 0
    assert reads == {'/cc_log_test_odom': intake.SMALL_RECEIVE_BYTES, '/cc_log_test_camera': intake.LARGE_RECEIVE_BYTES,
                     '/cc_log_test_grows': intake.LARGE_RECEIVE_BYTES}
