"""The message intake of the nodes (smart_logger and collect_logger): subscribers that only enqueue.

Every topic arrives as serialized bytes with the publisher's connection header (type, md5sum,
message_definition, callerid, latching): read off rospy's connections by cc_log itself (``tcpros_receive``,
``fast_receive``, the default: one thread reads every connection and queues what each pass read in one
``put_batch``), else rospy's own receive hands them over as ``rospy.AnyMsg``. Either only puts
them on a bounded queue (``IntakeQueue``); one feeder thread hands them to the sink in arrival order, draining the
queue in batches: the whole batch to ``sink.on_records`` as ``records.Record``s of serialized bytes when the sink
takes batches (``SmartLogger``), else each to ``sink.on_raw(topic, bytes, connection, receipt)`` when it takes
serialized messages, else decoded to ``sink.on_message(topic, msg, receipt, size)``. A connection whose
message definition ``safe_input.check_definition`` refuses is never decoded (``MessageDecoder``).
``Intake.subscribe(topic)`` adds a topic at any time; ``Intake.sync()`` waits until what was received before
the call has been handed to the sink (a manual trigger then sees it).

A batch is what arrived during ``batch_delay`` seconds (0.5) since its first message, or less when
``BATCH_MESSAGES`` messages or an eighth of the queue's byte bound came first: the sink's fixed cost per batch is
shared by many messages (the logger's windows are in message time, so the delay changes no window).

Edge module: rospy.
"""
import collections
import threading
import time

import rospy

from cc_log.base import errors, raw_message
from cc_log.logger import options
from cc_log.base.records import Record
from cc_log.nodes import tcpros_receive

DEFAULT_MAX_MESSAGES = options.get('intake_max_messages').default  # beyond, messages are dropped and counted
DEFAULT_MAX_MB = options.get('intake_max_mb').default              # MB of serialized messages
FEED_BATCH_DELAY = 0.5        # seconds at most the feeder lets messages gather before draining them in a batch
BATCH_MESSAGES = 1024         # messages that make a batch before the delay is over
BATCH_BYTES_SHARE = 8         # ... or this share of the queue's byte bound (an eighth)


