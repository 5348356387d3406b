"""cc_log's own reading of TCPROS messages off the subscriber connections rospy has established: one thread
reads every connection.

rospy stays the node: it registers with the master, takes publisherUpdate, asks each publisher for the topic
(requestTopic), connects and does the connection header handshake, reconnects and shuts down. Only the reading
of messages off a connected socket is cc_log's. ``Receiver(deliver, refuse, max_bytes).hook(subscriber, topic)``
takes over every connection of ``subscriber``, those open and those to come: once rospy's thread of a connection
has done the handshake and calls its ``receive_once``, the socket (made non-blocking) is added to the receiver's
one ``selectors`` loop and rospy's thread waits, blocked on an event, until the connection ends. The loop reads
what each ready socket has (``FrameReader``: several light messages in one ``recv_into``, a large one into a
``bytearray`` of its size) and hands the messages of one pass over every ready socket to ``deliver(batch)`` in one
call (``batch``: ``(topic, payload, connection_header)`` in order per connection); a message over ``max_bytes`` is
read past, never held, and its size handed to ``refuse(topic, size)``. After a pass that read less than
``READ_BYTES`` (light topics only) the loop lets messages gather ``GATHER_SECONDS`` in the sockets before the next
pass, so that one pass reads several (the feeder hands them on in batches of up to 0.5 s anyway); a heavier flow
is read at once, pass after pass; ``flush()`` (``Intake.sync``, before a manual trigger) has what the sockets hold
read and handed over at once. When the stream ends, or on a socket error,
the socket leaves the loop first, then rospy's thread raises what rospy's own ``receive_once`` raises there
(``TransportTerminated``: its receive loop ends; ``TransportException`` on an unexpected error: rospy closes the
socket and connects again), so connection, reconnection and shutdown stay rospy's, exactly as before. Skipped:
rospy's receive (a BytesIO filled a piece at a time, its message cut out, an ``AnyMsg``, the subscriber's callback
machinery and its locks), a thread woken per message and a hand-over per message.

It relies on these internals of rospy (Noetic, frozen), all read here and nowhere else:

- ``Subscriber.impl`` (``rospy.topics._SubscriberImpl``) and its ``add_connection(connection)``, which
  ``tcpros_pubsub.TCPROSHandler.create_transport`` calls before the thread that connects and then runs
  ``connection.receive_loop(impl.receive_callback)``; ``impl.connections`` (those added already);
- ``tcpros_base.TCPROSTransport``: ``receive_loop`` calls ``self.receive_once()`` once the socket is connected and
  the handshake read, ends on ``TransportTerminated`` (then calls ``self.close()``) and, on
  ``TransportException``, closes the socket, sets it to None and connects again (``_reconnect``, a new handshake,
  then ``receive_once`` again); ``close()`` (which the topic's ``close`` and ``remove_connection`` call from other
  threads, and which shuts the socket down and closes it), ``done``, ``name``, ``socket``, ``header`` (the
  publisher's connection header), ``read_buff`` (a BytesIO holding, from its start to its position, bytes the
  handshake read past its header), ``stat_bytes`` and ``stat_num_msg``; both ``receive_once`` and ``close`` are
  replaced per connection by instance attributes;

and of ``_SubscriberImpl``: ``callbacks`` (``(callback, args)`` pairs) and ``_invoke_callback``, for another
subscriber of the same topic in the process (``record --limit`` counts the node's topics so), and rospy's
``conn.latch`` (the last message of a latched connection, given to a callback added later), both kept as rospy
keeps them, at the cost of an ``AnyMsg`` per message only where they are used (their callbacks run on the
receiver's thread).

Edge module: rospy.
"""
import collections
import selectors
import socket
import struct
import threading

import rospy
from rospy.exceptions import TransportException, TransportTerminated
from rospy.msg import AnyMsg

LENGTH = struct.Struct('<I')  # the 4-byte little-endian length before each message
READ_BYTES = 1 << 16          # bytes asked of the socket at a time for messages smaller than that
CHECK_SECONDS = 1.0           # how often a waiting rospy thread looks whether its connection (or rospy) ended unseen
GATHER_SECONDS = 0.05         # after a pass that read less than READ_BYTES, the loop lets messages gather this long


