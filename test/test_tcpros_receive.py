"""cc_log's own TCPROS message reader (nodes/tcpros_receive) on real sockets (``socket.socketpair()``): the framing
(a 4-byte little-endian length, then the message) read exactly, whatever the sends; the end of the stream as
rospy's receive loop expects it, a message over the bound read past, not kept; and the Receiver, one thread
reading every hooked rospy connection, each run by rospy's own ``receive_loop`` on its thread. Pure: no roscore
(rospy Subscribers and TCPROS connection objects are made, never connected to a publisher)."""
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


def connection_of(subscriber, topic, sock, endpoint, header=None, leftovers=b''):
    """A rospy TCPROS connection of ``subscriber`` connected on ``sock`` (as after its handshake, ``leftovers``
    read past the header), added to the subscription as rospy's TCPROSHandler adds it."""
    connection = TCPROSTransport(TCPROSSub(topic, rospy.AnyMsg), topic)
    connection.set_endpoint_id(endpoint)
    assert subscriber.impl.add_connection(connection)
    connection.socket, connection.header = sock, header or {'type': '*', 'callerid': endpoint}
    connection.is_latched = connection.header.get('latching') == '1'
    connection.read_buff.write(leftovers)
    return connection


def looping(connection, subscriber):
    """rospy's receive loop of ``connection`` on its own thread, as rospy runs it."""
    thread = threading.Thread(target=connection.receive_loop, args=(subscriber.impl.receive_callback,), daemon=True)
    thread.start()
    return thread


class Delivered(object):
    """What a Receiver hands over: the messages in order with the thread that delivered them, the sizes refused."""

    def __init__(self):
        self.messages, self.threads, self.refused, self.batches = [], set(), [], 0
        self.changed = threading.Condition()

    def deliver(self, batch):
        with self.changed:
            self.messages += batch
            self.threads.add(threading.get_ident())
            self.batches += 1
            self.changed.notify_all()

    def refuse(self, topic, size):
        with self.changed:
            self.refused.append((topic, size))
            self.changed.notify_all()

    def payloads(self, topic, callerid=None):
        return [payload for t, payload, header in self.messages
                if t == topic and (callerid is None or header['callerid'] == callerid)]

    def wait_for(self, condition, timeout=60.0):
        with self.changed:
            assert self.changed.wait_for(condition, timeout)


@pytest.fixture
def receiving():
    """A Receiver handing over to a Delivered (bound 1 MB), stopped at the end, and the subscribers to close."""
    delivered = Delivered()
    receiver = tcpros_receive.Receiver(delivered.deliver, delivered.refuse, 1 << 20)
    subscribers = []
    yield receiver, delivered, subscribers
    for subscriber in subscribers:
        subscriber.unregister()
    receiver.stop()


def test_the_hooked_connection_hands_every_message_to_the_intake_under_rospys_receive_loop(pair, receiving):
    """rospy's own receive_loop runs the hooked connection: the bytes the handshake read past its header first,
    then each message, to ``deliver`` with the connection header; another subscriber of the topic in the process
    gets each as an AnyMsg, the latch is kept; the end of the stream ends the loop as rospy's receive does."""
    sender, sock = pair
    receiver, delivered, subscribers = receiving
    topic = '/cc_log_test_fast_receive'
    others = []
    subscriber = rospy.Subscriber(topic, rospy.AnyMsg, lambda msg: None, queue_size=None)
    other = rospy.Subscriber(topic, rospy.AnyMsg, others.append, queue_size=None)  # same impl
    subscribers += [other, subscriber]
    receiver.hook(subscriber, topic)
    payloads = [message(700, n) for n in range(50)] + [message(921600, 7), b'']
    data = b''.join(frame(p) for p in payloads[:20]) + frame(bytes(3 << 20)) + \
        b''.join(frame(p) for p in payloads[20:])
    connection = connection_of(subscriber, topic, sock, 'http://publisher:1/',
                               {'type': '*', 'latching': '1', 'callerid': '/pub'}, data[:1000])
    thread = sent_in_thread(sender, [data[1000:]], end=True)
    connection.receive_loop(subscriber.impl.receive_callback)  # returns at the end of the stream
    thread.join(60.0)
    assert delivered.payloads(topic) == payloads and delivered.refused == [(topic, 3 << 20)]  # the large one read past
    assert all(header is connection.header for _, _, header in delivered.messages)
    assert [msg._buff for msg in others] == payloads and connection.latch._buff == b''
    assert connection.stat_num_msg == len(payloads) and connection.stat_bytes == len(data) - 4 - (3 << 20)
    assert connection.done and connection.read_buff is None  # closed by rospy's loop