class IntakeQueue(object):
    """The bounded intake queue: at most ``max_messages`` messages and ``max_bytes`` serialized bytes.

    ``put`` returns False (and counts ``overflowed``) when the message does not fit; ``take_batch`` waits for a
    batch (``delay`` seconds since its first item, ``batch_messages`` items, ``batch_bytes`` bytes or a ``force``d
    item, whichever comes first) and returns every queued item at once (oldest first). ``qsize()`` as
    queue.Queue's. ``received``: items put per ``topic`` given to ``put`` (those that did not fit too), counted
    under the queue's own lock.
    """

    def __init__(self, max_messages, max_bytes, batch_messages=BATCH_MESSAGES, batch_bytes=None):
        self.max_messages = int(max_messages)
        self.max_bytes = int(max_bytes)
        self.batch_messages = max(1, min(int(batch_messages), self.max_messages))
        self.batch_bytes = max(1, self.max_bytes // BATCH_BYTES_SHARE if batch_bytes is None else int(batch_bytes))
        self.overflowed = 0
        self.bytes = 0
        self.received = collections.Counter()
        self.received_bytes = collections.Counter()
        self._items = collections.deque()
        self._ready = threading.Condition(threading.Lock())
        self._urgent = False  # a forced item is queued: the batch is due now

    def qsize(self):
        return len(self._items)

    def listen(self, topic):
        """List ``topic`` in ``received`` (0) before its first item."""
        with self._ready:
            self.received[topic] += 0

    def received_counts(self):
        """A copy of ``received``."""
        with self._ready:
            return dict(self.received)

    def received_sizes(self):
        """``{topic: serialized bytes received}`` (those that did not fit too)."""
        with self._ready:
            return dict(self.received_bytes)

    def put(self, item, size=0, force=False, topic=None):
        with self._ready:
            if topic is not None:
                self.received[topic] += 1
                self.received_bytes[topic] += size
            if not force and (len(self._items) >= self.max_messages or self.bytes + size > self.max_bytes):
                self.overflowed += 1
                return False
            self._items.append((item, size))
            self.bytes += size
            count = len(self._items)
            if force:
                self._urgent = True
            if count == 1 or force or count == self.batch_messages or \
                    self.batch_bytes <= self.bytes < self.batch_bytes + size:
                self._ready.notify()
            return True

    def put_batch(self, items, receipt):
        """Queue each ``(topic, data, header)`` of ``items`` (serialized messages, oldest first) as
        ``(topic, data, header, receipt)``, counted as ``put`` counts them, under one lock; returns
        ``(topic, size)`` of each that did not fit."""
        refused = []
        with self._ready:
            count, size_before = len(self._items), self.bytes
            for topic, data, header in items:
                size = len(data)
                self.received[topic] += 1
                self.received_bytes[topic] += size
                if len(self._items) >= self.max_messages or self.bytes + size > self.max_bytes:
                    self.overflowed += 1
                    refused.append((topic, size))
                    continue
                self._items.append(((topic, data, header, receipt), size))
                self.bytes += size
            if not count and self._items or count < self.batch_messages <= len(self._items) or \
                    size_before < self.batch_bytes <= self.bytes:
                self._ready.notify()
        return refused

    def refuse(self, topic, size):
        """Count a message of ``size`` bytes on ``topic`` that was not queued (in ``received`` and
        ``overflowed``), as ``put`` counts one that does not fit."""
        with self._ready:
            self.received[topic] += 1
            self.received_bytes[topic] += size
            self.overflowed += 1

    def take_batch(self, delay):
        """Every queued item (oldest first) once the batch is due: wait for a first item, then until ``delay``
        seconds have passed, ``batch_messages`` items or ``batch_bytes`` bytes are queued, or an item was put with
        ``force`` (an end or sync mark)."""
        with self._ready:
            while not self._items:
                self._ready.wait()
            deadline = time.monotonic() + delay
            while not (self._urgent or len(self._items) >= self.batch_messages or self.bytes >= self.batch_bytes):
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._ready.wait(left)
            items, self._items = self._items, collections.deque()
            self.bytes = 0
            self._urgent = False
        return [item for item, _ in items]


def overflow_text(queue, topic, size):
    """Why a message of ``size`` bytes on ``topic`` did not fit ``queue``, and what to do, in one line."""
    if size > queue.max_bytes:
        return ('a message of %d bytes on %s is larger than the whole intake queue (~intake_max_mb %g): dropped; '
                'raise ~intake_max_mb (%d dropped so far)' % (size, topic, queue.max_bytes / 1e6, queue.overflowed))
    return ('intake queue full (%d of at most %d messages, %.1f of %g MB queued): the node falls behind its '
            'topics; %s dropped on %s, %d in all so far' % (queue.qsize(), queue.max_messages, queue.bytes / 1e6,
                                                            queue.max_bytes / 1e6, 'a message', topic,
                                                            queue.overflowed))


class MessageDecoder(object):
    """Decodes what the intake receives (``raw_message.message_class``: the installed class
    of the publisher's type, else one built from the publisher's message definition, which must pass
    ``safe_input.check_definition`` first: genpy runs the code it generates). A definition that does not is
    refused for good: the topic is warned about once, and its messages are counted in ``refused``."""

    MAX_REFUSALS = 256  # (type, definition) pairs remembered as refused

    def __init__(self, classes=()):
        self.classes = dict(classes)  # type name -> class used before any other
        self.refused = 0
        self._refusals = set()

    def accepts(self, connection, topic):
        """Whether messages of ``connection`` (a header dict) can be decoded; a refusal is counted."""
        msg_type = connection.get('type', '')
        if msg_type in self.classes:
            return True
        definition = connection.get('message_definition', '')
        if (msg_type, definition) in self._refusals:
            self.refused += 1
            return False
        try:
            raw_message.message_class(connection)
        except ValueError as error:
            if len(self._refusals) >= self.MAX_REFUSALS:
                self._refusals.clear()
            self._refusals.add((msg_type, definition))
            self.refused += 1
            rospy.logwarn('topic %s: messages refused, never decoded: %s', topic, error)
            return False
        return True

    def decode(self, data, header, topic):
        """The message of the serialized ``data`` of a connection ``header``, deserialized, or None when its
        definition is refused."""
        if not self.accepts(header, topic):
            return None
        cls = self.classes.get(header.get('type', '')) or raw_message.message_class(header)
        decoded = cls()
        decoded.deserialize(data)
        return decoded


class Intake(object):
    """Subscribers that only enqueue, one feeder thread (see the module docstring).

    ``driving_topic`` and ``side_topics`` are subscribed at once (resolved names; ``side_topics`` lists those
    subscribed besides the driving one), ``subscribe`` adds more. The queue is bounded (``max_messages``,
    ``max_bytes``): a message arriving when it is full is dropped and counted in ``overflowed`` (and in
    ``dropped``, which also counts messages that could not be decoded or handled, and those of a refused
    message definition: ``decoder.refused``). ``on_new_topic(topic, type name)`` (optional) is called at each
    topic's first accepted message, on the feeder thread. ``tcp_nodelay``: subscribe with TCP_NODELAY
    (``~tcp_nodelay``); ``fast_receive``: read the messages off rospy's connections with ``tcpros_receive``
    (``~fast_receive``), else let rospy read them.

    Each queued item is ``(topic, data, header, receipt)``: ``data`` the serialized bytes and ``header`` the
    publisher's connection header, or ``data`` a decoded message and ``header`` None (as a test may queue)."""

    on_new_topic = None

    def __init__(self, sink, driving_topic, side_topics=(), max_messages=DEFAULT_MAX_MESSAGES,
                 max_bytes=int(DEFAULT_MAX_MB * 1000 ** 2), batch_delay=FEED_BATCH_DELAY, on_new_topic=None,
                 tcp_nodelay=False, fast_receive=True):
        self.sink = sink
        self.on_new_topic = on_new_topic
        self._typed = set()               # topics whose first message was accepted
        self.tcp_nodelay = bool(tcp_nodelay)
        self.fast_receive = bool(fast_receive)
        self.queue = IntakeQueue(max_messages, max_bytes)
        self.dropped = 0             # messages not handed to the sink: queue full, undecodable, not handled
        self.cpu_seconds = 0.0       # CPU time of the feeder thread handing messages to the sink
        self.batch_delay = float(batch_delay)
        self.decoder = MessageDecoder()
        self._raw = hasattr(sink, 'on_raw')
        self._lock = threading.Lock()
        self._receiver = tcpros_receive.Receiver(self.put_batch, self.refuse, self.queue.max_bytes) \
            if self.fast_receive else None
        self.driving_topic = rospy.resolve_name(driving_topic)
        self.subscribers = {}
        self.side_topics = []
        self._subscribe(self.driving_topic)
        for topic in side_topics:
            if rospy.resolve_name(topic) == self.driving_topic:
                rospy.logwarn('~topics: %s is the driving topic; it is logged anyway', topic)
                continue
            self.subscribe(topic)
        self._thread = threading.Thread(target=self._feed, name='cc_log feeder')
        self._thread.daemon = True
        self._thread.start()

    def subscribe(self, topic):
        """Subscribe ``topic`` (any type, as rospy.AnyMsg) now; return its resolved name, or None when it was
        subscribed already. Thread-safe."""
        resolved = rospy.resolve_name(topic)
        with self._lock:
            if resolved in self.subscribers:
                return None
            self.side_topics.append(resolved)
            return self._subscribe(resolved)

    def _subscribe(self, resolved):
        self.queue.listen(resolved)  # its rate is 0 until its first message
        subscriber = rospy.Subscriber(resolved, rospy.AnyMsg, self._enqueue, resolved, queue_size=None,
                                      tcp_nodelay=self.tcp_nodelay)
        if self._receiver is not None:
            self._receiver.hook(subscriber, resolved)
        self.subscribers[resolved] = subscriber
        return resolved

    @property
    def overflowed(self):
        """Messages dropped because the intake queue was full."""
        return self.queue.overflowed

    def counts(self):
        """``{topic: messages received so far}`` (a copy; the rates on /diagnostics)."""
        return self.queue.received_counts()

    def sizes(self):
        """``{topic: serialized bytes received so far}`` (a copy; the MB/s on /diagnostics)."""
        return self.queue.received_sizes()

    def _enqueue(self, msg, topic):
        """rospy's callback (``fast_receive`` off): the serialized message queued (``put``)."""
        self.put(topic, msg._buff, msg._connection_header)

    def put(self, topic, data, header):
        """Queue the serialized message ``data`` of ``topic`` (``header``: its connection header) with its receipt
        time, counted; the feeder thread does the rest. Cheap: called on the thread that read it."""
        size = len(data)
        if not self.queue.put((topic, data, header, rospy.get_rostime()), size, topic=topic):
            self.dropped += 1
            rospy.logwarn_throttle(10.0, overflow_text(self.queue, topic, size))

    def put_batch(self, batch):
        """Queue the serialized messages ``(topic, data, header)`` of ``batch`` (``tcpros_receive``: what one pass
        over the ready connections read, each connection's in order) in the order of their header stamps
        (``raw_message.in_stamp_order``) with one receipt time, each counted as ``put`` counts it."""
        refused = self.queue.put_batch(raw_message.in_stamp_order(batch), rospy.get_rostime())
        if refused:
            self.dropped += len(refused)
            rospy.logwarn_throttle(10.0, overflow_text(self.queue, *refused[-1]))

    def refuse(self, topic, size):
        """A message of ``size`` bytes on ``topic``, larger than the whole queue, read past and not kept
        (``tcpros_receive``): counted and warned as ``put`` counts one that does not fit."""
        self.queue.refuse(topic, size)
        self.dropped += 1
        rospy.logwarn_throttle(10.0, overflow_text(self.queue, topic, size))

    def sync(self, timeout=5.0):
        """Wait until every message received before the call has been handed to the sink; False when that
        took longer than ``timeout`` seconds (the feeder is behind) or the intake is stopped."""
        if not self._thread.is_alive():
            return False
        deadline = time.monotonic() + timeout
        if self._receiver is not None and not self._receiver.flush(timeout):  # what the sockets hold, read now
            return False
        done = threading.Event()
        self.queue.put(done, force=True)
        return done.wait(max(0.0, deadline - time.monotonic()))

    def _feed(self):
        batched = hasattr(self.sink, 'on_records')
        self._await_clock()
        while True:
            batch = self.queue.take_batch(self.batch_delay)
            started = time.thread_time()
            try:
                if not (self._feed_records(batch) if batched else self._feed_each(batch)):
                    return
            finally:
                self.cpu_seconds += time.thread_time() - started

    @staticmethod
    def _await_clock():
        """Under ``use_sim_time``, hand nothing over before the first /clock (the queue holds what comes, bounded):
        what arrived before it gets that first clock as its receipt time (``_receipt``), never 1970."""
        if not rospy.rostime.is_wallclock():  # use_sim_time (read by init_node; no master asked here)
            while rospy.get_rostime().is_zero() and not rospy.is_shutdown():
                time.sleep(0.05)

    @staticmethod
    def _receipt(receipt):
        """Float seconds of a receipt time; one taken before the clock started (zero) is now."""
        if receipt.is_zero():
            receipt = rospy.get_rostime()
        return receipt.secs + 1e-9 * receipt.nsecs

    def _feed_each(self, batch):
        """Hand a drained batch to the sink message by message; False once the end mark (None) is reached."""
        for item in batch:
            if item is None:
                return False
            if isinstance(item, threading.Event):
                item.set()  # a sync mark: everything before it was fed
            else:
                self._feed_one(*item)
        return True

    def _feed_records(self, batch):
        """Hand a drained batch to ``sink.on_records`` as serialized records (a decoded message, as a test may
        queue, goes through ``_feed_one``); False once the end mark (None) is reached."""
        records = []
        for item in batch:
            if item is None:
                self._feed_batch(records)
                return False
            if isinstance(item, threading.Event):
                self._feed_batch(records)
                records = []
                item.set()  # a sync mark: everything before it was fed
                continue
            topic, data, header, receipt = item
            if header is None:
                self._feed_batch(records)
                records = []
                self._feed_one(*item)
            elif not self._accepts(header, topic):
                self.dropped += 1  # refused (warned once by the decoder)
            else:
                records.append(Record(self._receipt(receipt), topic, None, 0, data, header))
        self._feed_batch(records)
        return True

    def _accepts(self, header, topic):
        """Whether the decoder accepts messages of the connection ``header``; the first of each topic goes to
        ``on_new_topic``."""
        if not self.decoder.accepts(header, topic):
            return False
        if topic not in self._typed:
            self._typed.add(topic)
            if self.on_new_topic is not None:
                self.on_new_topic(topic, header.get('type', ''))
        return True

    def _feed_batch(self, records):
        """``sink.on_records(records)``; a record that cannot be decoded is dropped (and counted), the rest fed."""
        while records:
            try:
                self.sink.on_records(records)
                return
            except errors.UndecodableRecord as error:
                self.dropped += 1
                rospy.logwarn_throttle(10.0, 'cannot decode a message of %s: %s' % (error.topic, error.error))
                records = records[error.index + 1:]
            except Exception as error:  # a bad message must not stop the feeder (and so all logging)
                self.dropped += len(records)
                rospy.logerr_throttle(10.0, '%d messages not handled: %s: %s'
                                      % (len(records), type(error).__name__, error))
                return

    def _feed_one(self, topic, data, header, receipt):
        """Hand one queued message to the sink (serialized to ``on_raw`` if it takes them, else decoded)."""
        try:
            if header is not None and not self._accepts(header, topic):
                self.dropped += 1  # refused (warned once by the decoder)
                return
            if self._raw and header is not None:
                self.sink.on_raw(topic, data, header, self._receipt(receipt))
                return
            decoded = data if header is None else self.decoder.decode(data, header, topic)
            self.sink.on_message(topic, decoded, self._receipt(receipt), len(data) if header is not None else 0)
        except raw_message.DECODE_ERRORS as error:
            self.dropped += 1
            rospy.logwarn_throttle(10.0, 'cannot decode a message of %s: %s' % (topic, error))
        except Exception as error:  # a bad message must not stop the feeder (and so all logging)
            self.dropped += 1
            rospy.logerr_throttle(10.0, 'message of %s not handled: %s: %s'
                                  % (topic, type(error).__name__, error))

    def stop(self):
        """Stop listening, feed what is queued, and wait for the feeder."""
        with self._lock:
            subscribers = list(self.subscribers.values())
        for subscriber in subscribers:
            subscriber.unregister()
        if self._receiver is not None:
            self._receiver.stop()
        self.queue.put(None, force=True)
        self._thread.join()
