"""cc_log's own reading of TCPROS messages off a subscriber connection rospy has established.

rospy stays the node: it registers with the master, takes publisherUpdate, asks each publisher for the topic
(requestTopic), connects and does the connection header handshake, reconnects and shuts down. Only the reading
of messages off a connected socket is cc_log's: ``hook(subscriber, deliver, refuse, max_bytes)`` gives every
connection of ``subscriber`` an instance-level ``receive_once`` that reads one message (``FrameReader``) and hands
its serialized bytes straight to ``deliver(payload, connection_header)`` (one over ``max_bytes`` is read past, never
held, and its size handed to ``refuse(size)``), skipping rospy's receive (a BytesIO filled
a piece at a time, its message cut out, an ``AnyMsg``, the subscriber's callback machinery and its locks).

It relies on these internals of rospy (Noetic, frozen), all read here and nowhere else:

- ``Subscriber.impl`` (``rospy.topics._SubscriberImpl``) and its ``add_connection(connection)``, which
  ``tcpros_pubsub.TCPROSHandler.create_transport`` calls before the thread that connects and then runs
  ``connection.receive_loop(impl.receive_callback)``; ``impl.connections`` (those added already);
- ``tcpros_base.TCPROSTransport``: ``receive_loop`` calls ``self.receive_once()`` for a list of messages and
  hands it to ``receive_callback`` (an empty list: nothing done), ends on ``TransportTerminated`` and reconnects
  on ``TransportException``; ``socket``, ``header`` (the publisher's connection header), ``read_buff`` (a BytesIO
  holding, from its start to its position, bytes read past the handshake or past rospy's last message),
  ``stat_bytes`` and ``stat_num_msg``.

and of ``_SubscriberImpl``: ``callbacks`` (``(callback, args)`` pairs) and ``_invoke_callback``, for another
subscriber of the same topic in the process (``record --limit`` counts the node's topics so), and rospy's
``conn.latch`` (the last message of a latched connection, given to a callback added later), both kept as rospy
keeps them, at the cost of an ``AnyMsg`` per message only where they are used.

Edge module: rospy.
"""
import struct

from rospy.exceptions import TransportException, TransportTerminated
from rospy.msg import AnyMsg

LENGTH = struct.Struct('<I')  # the 4-byte little-endian length before each message
READ_BYTES = 1 << 16          # bytes asked of the socket at a time for messages smaller than that


class TooLarge(Exception):
    """A message of ``size`` bytes, more than the ``bound``: read past, not kept."""

    def __init__(self, size, bound):
        Exception.__init__(self, 'a message of %d bytes, more than the %d bytes the intake holds' % (size, bound))
        self.size, self.bound = size, bound


class FrameReader(object):
    """Reads TCPROS messages (a 4-byte little-endian length, then that many bytes) off a connected blocking
    socket, one per ``read()``.

    Small messages are read ``READ_BYTES`` at a time into one reused buffer (one ``recv_into`` for a message that
    came alone, one for many that came together) and returned as ``bytes``; a message larger than that buffer is
    returned as a ``bytearray`` of its size filled by ``recv_into`` (no other copy but the few bytes read with its
    length). A message over ``max_bytes`` is read past through the reused buffer (nothing allocated, the stream kept)
    and ``TooLarge`` raised; the end of the stream, or a socket error, is a ``TransportTerminated``, as rospy's
    ``recv_buff``.
    ``leftovers``: bytes of the stream read before (past the handshake)."""

    def __init__(self, sock, max_bytes, leftovers=b''):
        self.sock = sock
        self.max_bytes = int(max_bytes)
        self._buffer = bytearray(max(READ_BYTES, len(leftovers)))
        self._view = memoryview(self._buffer)
        self._buffer[:len(leftovers)] = leftovers
        self._start, self._end = 0, len(leftovers)  # the unread bytes: _buffer[_start:_end]

    def take(self, data):
        """Put ``data`` (bytes of the stream read elsewhere) after the unread bytes."""
        unread = self._end - self._start
        if unread + len(data) > len(self._buffer):
            self._buffer = bytearray(unread + len(data))
            self._buffer[:unread] = self._view[self._start:self._end]
            self._view = memoryview(self._buffer)
        elif self._start:
            self._buffer[:unread] = self._view[self._start:self._end]
        self._buffer[unread:unread + len(data)] = data
        self._start, self._end = 0, unread + len(data)

    def read(self):
        """The next message's serialized bytes."""
        while True:
            unread = self._end - self._start
            if unread >= 4:
                (length,) = LENGTH.unpack_from(self._buffer, self._start)
                if length > self.max_bytes:
                    self._skip(length)
                    raise TooLarge(length, self.max_bytes)
                begin = self._start + 4
                if unread - 4 >= length:
                    self._start = begin + length
                    return bytes(self._view[begin:self._start])
                if 4 + length > len(self._buffer):
                    return self._read_large(length, begin)
            self._receive()

    def _skip(self, length):
        """Read past the unread bytes' first message (``length`` bytes after its length)."""
        left = length - (self._end - self._start - 4)
        if left <= 0:  # all read already: the next message starts right after it
            self._start += 4 + length
            return
        self._start = self._end = 0
        while left > 0:
            left -= self._recv_into(self._view[:min(left, len(self._buffer))])

    def _read_large(self, length, begin):
        payload = bytearray(length)
        view = memoryview(payload)
        filled = self._end - begin
        view[:filled] = self._view[begin:self._end]
        self._start = self._end = 0
        while filled < length:
            filled += self._recv_into(view[filled:])
        return payload

    def _receive(self):
        """Read what the socket has (up to the buffer's end) after the unread bytes, moved to the start."""
        unread = self._end - self._start
        if self._start:
            self._buffer[:unread] = self._view[self._start:self._end]
            self._start, self._end = 0, unread
        self._end += self._recv_into(self._view[self._end:])

    def _recv_into(self, view):
        try:
            count = self.sock.recv_into(view)
        except OSError as error:
            raise TransportTerminated('unable to receive data from sender: %s' % error)
        if not count:
            raise TransportTerminated("unable to receive data from sender, check sender's logs for details")
        return count


