"""How much rospy reads from a topic's socket at a time: small reads for light topics (a 1 MB read costs more
than a 700-byte odometry message), large ones only where the messages are large. Pure: no roscore (a rospy
Subscriber and a TCPROS connection object are made, never connected)."""
import pytest

rospy = pytest.importorskip('rospy')
from rospy.impl.tcpros_base import TCPROSTransport  # noqa: E402
from rospy.impl.tcpros_pubsub import TCPROSSub  # noqa: E402

from cc_log.core.window_prep import HEAVY_BYTES  # noqa: E402
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
