"""cc_log's own TCPROS message reader (nodes/tcpros_receive) on real sockets (``socket.socketpair()``): the framing
(a 4-byte little-endian length, then the message) read exactly, whatever the sends; the end of the stream as
rospy's receive loop expects it, a message over the bound read past, not kept; and the hook on a rospy connection
run by rospy's own ``receive_loop``. Pure: no roscore (a rospy Subscriber and a TCPROS connection object are made, never
connected to a publisher)."""
import socket
import struct
import threading

import pytest

rospy = pytest.importorskip('rospy')
from rospy.exceptions import TransportTerminated  # noqa: E402
from rospy.impl.tcpros_base import TCPROSTransport  # noqa: E402
from rospy.impl.tcpros_pubsub import TCPROSSub  # noqa: E402

from cc_log.nodes import tcpros_receive  # noqa: E402
from cc_log.nodes.tcpros_receive import FrameReader  # noqa: E402

BOUND = 64 * 1000 ** 2  # the intake queue's default byte bound


def frame(payload):
    return struct.pack('<I', len(payload)) + payload


def message(size, seed=0):
    """``size`` bytes that differ from one message to the next."""
    return bytes((seed + k * 7) % 251 for k in range(size)) if size < 1000 else \
        (bytes(range(256)) * (size // 256 + 2))[seed % 256:seed % 256 + size]


@pytest.fixture
def pair():
    sender, receiver = socket.socketpair()
    yield sender, receiver
    sender.close()
    receiver.close()


def sent_in_thread(sock, parts, end=False):
    """Send each of ``parts`` (one ``sendall`` each) on a thread, the reader reading meanwhile; ``end``: then
    end the stream."""
    def send():
        for part in parts:
            sock.sendall(part)
        if end:
            sock.shutdown(socket.SHUT_WR)
    thread = threading.Thread(target=send, daemon=True)
    thread.start()
    return thread


def test_messages_of_0_1_and_5_mb_are_read_whole_and_equal_to_what_was_sent(pair):
    sender, receiver = pair
    payloads = [b'', b'x', message(5 * 1000 ** 2, 3), b'', message(700, 1)]
    thread = sent_in_thread(sender, [frame(p) for p in payloads])
    reader = FrameReader(receiver, BOUND)
    read = [reader.read() for _ in payloads]
    thread.join(60.0)
    assert read == payloads
    assert [type(p) for p in read] == [bytes, bytes, bytearray, bytes, bytes]  # a large one: no copy of it made


def test_a_message_sent_a_byte_at_a_time_is_read_whole(pair):
    sender, receiver = pair
    payloads = [message(300, 5), message(70000, 9)]
    data = b''.join(frame(p) for p in payloads)
    thread = sent_in_thread(sender, [data[k:k + 1] for k in range(300 + 4)] + [data[304:]])
    reader = FrameReader(receiver, BOUND)
    assert [reader.read(), reader.read()] == payloads
    thread.join(60.0)


def test_many_messages_in_one_send_are_read_one_by_one_in_order(pair):
    sender, receiver = pair
    payloads = [message(n % 900, n) for n in range(500)]  # ~225 kB: more than the reader's buffer
    thread = sent_in_thread(sender, [b''.join(frame(p) for p in payloads)])
    reader = FrameReader(receiver, BOUND)
    assert [reader.read() for _ in payloads] == payloads
    thread.join(60.0)


def test_bytes_read_before_the_reader_come_first(pair):
    sender, receiver = pair
    first, second = message(100, 1), message(200000, 2)
    data = frame(first) + frame(second)
    reader = FrameReader(receiver, BOUND, leftovers=data[:50])
    reader.take(data[50:110])  # the rest of the first message and the start of the second
    thread = sent_in_thread(sender, [data[110:]])
    assert reader.read() == first and reader.read() == second
    thread.join(60.0)


@pytest.mark.parametrize('size, sent', [(10, 5), (200000, 100000), (4, 0)])
def test_the_end_of_the_stream_mid_message_is_transport_terminated(pair, size, sent):
    sender, receiver = pair
    sender.sendall(frame(message(size))[:4 + sent] if sent else b'\x04\x00')
    sender.shutdown(socket.SHUT_WR)
    reader = FrameReader(receiver, BOUND)
    with pytest.raises(TransportTerminated):
        reader.read()


def test_the_end_of_the_stream_between_messages_is_transport_terminated(pair):
    sender, receiver = pair
    sender.sendall(frame(b'last'))
    sender.close()
    reader = FrameReader(receiver, BOUND)
    assert reader.read() == b'last'
    with pytest.raises(TransportTerminated):
        reader.read()


@pytest.mark.parametrize('size', [2000, 200000])
def test_a_message_over_the_bound_is_read_past_not_kept_and_the_next_one_read(pair, size):
    sender, receiver = pair
    thread = sent_in_thread(sender, [frame(message(size, 1)) + frame(b'next') + frame(message(size, 2))])
    reader = FrameReader(receiver, 1000)
    with pytest.raises(tcpros_receive.TooLarge) as raised:
        reader.read()
    assert (raised.value.size, raised.value.bound) == (size, 1000)
    assert str(raised.value) == 'a message of %d bytes, more than the 1000 bytes the intake holds' % size
    assert reader.read() == b'next'
    with pytest.raises(tcpros_receive.TooLarge):
        reader.read()
    assert len(reader._buffer) == tcpros_receive.READ_BYTES  # nothing allocated for them
    thread.join(60.0)


def test_a_bogus_length_allocates_nothing_and_the_end_of_the_stream_ends_it(pair):
    sender, receiver = pair
    sender.sendall(struct.pack('<I', 0xFFFFFFF0) + b'rest')
    sender.shutdown(socket.SHUT_WR)
    reader = FrameReader(receiver, BOUND)
    with pytest.raises(TransportTerminated):
        reader.read()
    assert len(reader._buffer) == tcpros_receive.READ_BYTES


def test_the_hooked_connection_hands_every_message_to_the_intake_under_rospys_receive_loop(pair):
    """rospy's own receive_loop runs the hooked connection: the bytes the handshake read past its header first,
    then each message, to ``deliver`` with the connection header; another subscriber of the topic in the process
    gets each as an AnyMsg, the latch is kept; the end of the stream ends the loop as rospy's receive does."""
    sender, receiver = pair
    topic = '/cc_log_test_fast_receive'
    delivered, others, refused = [], [], []
    subscriber = rospy.Subscriber(topic, rospy.AnyMsg, lambda msg: None, queue_size=None)
    other = rospy.Subscriber(topic, rospy.AnyMsg, others.append, queue_size=None)  # same impl
    try:
        tcpros_receive.hook(subscriber, lambda payload, header: delivered.append((payload, header)),
                            refused.append, 1 << 20)
        connection = TCPROSTransport(TCPROSSub(topic, rospy.AnyMsg), topic)
        connection.set_endpoint_id('http://publisher:1/')
        assert subscriber.impl.add_connection(connection)
        payloads = [message(700, n) for n in range(50)] + [message(921600, 7), b'']
        data = b''.join(frame(p) for p in payloads[:20]) + frame(bytes(3 << 20)) + \
            b''.join(frame(p) for p in payloads[20:])
        connection.socket, connection.header = receiver, {'type': '*', 'latching': '1', 'callerid': '/pub'}
        connection.is_latched = True
        connection.read_buff.write(data[:1000])  # as rosgraph's handshake leaves what it read past the header
        thread = sent_in_thread(sender, [data[1000:]], end=True)
        connection.receive_loop(subscriber.impl.receive_callback)  # returns at the end of the stream
        thread.join(60.0)
    finally:
        other.unregister()
        subscriber.unregister()
    assert [payload for payload, _ in delivered] == payloads and refused == [3 << 20]  # the large one read past
    assert all(header is connection.header for _, header in delivered)
    assert [msg._buff for msg in others] == payloads and connection.latch._buff == b''
    assert connection.stat_num_msg == len(payloads) and connection.stat_bytes == len(data) - 4 - (3 << 20)
    assert connection.done and connection.read_buff is None  # closed by rospy's loop


def test_the_intake_counts_and_warns_a_message_read_past_as_one_its_queue_cannot_take(caplog):
    from cc_log.nodes import intake
    receiver = intake.Intake.__new__(intake.Intake)  # the queue's part only: no subscribers, no thread
    receiver.queue, receiver.dropped = intake.IntakeQueue(100, 1000), 0
    initialized = rospy.rostime.is_rostime_initialized()
    rospy.rostime.set_rostime_initialized(True)  # wall-clock time for rospy's throttled warning, as a node has
    try:
        with caplog.at_level('WARNING', logger='rosout'):
            receiver.refuse('/cloud', 3 << 20)
    finally:
        rospy.rostime.set_rostime_initialized(initialized)
    assert (receiver.queue.overflowed, receiver.dropped, receiver.queue.qsize()) == (1, 1, 0)
    assert receiver.counts() == {'/cloud': 1} and receiver.sizes() == {'/cloud': 3 << 20}
    assert [r.getMessage() for r in caplog.records] == [
        'a message of 3145728 bytes on /cloud is larger than the whole intake queue (~intake_max_mb 0.001): dropped; '
        'raise ~intake_max_mb (1 dropped so far)']