class TooLarge(Exception):
    """A message of ``size`` bytes, more than the ``bound``: read past, not kept."""

    def __init__(self, size, bound):
        Exception.__init__(self, 'a message of %d bytes, more than the %d bytes the intake holds' % (size, bound))
        self.size, self.bound = size, bound


class FrameReader(object):
    """Reads TCPROS messages (a 4-byte little-endian length, then that many bytes) off a connected socket.

    ``pull(out)`` receives once (what a non-blocking socket has; on a blocking one, waits for some) and appends to
    ``out`` every message that completes, in order: small messages are read ``READ_BYTES`` at a time into one
    reused buffer (one ``recv_into`` for a message that came alone, one for many that came together) and appended
    as ``bytes``; a message larger than that buffer is filled into a ``bytearray`` of its size by ``recv_into`` (no
    other copy but the few bytes read with its length), over as many pulls as it takes. A message over
    ``max_bytes`` is read past through the reused buffer (nothing allocated, the stream kept) and a ``TooLarge``
    appended in its place. The end of the stream, or a socket error, is a ``TransportTerminated``, as rospy's
    ``recv_buff``. ``read()``: the next message of a blocking socket (``TooLarge`` raised in its place).
    ``leftovers``: bytes of the stream read before (past the handshake)."""

    def __init__(self, sock, max_bytes, leftovers=b''):
        self.sock = sock
        self.max_bytes = int(max_bytes)
        self._buffer = bytearray(max(READ_BYTES, len(leftovers)))
        self._view = memoryview(self._buffer)
        self._buffer[:len(leftovers)] = leftovers
        self._start, self._end = 0, len(leftovers)  # the unread bytes: _buffer[_start:_end]
        self._large = None     # [payload, its memoryview, bytes filled] of a message larger than the buffer
        self._skipping = None  # [bytes left, its TooLarge] of a message over max_bytes being read past
        self._read = collections.deque()  # messages pulled, not yet returned by read()

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
        """The next message's serialized bytes (a blocking socket)."""
        while not self._read:
            self.parse(self._read)
            if not self._read:
                self.pull(self._read)
        item = self._read.popleft()
        if item.__class__ is TooLarge:
            raise item
        return item

    def pull(self, out):
        """Receive once and append to ``out`` the messages that completes; the bytes received (0: none there)."""
        if self._large is not None:
            payload, view, filled = self._large
            count = self._recv_into(view[filled:])
            self._large[2] = filled = filled + count
            if filled == len(payload):
                self._large = None
                out.append(payload)
            return count
        if self._skipping is not None:
            left, too_large = self._skipping
            count = self._recv_into(self._view[:min(left, len(self._buffer))])
            self._skipping[0] = left = left - count
            if not left:
                self._skipping = None
                out.append(too_large)
            return count
        unread = self._end - self._start
        if self._start:
            self._buffer[:unread] = self._view[self._start:self._end]
            self._start, self._end = 0, unread
        count = self._recv_into(self._view[self._end:])
        self._end += count
        self.parse(out)
        return count

    def parse(self, out):
        """Append to ``out`` every complete message of the unread bytes (no receive); a message larger than the
        buffer, or over ``max_bytes``, that they start is then filled, or read past, by the next pulls."""
        buffer, view, start, end = self._buffer, self._view, self._start, self._end
        while end - start >= 4:
            (length,) = LENGTH.unpack_from(buffer, start)
            begin = start + 4
            if end - begin >= length:
                start = begin + length
                out.append(TooLarge(length, self.max_bytes) if length > self.max_bytes else bytes(view[begin:start]))
                continue
            if length > self.max_bytes:
                self._skipping = [length - (end - begin), TooLarge(length, self.max_bytes)]
                start = end = 0
            elif 4 + length > len(buffer):
                payload = bytearray(length)
                self._large = [payload, memoryview(payload), end - begin]
                payload[:end - begin] = view[begin:end]
                start = end = 0
            break
        self._start, self._end = start, end

    def _recv_into(self, view):
        try:
            count = self.sock.recv_into(view)
        except BlockingIOError:
            return 0
        except OSError as error:
            raise TransportTerminated('unable to receive data from sender: %s' % error)
        if not count:
            raise TransportTerminated("unable to receive data from sender, check sender's logs for details")
        return count