def test_many_connections_are_read_by_one_thread_each_in_order(receiving):
    """Three topics, one with two publishers, sent at once from five threads: every message handed over once, in
    order per connection, all from the receiver's one thread, several in a batch; each rospy thread ends with its
    stream."""
    receiver, delivered, subscribers = receiving
    ends, threads, sent = [], [], {}
    for number, topic in enumerate(['/cc_log_test_many_a', '/cc_log_test_many_b', '/cc_log_test_many_c']):
        subscriber = rospy.Subscriber(topic, rospy.AnyMsg, lambda msg: None, queue_size=None)
        subscribers.append(subscriber)
        receiver.hook(subscriber, topic)
        for publisher in range(2 if number == 0 else 1):
            sender, sock = socket.socketpair()
            ends += [sender, sock]
            callerid = '/pub%d' % publisher
            connection = connection_of(subscriber, topic, sock, 'http://pub%d:%d/' % (publisher, number),
                                       {'type': '*', 'callerid': callerid})
            threads.append(looping(connection, subscriber))
            sizes = [300 + (k * 37) % 700 if k % 50 else 200000 for k in range(400)]  # a large one every 50
            payloads = [message(size, k + 7 * number + publisher) for k, size in enumerate(sizes)]
            sent[topic, callerid] = payloads
            threads.append(sent_in_thread(sender, [frame(p) for p in payloads], end=True))
    try:
        for thread in threads:
            thread.join(60.0)
            assert not thread.is_alive()
    finally:
        for end in ends:
            end.close()
    for (topic, callerid), payloads in sent.items():
        assert delivered.payloads(topic, callerid) == payloads
    assert len(delivered.messages) == 1600 and delivered.threads == {receiver._thread.ident}
    assert delivered.batches < len(delivered.messages)


def hooked(receiver, subscribers, topic):
    """A subscriber of ``topic`` hooked to ``receiver`` (kept in ``subscribers``) with one connection on a socket
    pair, its rospy receive loop running: (connection, its thread, the sending end, the receiving end)."""
    subscriber = rospy.Subscriber(topic, rospy.AnyMsg, lambda msg: None, queue_size=None)
    subscribers.append(subscriber)
    receiver.hook(subscriber, topic)
    sender, sock = socket.socketpair()
    connection = connection_of(subscriber, topic, sock, 'http://pub:1/')
    return connection, looping(connection, subscriber), sender, sock


def test_a_connection_closed_while_others_flow_ends_alone(receiving):
    """rospy closes one connection (as unregistering its topic does) while another sends: its rospy thread ends,
    the other connection's messages keep coming, every one once and in order."""
    receiver, delivered, subscribers = receiving
    topics = ['/cc_log_test_closed', '/cc_log_test_flowing']
    connections = [hooked(receiver, subscribers, topic) for topic in topics]
    ends = [end for connection in connections for end in connection[2:]]
    (closed, closed_thread, closed_sender, _), (_, flowing_thread, flowing_sender, _) = connections
    try:
        first = [message(500, k) for k in range(100)]
        closed_sender.sendall(b''.join(frame(p) for p in first))
        flowing_sender.sendall(b''.join(frame(p) for p in first))
        delivered.wait_for(lambda: len(delivered.messages) == 200)
        closed.close()  # from another thread, as rospy's topic close or remove_connection does
        closed_thread.join(60.0)
        assert not closed_thread.is_alive() and closed.done
        later = [message(900, k) for k in range(100, 300)]
        for payload in later:
            flowing_sender.sendall(frame(payload))
        flowing_sender.shutdown(socket.SHUT_WR)
        flowing_thread.join(60.0)
        assert not flowing_thread.is_alive()
    finally:
        for end in ends:
            end.close()
    assert delivered.payloads(topics[0]) == first and delivered.payloads(topics[1]) == first + later