def hook(subscriber, deliver, refuse, max_bytes):
    """Read the messages of every connection of ``subscriber`` (a rospy.Subscriber), those open and those to
    come, with a ``FrameReader``, handing each to ``deliver(payload, connection_header)`` on the connection's
    thread instead of to the subscriber's callback; the size of one over ``max_bytes`` to ``refuse(size)``."""
    impl = subscriber.impl
    add_connection = impl.add_connection
    own = (subscriber.callback, subscriber.callback_args)

    def add_reading_connection(connection):
        read_messages(connection, impl, own, deliver, refuse, max_bytes)
        return add_connection(connection)
    impl.add_connection = add_reading_connection
    for connection in list(impl.connections):
        read_messages(connection, impl, own, deliver, refuse, max_bytes)


def read_messages(connection, impl, own, deliver, refuse, max_bytes):
    """Give ``connection`` (a rospy TCPROSTransport of ``impl``) a ``receive_once`` that reads one message with a
    ``FrameReader``, counts it in rospy's statistics, hands it to ``deliver`` and returns no message to rospy.
    Other subscribers of the topic in this process (callbacks of ``impl`` besides ``own``, the hooked
    subscriber's) get it as rospy would give it, an ``AnyMsg``, as does rospy's latch of a latched connection."""
    reader = None

    def receive_once():
        nonlocal reader
        sock = connection.socket
        if sock is None:
            raise TransportException('connection not initialized')
        if reader is None or reader.sock is not sock:  # connected, or connected again
            reader = FrameReader(sock, max_bytes)
        pending = connection.read_buff
        if pending.tell():  # bytes rospy read past the handshake (or past its last message)
            reader.take(pending.getvalue()[:pending.tell()])
            pending.seek(0)
            pending.truncate()
        try:
            payload = reader.read()
        except TooLarge as error:
            refuse(error.size)
            return []
        except TransportException:
            raise
        except Exception as error:  # out of memory...: the stream's place is lost, rospy connects again
            raise TransportException('receive_once[%s]: unexpected error %s' % (connection.name, error))
        connection.stat_bytes += len(payload) + 4
        connection.stat_num_msg += 1
        deliver(payload, connection.header)
        callbacks = impl.callbacks  # None once the subscription is closed
        if connection.is_latched or (callbacks and len(callbacks) > 1):
            _as_rospy_would(payload, connection, callbacks or (), impl, own)
        return []
    connection.receive_once = receive_once


def _as_rospy_would(payload, connection, callbacks, impl, own):
    """The message as an ``AnyMsg`` to the other callbacks of ``impl`` and as the latch of ``connection``."""
    msg = AnyMsg()
    msg._buff, msg._connection_header = payload, connection.header
    if connection.is_latched:
        connection.latch = msg
    for callback, args in callbacks:
        if (callback, args) != own:
            impl._invoke_callback(msg, callback, args)