class _Reading(object):
    """One connected socket of a connection in the receiver's loop, until ``ended`` (then rospy's thread raises
    ``error``)."""

    __slots__ = ('connection', 'sock', 'reader', 'topic', 'impl', 'own', 'ended', 'error')

    def __init__(self, connection, sock, reader, topic, impl, own):
        self.connection, self.sock, self.reader, self.topic, self.impl, self.own = \
            connection, sock, reader, topic, impl, own
        self.ended = threading.Event()
        self.error = None


class Receiver(object):
    """One thread reading the messages of every connection of the subscribers ``hook``ed (see the module
    docstring): each pass over the ready sockets hands its messages to ``deliver(batch)`` in one call
    (``(topic, payload, connection_header)``, in order per connection); the size of a message over ``max_bytes``,
    read past, to ``refuse(topic, size)``. ``stop()`` ends the thread (and any connection still read)."""

    def __init__(self, deliver, refuse, max_bytes):
        self.deliver, self.refuse, self.max_bytes = deliver, refuse, int(max_bytes)
        self._selector = selectors.DefaultSelector()
        self._wake, self._waker = socket.socketpair()
        self._wake.setblocking(False)
        self._selector.register(self._wake, selectors.EVENT_READ, None)
        self._lock = threading.Lock()  # the selector's registrations, a reading's end
        self._stopped = False
        self._passed = threading.Condition()  # the loop's passes counted; flush() waits for them
        self._passes = self._wanted = 0        # passes done; passes a flush() waits for (no gathering before)
        self._hurry = threading.Event()        # ends a gathering early (flush, stop)
        self._thread = threading.Thread(target=self._run, name='cc_log receive')
        self._thread.daemon = True
        self._thread.start()

    def hook(self, subscriber, topic):
        """Read every connection of ``subscriber`` (a rospy.Subscriber of ``topic``), open or to come, here
        instead of on its rospy thread; its messages go to ``deliver`` instead of the subscriber's callback."""
        impl = subscriber.impl
        add_connection = impl.add_connection
        own = (subscriber.callback, subscriber.callback_args)

        def add_read_connection(connection):
            self._take_over(connection, topic, impl, own)
            return add_connection(connection)
        impl.add_connection = add_read_connection
        for connection in list(impl.connections):
            self._take_over(connection, topic, impl, own)

    def _take_over(self, connection, topic, impl, own):
        """Give ``connection`` a ``receive_once`` that hands its socket to the loop and waits for its end, and a
        ``close`` that takes the socket out of the loop first."""
        close = connection.close
        current = [None]  # the connection's _Reading, once connected

        def receive_once():
            sock = connection.socket
            if sock is None:
                raise TransportException('connection not initialized')
            current[0] = reading = _Reading(connection, sock, FrameReader(sock, self.max_bytes, _leftovers(connection)),
                                            topic, impl, own)
            self._start(reading)
            while not reading.ended.wait(CHECK_SECONDS):
                if connection.done or connection.socket is not sock or rospy.is_shutdown():
                    self._end(reading, TransportTerminated('connection closed'))
            raise reading.error

        def close_connection():
            if current[0] is not None:
                self._end(current[0], TransportTerminated('connection closed'))
            close()
        connection.receive_once = receive_once
        connection.close = close_connection

    def _start(self, reading):
        """The messages already read past the handshake handed over, then the socket into the loop."""
        batch = []
        self._take(reading, _parsed(reading.reader), batch)
        if batch:
            self._deliver(batch)
        reading.sock.setblocking(False)
        with self._lock:
            if self._stopped:
                reading.error = TransportTerminated('the receiver is stopped')
                reading.ended.set()
            else:
                self._selector.register(reading.sock, selectors.EVENT_READ, reading)

    def _end(self, reading, error):
        """``reading`` out of the loop, its rospy thread woken to raise ``error`` (once)."""
        with self._lock:
            if reading.ended.is_set():
                return
            try:
                if self._selector.get_key(reading.sock).data is reading:
                    self._selector.unregister(reading.sock)
            except (KeyError, ValueError):
                pass
            reading.error = error
            reading.ended.set()

    def _run(self):
        hurry = False
        while True:
            batch, received = [], 0
            for key, _ in self._selector.select(0 if hurry else None):
                reading = key.data
                if reading is None:  # woken by stop() or flush()
                    if self._stopped:
                        return
                    _drain(self._wake)
                    continue
                out = []
                try:
                    received += reading.reader.pull(out)
                except TransportTerminated as error:
                    self._end(reading, error)
                except Exception as error:  # out of memory...: the stream's place is lost, rospy connects again
                    self._end(reading, TransportException('receive_once[%s]: unexpected error %s'
                                                          % (reading.connection.name, error)))
                if out:
                    self._take(reading, out, batch)
            if batch:
                self._deliver(batch)
            hurry = self._passed_once()
            if not hurry and received < READ_BYTES and not self._stopped:
                self._hurry.wait(GATHER_SECONDS)  # light traffic: the next pass reads what came meanwhile at once
                self._hurry.clear()
                with self._passed:
                    hurry = self._passes < self._wanted

    def _passed_once(self):
        """Count a pass; whether a flush() still waits for more."""
        with self._passed:
            self._passes += 1
            self._passed.notify_all()
            return self._passes < self._wanted

    def flush(self, timeout):
        """Wait until the loop has read and handed over what the sockets held at the call (no gathering
        meanwhile); False after ``timeout`` seconds or once stopped."""
        with self._passed:
            self._wanted = target = max(self._wanted, self._passes + 2)  # the pass under way may have begun before
        self._hurry.set()
        try:
            self._waker.send(b'x')
        except OSError:  # stopped and closed
            return False
        with self._passed:
            return self._passed.wait_for(lambda: self._passes >= target or self._stopped, timeout) and \
                not self._stopped

    def _take(self, reading, out, batch):
        """The messages ``out`` of ``reading`` into ``batch``, counted in rospy's statistics; one read past to
        ``refuse``; other subscribers of the topic and the latch served as rospy would."""
        connection, topic, header = reading.connection, reading.topic, reading.connection.header
        payloads = []
        for item in out:
            if item.__class__ is TooLarge:
                self.refuse(topic, item.size)
            else:
                payloads.append(item)
        if not payloads:
            return
        batch.extend([(topic, payload, header) for payload in payloads])
        connection.stat_bytes += sum(map(len, payloads)) + 4 * len(payloads)
        connection.stat_num_msg += len(payloads)
        callbacks = reading.impl.callbacks  # None once the subscription is closed
        if connection.is_latched or (callbacks and len(callbacks) > 1):
            for payload in payloads:
                _as_rospy_would(payload, connection, callbacks or (), reading.impl, reading.own)

    def _deliver(self, batch):
        try:
            self.deliver(batch)
        except Exception as error:  # the loop reads every topic: it must not stop
            rospy.logerr_throttle(10.0, '%d messages not queued: %s: %s' % (len(batch), type(error).__name__, error))

    def stop(self):
        """End the loop's thread and every connection still in it (rospy's threads raise TransportTerminated)."""
        with self._lock:
            self._stopped = True
            readings = [key.data for key in self._selector.get_map().values() if key.data is not None]
        for reading in readings:
            self._end(reading, TransportTerminated('the receiver is stopped'))
        self._hurry.set()
        self._waker.send(b'x')
        self._thread.join()
        with self._passed:
            self._passed.notify_all()
        self._selector.close()
        self._wake.close()
        self._waker.close()


def _leftovers(connection):
    """The bytes rospy's handshake read past the connection header (taken from its ``read_buff``)."""
    pending = connection.read_buff
    if pending is None or not pending.tell():
        return b''
    data = pending.getvalue()[:pending.tell()]
    pending.seek(0)
    pending.truncate()
    return data


def _drain(sock):
    """Read what the non-blocking ``sock`` holds."""
    try:
        while sock.recv(4096):
            pass
    except BlockingIOError:
        pass


def _parsed(reader):
    out = []
    reader.parse(out)
    return out


def _as_rospy_would(payload, connection, callbacks, impl, own):
    """The message as an ``AnyMsg`` to the other callbacks of ``impl`` and as the latch of ``connection``."""
    msg = AnyMsg()
    msg._buff, msg._connection_header = payload, connection.header
    if connection.is_latched:
        connection.latch = msg
    for callback, args in callbacks:
        if (callback, args) != own:
            impl._invoke_callback(msg, callback, args)
