#!/usr/bin/python3
"""Test node of fast_receive.test: the smart logger reads its topics with cc_log's own TCPROS reader
(nodes/tcpros_receive, ``~fast_receive`` on by default) from real publishers.

Before the node starts, a latched ``/note`` (std_msgs/String) is published once. The node (a real process, bag-lz4
windows) then gets real Husky odometry, restamped to now, with a 640x480 rgb8 camera image (0.9 MB, each of
different content) after every tenth message, and ``/restarted`` (std_msgs/String) from a publisher process that
is killed and started again (rospy's reconnection: the master's publisherUpdate, a new connection). After a
manual ``~trigger`` the window must hold every message published, exactly once, in order and byte-identical to
what was serialized: the odometry, the images, ``/note`` and both publishers' ``/restarted`` messages. And an
``Intake`` in this process hands its sink a large message as the ``bytearray`` the reader filled (rospy's receive,
``fast_receive`` off, hands over ``bytes``), every message equal to what was published.

``fast_receive_check.py --publish TOPIC COUNT TAG`` is the ``/restarted`` publisher: it publishes ``TAG-0`` ..
``TAG-<COUNT-1>`` once a subscriber is connected, then waits to be killed.
"""
import io
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import unittest

import rosbag
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Image
from std_msgs.msg import String
from std_srvs.srv import Trigger

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rostest_fixtures as fx  # noqa: E402

from cc_log.msg import AnomalyEvent  # noqa: E402
from cc_log.nodes import intake  # noqa: E402

PKG = 'cc_log'
NODE = 'fast_receive_node'
ODOMETRY = 200   # odometry messages before the trigger
IMAGE_EVERY = 10  # an image after every tenth of them
RESTARTED = 30   # /restarted messages of each publisher
PRE, POST = 250, 5
CONFIG = """
topics: [/camera/image_raw, /note, /restarted]
driving_topic: /odom
windows: {pre: %d, post: %d}
triggers:
  - {name: bumper, kind: rule, topic: /bumper, arrival: true}
""" % (PRE, POST)


def serialized(msg):
    buffer = io.BytesIO()
    msg.serialize(buffer)
    return buffer.getvalue()


def publish_until_killed(topic, count, tag):
    rospy.init_node('cc_log_test_restarted')
    publisher = rospy.Publisher(topic, String, queue_size=1000)
    fx.wait_for(lambda: publisher.get_num_connections() >= 1, 30, 'a subscriber of %s' % topic)
    for k in range(count):
        publisher.publish(String(data='%s-%d' % (tag, k)))
    rospy.spin()


class Sink(object):
    """Takes the intake's batches (as SmartLogger.on_records)."""

    def __init__(self):
        self.records = []

    def on_records(self, records):
        self.records.extend(records)


class FastReceiveTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('fast_receive_check')
        cls.tmp = tempfile.mkdtemp(prefix='cc_log_fast_receive_')
        config = os.path.join(cls.tmp, 'fast_receive.yaml')
        with open(config, 'w') as stream:
            stream.write(CONFIG)
        cls.note = String(data='published before the node started')
        cls.note_pub = rospy.Publisher('/note', String, queue_size=1, latch=True)
        cls.note_pub.publish(cls.note)
        cls.odom_pub = rospy.Publisher('/odom', Odometry, queue_size=10000)
        cls.image_pub = rospy.Publisher('/camera/image_raw', Image, queue_size=1000)
        cls.events, cls.diagnostics = [], []
        rospy.Subscriber('/%s/anomalies' % NODE, AnomalyEvent, cls.events.append, queue_size=None)
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.diagnostics.append, queue_size=None)
        cls.node = fx.start('smart_logger.py', '__name:=' + NODE, '_config:=' + config, '_format:=bag-lz4',
                            '_directory:=' + os.path.join(cls.tmp, 'windows'), '_diagnostic_period:=0.1')
        rospy.wait_for_service('/%s/trigger' % NODE, timeout=30)
        fx.wait_for(lambda: all(p.get_num_connections() for p in (cls.note_pub, cls.odom_pub, cls.image_pub)),
                    20, 'the smart logger to subscribe')
        cls.odom = fx.husky()[0][:ODOMETRY + PRE + POST + 10]
        cls.publishers = []

    @classmethod
    def tearDownClass(cls):
        for process in cls.publishers:
            if process.poll() is None:
                process.kill()
            process.wait()
        code, out, err = fx.stop(cls.node)
        sys.stderr.write(err[-3000:])
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def publish_odometry(self, records, images=None):
        """Publish ``records`` restamped to now (and an image after every ``IMAGE_EVERY``th, kept in
        ``images``); their serialized bytes."""
        sent = []
        for k, record in enumerate(records):
            record.msg.header.stamp = rospy.Time.now()
            self.odom_pub.publish(record.msg)
            sent.append(serialized(record.msg))
            if images is not None and k % IMAGE_EVERY == IMAGE_EVERY - 1:
                image = Image(height=480, width=640, encoding='rgb8', step=1920,
                              data=bytes([len(images) % 256]) * 921600)
                image.header.stamp, image.header.seq = rospy.Time.now(), len(images)
                self.image_pub.publish(image)
                images.append(serialized(image))
            time.sleep(0.004)
        return sent

    def received(self, count, what):
        fx.wait_for(lambda: fx.received(self.diagnostics, NODE) >= count, 30, what)

    def restarted_publisher(self, tag):
        process = subprocess.Popen([sys.executable, os.path.abspath(__file__), '--publish', '/restarted',
                                    str(RESTARTED), tag])
        self.publishers.append(process)
        return process

    def test_every_message_arrives_once_in_order_byte_identical_and_a_restarted_publisher_is_read_again(self):
        images = []
        odometry = self.publish_odometry(self.odom[:ODOMETRY // 2], images)
        self.received(1 + len(odometry) + len(images), 'the first odometry and images')
        first = self.restarted_publisher('a')
        self.received(1 + len(odometry) + len(images) + RESTARTED, "the first publisher's /restarted")
        first.send_signal(signal.SIGKILL)  # dies without unregistering
        first.wait()
        self.restarted_publisher('b')  # the same node name: the master hands its new address on
        self.received(1 + len(odometry) + len(images) + 2 * RESTARTED, "the restarted publisher's /restarted")
        odometry += self.publish_odometry(self.odom[ODOMETRY // 2:ODOMETRY], images)
        self.received(1 + len(odometry) + len(images) + 2 * RESTARTED, 'all odometry and images')
        response = rospy.ServiceProxy('/%s/trigger' % NODE, Trigger)()
        self.assertTrue(response.success, response.message)
        odometry += self.publish_odometry(self.odom[ODOMETRY:])  # the window is handed on pre + post later
        fx.wait_for(lambda: [e for e in self.events if e.event == AnomalyEvent.WRITTEN], 60, 'the window')
        path, = [e.path for e in self.events if e.event == AnomalyEvent.WRITTEN]
        with rosbag.Bag(path) as bag:
            kept = {}
            for topic, raw, _ in bag.read_messages(raw=True):
                kept.setdefault(topic, []).append(bytes(raw[1]))
        self.assertEqual(kept['/note'], [serialized(self.note)])
        self.assertEqual(kept['/restarted'], [serialized(String(data='%s-%d' % (tag, k)))
                                              for tag in 'ab' for k in range(RESTARTED)])
        self.assertEqual(len(kept['/camera/image_raw']), ODOMETRY // IMAGE_EVERY)
        self.assertTrue(kept['/camera/image_raw'] == images, 'the images differ from those published')
        # the trigger applies to the newest message received (the last before it), the window's pre reaches the
        # first one, its post the next POST
        self.assertEqual(len(kept['/odom']), ODOMETRY + POST)
        self.assertTrue(kept['/odom'] == odometry[:ODOMETRY + POST], 'the odometry differs from that published')

    def test_an_intake_hands_over_what_its_own_reader_read_and_what_rospy_read_when_asked(self):
        for fast, prefix in ((True, '/fast'), (False, '/rospy')):
            sink = Sink()
            reader = intake.Intake(sink, prefix + '/odom', [prefix + '/image'], fast_receive=fast)
            odom_pub = rospy.Publisher(prefix + '/odom', Odometry, queue_size=100)
            image_pub = rospy.Publisher(prefix + '/image', Image, queue_size=100)
            try:
                fx.wait_for(lambda: odom_pub.get_num_connections() and image_pub.get_num_connections(), 20,
                            'the intake to subscribe %s' % prefix)
                images = [Image(height=480, width=640, encoding='rgb8', step=1920, data=bytes([k]) * 921600)
                          for k in range(5)]
                odometry = [record.msg for record in self.odom[:5]]
                for image, odom in zip(images, odometry):
                    image_pub.publish(image)
                    odom_pub.publish(odom)
                fx.wait_for(lambda: sum(reader.counts().values()) == 10, 20, 'the intake to receive %s' % prefix)
                self.assertTrue(reader.sync(20.0))
            finally:
                reader.stop()
            kept = {topic: [record.raw for record in sink.records if record.topic == topic]
                    for topic in (prefix + '/odom', prefix + '/image')}
            self.assertTrue(kept[prefix + '/image'] == [serialized(image) for image in images], prefix)
            self.assertTrue(kept[prefix + '/odom'] == [serialized(odom) for odom in odometry], prefix)
            self.assertEqual({type(data) for data in kept[prefix + '/image']}, {bytearray if fast else bytes})
            self.assertEqual({type(data) for data in kept[prefix + '/odom']}, {bytes})


if __name__ == '__main__':
    if '--publish' in sys.argv:
        where = sys.argv.index('--publish')
        publish_until_killed(sys.argv[where + 1], int(sys.argv[where + 2]), sys.argv[where + 3])
    else:
        rostest.rosrun(PKG, 'fast_receive', FastReceiveTest)