def test_a_message_over_the_bound_on_one_connection_does_not_disturb_another(receiving):
    """A 3 MB message (over the 1 MB bound) on one connection, sent a piece at a time while the other connection
    sends: read past and refused, that connection kept (its next message read), the other's messages all read."""
    receiver, delivered, subscribers = receiving
    topics = ['/cc_log_test_oversize', '/cc_log_test_beside']
    connections = [hooked(receiver, subscribers, topic) for topic in topics]
    pairs = [end for connection in connections for end in connection[2:]]
    threads = [connection[1] for connection in connections]
    huge = frame(message(3 << 20, 5))
    before, after = message(600, 1), message(600000, 2)
    beside = [message(700, k) for k in range(300)]
    threads.append(sent_in_thread(pairs[0], [frame(before)] + [huge[k:k + 100000] for k in range(0, len(huge), 100000)]
                                  + [frame(after)], end=True))
    threads.append(sent_in_thread(pairs[2], [frame(p) for p in beside], end=True))
    try:
        for thread in threads:
            thread.join(60.0)
            assert not thread.is_alive()
    finally:
        for end in pairs:
            end.close()
    assert delivered.payloads(topics[0]) == [before, after] and delivered.refused == [(topics[0], 3 << 20)]
    assert delivered.payloads(topics[1]) == beside


def test_a_stopped_receiver_ends_the_connections_it_reads(pair):
    """``stop()`` ends the rospy thread of every connection still read (TransportTerminated: its loop ends)."""
    sender, sock = pair
    delivered = Delivered()
    receiver = tcpros_receive.Receiver(delivered.deliver, delivered.refuse, 1 << 20)
    topic = '/cc_log_test_stopped'
    subscriber = rospy.Subscriber(topic, rospy.AnyMsg, lambda msg: None, queue_size=None)
    try:
        receiver.hook(subscriber, topic)
        connection = connection_of(subscriber, topic, sock, 'http://pub:1/')
        thread = looping(connection, subscriber)
        sender.sendall(frame(b'one'))
        delivered.wait_for(lambda: delivered.messages)
        receiver.stop()
        thread.join(60.0)
        assert not thread.is_alive() and connection.done
    finally:
        subscriber.unregister()
    assert delivered.payloads(topic) == [b'one'] and not receiver._thread.is_alive()


def test_flush_hands_over_at_once_what_came_while_the_loop_gathers(receiving, monkeypatch):
    """After a light pass the loop lets messages gather (here 60 s); ``flush()`` (what ``Intake.sync`` calls before
    a manual trigger) has what the socket holds read and handed over now, and gathering goes on after."""
    monkeypatch.setattr(tcpros_receive, 'GATHER_SECONDS', 60.0)
    receiver, delivered, subscribers = receiving
    topic = '/cc_log_test_flush'
    subscriber = rospy.Subscriber(topic, rospy.AnyMsg, lambda msg: None, queue_size=None)
    subscribers.append(subscriber)
    receiver.hook(subscriber, topic)
    sender, sock = socket.socketpair()
    try:
        connection = connection_of(subscriber, topic, sock, 'http://pub:1/')
        looping(connection, subscriber)
        sender.sendall(frame(b'first'))
        delivered.wait_for(lambda: delivered.messages)  # read at once: the loop then gathers for 60 s
        sender.sendall(frame(b'second') + frame(b'third'))
        assert receiver.flush(10.0)
        assert delivered.payloads(topic) == [b'first', b'second', b'third']
    finally:
        sender.close()
        sock.close()


def test_a_batch_is_queued_under_one_lock_with_one_receipt_and_counted_as_put_counts():
    from cc_log.nodes import intake
    queue = intake.IntakeQueue(3, 1000)
    header = {'type': '*'}
    refused = queue.put_batch([('/a', b'x' * 10, header), ('/b', b'y' * 995, header), ('/a', b'z' * 20, header),
                               ('/a', b'w' * 30, header), ('/b', b'v', header)], 'receipt')
    assert refused == [('/b', 995), ('/b', 1)]  # over the bytes, then over the messages
    assert queue.overflowed == 2 and queue.bytes == 60 and queue.qsize() == 3
    assert queue.received_counts() == {'/a': 3, '/b': 2} and queue.received_sizes() == {'/a': 60, '/b': 996}
    assert queue.take_batch(0.0) == [('/a', b'x' * 10, header, 'receipt'), ('/a', b'z' * 20, header, 'receipt'),
                                     ('/a', b'w' * 30, header, 'receipt')]


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
