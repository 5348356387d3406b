"""The row-JSON bytes of serialized messages, estimated from a sample decoded when the figure is asked for.

``RawJsonEstimate`` notes every serialized message the smart logger takes (its type and length: no decoding on
the message path) and keeps the sampled ones; ``total`` (what ``SmartLogger.stats()`` reports as
``raw_json_bytes``) decodes the samples kept since it was last asked, then scales. Samples waiting beyond
``pending_bytes`` are decoded at once, so what is held stays small whoever asks how often.
"""
import itertools
import operator
import threading

from cc_log.base import msg_codec, raw_message

__all__ = ['RawJsonEstimate', 'JSON_SAMPLE_EVERY', 'JSON_SAMPLE_FIRST', 'JSON_SAMPLE_FIRST_BYTES', 'PENDING_BYTES']

JSON_SAMPLE_EVERY = 64  # serialized messages: one in this many is decoded to measure its row-JSON bytes ...
JSON_SAMPLE_FIRST = 64  # ... after the first this many of each type, which all are ...
JSON_SAMPLE_FIRST_BYTES = 1 << 20  # ... while fewer serialized bytes of the type came (a 1 MB image: the first only)
PENDING_BYTES = 4 << 20  # serialized bytes of samples held until asked (beyond: decoded when noted)
_TYPE = operator.itemgetter('type')


class RawJsonEstimate(object):
    """Row-JSON bytes of serialized messages without decoding them all: per message type, the row-JSON
    bytes per serialized byte of the first ``first`` messages (those that came while fewer than ``first_bytes``
    of the type had) and of every ``every``-th one after them, times the serialized bytes of them all (exact up to
    ``first`` messages of a type): decoding a few large messages (images, hostile strings that genpy decodes a byte
    at a time) is bounded as decoding many small ones is. ``count``/``count_all`` only
    note (one thread at a time); the samples are decoded by ``total`` (any thread) or once more than
    ``pending_bytes`` wait."""

    def __init__(self, every=JSON_SAMPLE_EVERY, first=JSON_SAMPLE_FIRST, pending_bytes=PENDING_BYTES,
                 first_bytes=JSON_SAMPLE_FIRST_BYTES):
        self.every = int(every)
        self.first = int(first)
        self.first_bytes = int(first_bytes)
        self.pending_bytes = int(pending_bytes)
        self._counter = msg_codec.RowJsonCounter()
        self._types = {}  # type -> [messages, serialized bytes, sampled serialized bytes, sampled JSON bytes]
        self._pending = []  # (entry of _types, raw, connection) sampled, not decoded yet
        self._held = 0  # serialized bytes of _pending
        self._lock = threading.Lock()  # _pending, _held and the sampled sums
        self._decoding = threading.Lock()  # one decoder at a time (the counter's memo)

    def _entry(self, msg_type):
        entry = self._types.get(msg_type)
        if entry is None:
            entry = self._types[msg_type] = [0, 0, 0, 0]
        return entry

    def count(self, raw, connection):
        """Note one message (its bytes and connection header)."""
        entry = self._entry(connection['type'])
        if (entry[0] < self.first and entry[1] < self.first_bytes) or entry[0] % self.every == 0:
            self._keep([(entry, raw, connection)])
        entry[0] += 1
        entry[1] += len(raw)

    def count_all(self, raws, connections):
        """``count`` of each message in turn (``raws`` and their ``connections``), looking each type up once."""
        if len(raws) <= 4:  # a live batch: the bookkeeping of a batch would cost more than it saves
            for raw, connection in zip(raws, connections):
                self.count(raw, connection)
            return
        types = list(map(_TYPE, connections))
        sampled = []
        for msg_type in dict.fromkeys(types):
            if types.count(msg_type) == len(types):
                places = range(len(raws))
            else:
                places = list(itertools.compress(range(len(raws)), map(msg_type.__eq__, types)))
            entry = self._entry(msg_type)
            seen = entry[0]
            sizes = list(map(len, map(raws.__getitem__, places)))
            head = sizes[:max(self.first - seen, 0)]  # the first of the type, while fewer than first_bytes came
            before = itertools.accumulate(head, initial=entry[1])  # the type's bytes before each of them
            first = range(min(len(head), sum(1 for _ in itertools.takewhile(self.first_bytes.__gt__, before))))
            every = range((-seen) % self.every, len(places), self.every)  # and every every-th
            sampled.extend((entry, raws[places[k]], connections[places[k]])
                           for k in sorted(set(itertools.chain(first, every))))
            entry[0] += len(places)
            entry[1] += sum(sizes)
        if sampled:
            self._keep(sampled)

    def _keep(self, samples):
        with self._lock:
            self._pending.extend(samples)
            self._held += sum(len(raw) for _, raw, _ in samples)
            full = self._held > self.pending_bytes
        if full:
            self._decode()

    def _decode(self):
        """Decode the samples held and add them to their types' sums."""
        with self._decoding:
            with self._lock:
                pending, self._pending, self._held = self._pending, [], 0
            sums = []
            for entry, raw, connection in pending:
                try:
                    json_bytes = self._counter.count(raw_message.decode(raw, connection))
                except raw_message.DECODE_ERRORS:
                    continue
                sums.append((entry, len(raw), json_bytes))
            with self._lock:
                for entry, size, json_bytes in sums:
                    entry[2] += size
                    entry[3] += json_bytes

    @property
    def total(self):
        """Estimated row-JSON bytes of every message noted (the samples held are decoded now)."""
        self._decode()
        with self._lock:
            return int(round(sum(json_bytes * size / sampled
                                 for _, size, sampled, json_bytes in list(self._types.values()) if sampled)))
