"""The window buffer of smart mode.

It holds the *logging windows* of the driving topic (the topic whose messages count ``pre`` and ``post``):
on a trigger at message i, messages i-pre ... i+post are kept. A trigger inside an open window extends it
(and reaches back before its start when its own pre is longer than the one that opened it: a goal abort after a
classifier's flag; the buffer holds its pre of driving messages for that until the window's first part is
written), and two windows that overlap, touch or lie closer than ``post`` (the gap from the end of one to the
start of the next) become one, with the messages between, so no message is written twice, none inside a window
is skipped and a window is not cut in two files by a short calm: a closed window waits ``pre + post`` more
(counts with counts, durations with durations; else ``pre``) before it is handed on. Messages of other topics are
buffered by time (``side_order``: in stamp order, one stamped more than ``max_ahead`` after the driving clock placed
at it, counted in ``restamped``) and saved in the windows whose time span holds them. (The feature window the
classifiers score is ``features.FeatureWindow``.)

Memory is bounded by ``max_buffer_mb``: every message buffered (driving and other topics, in or outside a
window) counts with its estimated memory cost (``Record.cost``, else ``MemoryCost``: a message held as its
serialized bytes costs their length plus ``RAW_RECORD_OVERHEAD``). An open window is
handed on in parts (as ``max_window`` splits it, with every message of other topics held) whenever the
buffer reaches half the budget, so that the buffer and the part being compressed and written stay within
the budget together. At the full budget a window waiting to be completed is completed, then messages
outside every window (the ``pre`` buffer, oldest first) go, counted in ``trimmed``, and while the driving topic is
silent in an open window, side records after its end (``budget_trim``). No message inside a window is ever dropped.

Everything is pure Python: records carry any message object, stamps are float seconds.
"""
import collections
import itertools
import math
import sys

from cc_log.base.records import LogWindow, Trigger
from cc_log.base import spans
from cc_log.base.spans import Span
from cc_log.buffer import side_order
from cc_log.buffer.budget_trim import BudgetTrim
from cc_log.buffer.window_batch import BatchAdd

DEFAULT_PRE = Span.parse('2s')   # durations: the same margin at any rate (100 messages: 1 s at 100 Hz, 20 s at 5 Hz)
DEFAULT_POST = Span.parse('2s')
DEFAULT_MAX_WINDOW = Span.messages(100000)
DEFAULT_JUMP_BACK_TOLERANCE = 1.0  # seconds a stamp may go backwards before the buffer resets
DEFAULT_MAX_BUFFER_MB = 256.0      # memory budget of everything buffered (MB = 10^6 bytes); 0: none
DEFAULT_MAX_AHEAD = 10.0           # seconds a side record may lie after the driving clock as it moves on (else: at it)
MB = 1000 ** 2
RECORD_OVERHEAD = 130              # bytes of a Record around its message: the tuple, stamp, cost, a deque slot
ALLOCATOR_FACTOR = 1.15            # measured RSS per buffered nav_msgs/Odometry / its deep sys.getsizeof
RAW_RECORD_OVERHEAD = 200          # bytes of a Record of serialized bytes besides their length: the tuple, stamp,
#                                    cost, the bytes object's header, a deque slot (193 measured by tracemalloc)


def deep_size(obj):
    """Bytes of ``obj`` and everything it holds (sys.getsizeof over slots, lists, tuples, dicts; shared
    objects counted once)."""
    seen = set()
    total = 0
    stack = [obj]
    while stack:
        item = stack.pop()
        if id(item) in seen:
            continue
        seen.add(id(item))
        total += sys.getsizeof(item)
        if isinstance(item, (str, bytes, bytearray, int, float, complex, bool)) or item is None:
            continue
        if isinstance(item, (list, tuple, set, frozenset)):
            stack.extend(item)
        elif isinstance(item, dict):
            stack.extend(item.keys())
            stack.extend(item.values())
        else:
            for cls in type(item).__mro__:
                for name in getattr(cls, '__slots__', ()):
                    if isinstance(name, str) and hasattr(item, name):
                        stack.append(getattr(item, name))
            if hasattr(item, '__dict__'):
                stack.append(item.__dict__)
    return total


class MemoryCost(object):
    """Estimated memory of a buffered message, cheap: the deep size of the first message of each type is
    measured once (``deep_size``, times ALLOCATOR_FACTOR, plus RECORD_OVERHEAD) and memoised; when the
    serialized length of messages is known (``size``), later messages of the type scale it by their length
    over the first one's, so a scan or an image twice as long counts twice. Not thread-safe (one per owner)."""

    def __init__(self):
        self._memo = {}

    def of(self, record):
        """Bytes ``record`` takes: its serialized length plus RAW_RECORD_OVERHEAD when it holds only its
        bytes, else the estimate of its message."""
        if record.msg is None and record.raw is not None:
            return len(record.raw) + RAW_RECORD_OVERHEAD
        return self(record.msg, len(record.raw) if record.raw is not None else None)

    def __call__(self, msg, size=None):
        """Bytes ``msg`` takes in memory, estimated (``size``: its serialized length, or None)."""
        memo = self._memo.get(type(msg))
        if memo is None:
            memo = self._memo[type(msg)] = (int(deep_size(msg) * ALLOCATOR_FACTOR) + RECORD_OVERHEAD, size)
        cost, first = memo
        if size and first:
            return max(RECORD_OVERHEAD, cost * size // first)
        return cost


def part_bytes(budget):
    """The most a buffer of ``budget`` bytes holds before it hands a window on in parts: half of it, the other
    half being for the part the writer is busy with."""
    return budget // 2


def budget_bytes(max_buffer_mb, name='max_buffer_mb'):
    """``max_buffer_mb`` (a number >= 0; 0 or None: no budget) in bytes; ValueError('<name>: ...')."""
    try:
        number = float(max_buffer_mb or 0)
    except (TypeError, ValueError):
        number = float('nan')
    if not number >= 0 or number == float('inf'):
        raise ValueError('%s: %r must be a number of MB >= 0 (0: no budget)' % (name, max_buffer_mb))
    return int(number * MB)


def _slices(records, limit):
    """``records`` cut into consecutive lists of at most ``limit`` bytes of cost each (at least one record each)."""
    piece, cost = [], 0
    for record in records:
        if piece and cost + record.cost > limit:
            yield piece
            piece, cost = [], 0
        piece.append(record)
        cost += record.cost
    if piece:
        yield piece


class _OpenWindow(object):
    """A window still collecting driving records (open) or waiting to learn whether the next one touches
    it (pending)."""

    _keys = itertools.count(1)

    def __init__(self, records, trigger, post, since, before=()):
        self.key = next(self._keys)
        self.records = list(records)
        self.since = since     # first stamp of its time span (side records from here on belong to it)
        # driving records of the pre buffer before its start, held until its first part is written: a later
        # trigger with a longer pre reaches back into them (a goal abort after a classifier's short pre)
        self.before = list(before)
        self.triggers = []
        self.part = 0
        self.continued = False  # a part was written: side records after it belong to the next part
        self.remaining = 0     # messages still to take after the last trigger (count post)
        self.until = None      # last stamp to take (duration post)
        self.extend(trigger, post)

    @property
    def reach(self):
        """The first stamp a trigger with a longer pre may still reach back to (side records from here on)."""
        return min(self.since, self.before[0].stamp) if self.before else self.since

    def reach_back(self, pre):
        """A trigger at the newest record with ``pre``: start earlier when the records held before the start
        hold what ``pre`` asks for (never once a part was written)."""
        before = self.before
        if self.continued or not before:
            return
        if pre.is_duration:
            low = self.records[-1].stamp - pre.seconds
            cut = len(before)
            while cut and before[cut - 1].stamp >= low:
                cut -= 1
            self.since = min(self.since, low)
        else:
            cut = max(0, len(before) - max(0, pre.count - (len(self.records) - 1)))
            if cut < len(before):
                self.since = min(self.since, before[cut].stamp)
        if cut < len(before):
            self.records[:0] = before[cut:]
            del before[cut:]

    def extend(self, trigger, post):
        """Add a trigger; the window takes what the longest post of its triggers still asks for."""
        self.triggers.append(trigger)
        if post.is_duration:
            until = trigger.stamp + post.seconds
            self.until = until if self.until is None else max(self.until, until)
        else:
            self.remaining = max(self.remaining, post.count)

    def takes(self, stamp):
        """Whether a driving record at ``stamp`` still belongs to this window."""
        return self.remaining > 0 or (self.until is not None and stamp <= self.until)

    def take(self, record):
        self.records.append(record)
        if self.remaining > 0:
            self.remaining -= 1


def _sum(pre, post):
    """``pre + post`` as one Span when both are counts or both durations, else ``pre``."""
    if pre.is_duration and post.is_duration:
        return Span.duration(pre.seconds + post.seconds)
    if not pre.is_duration and not post.is_duration:
        return Span.messages(pre.count + post.count)
    return pre


class WindowBuffer(BatchAdd, BudgetTrim):
    """Logging windows around triggers.

    Call ``add`` for every driving message, ``add_side`` for messages of other topics (``add_batch`` for several
    of both), ``trigger`` when the last driving message is anomalous, and ``flush`` at the end of the
    stream. ``add``, ``add_side``, ``trigger`` and ``flush`` return the windows completed by that call (a
    list of LogWindow); a window is complete once ``pre + post`` further messages have shown that the next
    window does not come within ``post`` of it, or when it reaches ``max_window`` or the memory budget
    ``max_buffer_mb`` (written in parts). ``cost``: the MemoryCost estimating records that carry no cost.
    ``part_factor``: the memory the writer needs for a part per byte of it (>= 1; a format that decodes serialized
    messages needs several times their size): parts are handed on at half the budget divided by it. ``max_ahead``:
    seconds (> 0) a side record may lie after the driving clock when the clock moves on (else it is placed at it).
    """

    def __init__(self, pre=DEFAULT_PRE, post=DEFAULT_POST, max_window=DEFAULT_MAX_WINDOW,
                 jump_back_tolerance=DEFAULT_JUMP_BACK_TOLERANCE, max_buffer_mb=DEFAULT_MAX_BUFFER_MB, cost=None,
                 part_factor=1.0, topic_limits=None, held_elsewhere=None, max_ahead=DEFAULT_MAX_AHEAD):
        self.pre = Span.parse(pre, 'pre')
        self.post = Span.parse(post, 'post')
        self.max_window = Span.parse(max_window, 'max_window')
        if self.max_window.count == 0 or self.max_window.seconds == 0:
            raise ValueError('max_window: must hold at least one message')
        if (self.pre.is_duration == self.max_window.is_duration) and \
                (self.pre.count or self.pre.seconds or 0) >= (self.max_window.count or self.max_window.seconds):
            raise ValueError('pre: %s is larger than the buffer can hold (max_window %s)' % (self.pre, self.max_window))
        self.jump_back_tolerance = jump_back_tolerance
        self.max_ahead = spans.seconds(max_ahead, 'max_ahead', positive=True)
        self.max_buffer_bytes = budget_bytes(max_buffer_mb)
        self._part_bytes = int(part_bytes(self.max_buffer_bytes) / max(1.0, float(part_factor)))
        self._cost = cost if cost is not None else MemoryCost()
        self._pre_count = None if self.pre.is_duration else self.pre.count  # (None: a duration)
        self._bridge = _sum(self.pre, self.post)  # a closed window waits this long for the next (closer than post)
        self._max_count = None if self.max_window.is_duration else self.max_window.count
        self._bytes = 0                    # estimated memory of every record held
        self.trimmed = 0                   # records outside any window dropped early to stay within the budget
        self.trimmed_silent = 0            # side records after the open window's end dropped so (budget_trim)
        self.limited = 0                   # records outside any window dropped by their topic's own pre or cap
        self._ring = collections.deque()   # driving records outside any window: the newest plus pre before it
        self._side = {}                    # topic -> its records (other topics than the driving one), by time
        self._side_bytes = {}              # topic -> memory of its records held
        self.limits = dict(topic_limits or {})  # topic -> options.TopicLimits (pre, post, max_mb)
        self._held_elsewhere = held_elsewhere or (lambda: 0)  # bytes of parts handed on and not yet written
        self._open = None                  # window taking driving records
        self._pending = None               # closed window that the next one may still join (within post)
        self._clock = None                 # newest stamp seen (stamps may jitter backwards a little)
        self.resets = 0                    # times time jumped backwards and the buffer started over
        self.restamped = collections.Counter()  # topic -> side records placed at the driving clock (far after it)

    # -- logging windows ------------------------------------------------------------------------------

    @property
    def window_open(self):
        """True while a logging window is taking messages."""
        return self._open is not None

    @property
    def buffered_bytes(self):
        """Estimated memory (bytes) of the messages held (see ``buffered_messages``)."""
        return self._bytes

    @property
    def part_limit(self):
        """Bytes of an open window's records held before they are handed on as a part (0: no budget)."""
        return self._part_bytes

    @property
    def buffered_messages(self):
        """Messages held in memory: pre buffer, windows not yet written, other topics."""
        held = len(self._ring) + sum(map(len, self._side.values()))
        for window in (self._open, self._pending):
            if window is not None:
                held += len(window.records) + len(window.before)
        return held

    def add(self, record):
        """Add a driving record; return the windows this completes."""
        if not record.cost:
            record = self._costed(record)
        done = []
        stamp, clock = record.stamp, self._clock
        if clock is not None and stamp < clock - self.jump_back_tolerance:
            done.extend(self.flush())
            self._reset()
            clock = None
        if clock is None or stamp > clock:
            self._clock = clock = stamp
        window = self._open
        if window is not None:
            if window.remaining > 0 or (window.until is not None and clock <= window.until):  # window.takes(clock)
                window.take(record)
                self._bytes += record.cost
                if self._max_count is None or len(window.records) >= self._max_count:
                    done.extend(self._split(window))
                if self.max_buffer_bytes and self._bytes > self._part_bytes:
                    done.extend(self._enforce_budget())
                return done
            # Pending even when a split left it empty: a touching window continues its parts.
            self._pending, self._open = window, None
        ring = self._ring
        ring.append(record)
        self._bytes += record.cost
        if self._pending is not None:  # a trigger within post after its end (pre before it) joins the two windows
            if self._trim_ring(self._bridge):
                done.extend(self._finish(self._pending))
                self._pending = None
                self._trim_ring(self.pre)
        elif self._pre_count is None or len(ring) > self._pre_count + 1:  # else nothing to trim
            self._trim_ring(self.pre)
        if self._side:
            self._prune_side()
        if self.max_buffer_bytes and self._bytes > self._part_bytes:
            done.extend(self._enforce_budget())
        return done

    def add_side(self, record):
        """Add a record of another topic; it is saved in the window whose time span holds it. Returns the
        windows this completes (parts written because the memory budget was reached)."""
        if not record.cost:
            record = self._costed(record)
        topic = record.topic
        side = self._side.get(topic)
        if side is None:
            side = self._side[topic] = collections.deque()
            self._side_bytes[topic] = 0
        newest = side[-1].stamp if side else record.stamp
        side_order.insert(side, record)
        self._side_bytes[topic] += record.cost
        self._bytes += record.cost
        limits = self.limits.get(topic)
        if limits is not None and self._open is None and self._pending is None:  # a stamp far ahead trims nothing
            clock = newest if self._clock is None else max(newest, self._clock)  # (of the clock or its topic's newest)
            self._limit_topic(topic, side, limits, record.stamp if record.stamp <= clock + self.max_ahead else clock)
        if self.max_buffer_bytes and self._bytes > self._part_bytes:
            return self._enforce_budget()
        return []

    def _limit_topic(self, topic, side, limits, clock):
        """Outside every window: a topic's records older than its own ``pre`` or beyond its own memory cap go
        (counted in ``limited``), the oldest first."""
        while side and ((limits.pre is not None and side[0].stamp < clock - limits.pre)
                        or (limits.max_mb and self._side_bytes[topic] > limits.max_mb * MB and len(side) > 1)):
            self._drop_side(topic)
            self.limited += 1

    def _drop_side(self, topic, count=1):
        """Let the ``count`` oldest records of ``topic`` go (their costs counted off); return the last of them."""
        side = self._side[topic]
        gone = [side.popleft() for _ in range(count)]
        cost = sum(record.cost for record in gone)
        self._side_bytes[topic] -= cost
        self._bytes -= cost
        return gone[-1]

    def trigger(self, reason, score=None, name=None, pre=None, post=None, why=()):
        """Mark the last driving record: open a window around it or extend the open one.

        ``name``: of the trigger (None: ``reason``); ``pre``, ``post``: this trigger's Spans (None: the buffer's);
        ``why``: the features that stood out (kept with the trigger). A ``pre`` longer than the buffer's gets what
        the buffer holds (its ``pre``). A trigger with a longer ``pre`` than the one that opened the window reaches
        back as far as the buffer held when it opened, until a part of the window is written. Returns the windows
        this completes: parts of a window that reached max_window, and the pending window when this trigger's
        ``pre`` starts more than ``post`` after it (``joins``; a new window else extends the open one or merges with
        the pending one, which is completed as soon as a message after it leaves ``pre + post``).
        """
        if self._clock is None:
            raise ValueError('trigger: no message has been added yet')
        trigger = Trigger(self._clock, reason, score, name, tuple(why))
        post = self.post if post is None else Span.parse(post, 'post')
        pre = self.pre if pre is None else Span.parse(pre, 'pre')
        if self._open is not None:
            self._open.extend(trigger, post)
            self._open.reach_back(pre)
            return []
        done = []
        if self._pending is not None and not self.joins(pre):  # its pre starts more than post after the pending
            done, self._pending = self._finish(self._pending), None
        if self._pending is not None:
            # Every record after the pending window is still in the ring: the new window joins it.
            self._open, self._pending = self._pending, None
            self._open.records.extend(self._ring)
            self._open.extend(trigger, post)
            self._open.reach_back(pre)
        else:
            before = self._older_than(pre) if pre is not self.pre else ()
            since = min(trigger.stamp - pre.seconds if pre.is_duration else trigger.stamp, self._ring[0].stamp)
            self._open = _OpenWindow(self._ring, trigger, post, since, before)
        self._ring.clear()
        return done + self._split(self._open)

    def joins(self, pre=None):
        """Whether a trigger at the newest driving record, with its ``pre`` (None: the buffer's), joins a window:
        the open one, or the pending one when its ``pre`` reaches within ``post`` of it (the ring holds every record
        after the pending window: they all lie within ``pre + post``)."""
        if self._open is not None:
            return True
        if self._pending is None:
            return False
        span, ring = _sum(self.pre if pre is None else Span.parse(pre, 'pre'), self.post), self._ring
        if span.is_duration:
            return not ring or ring[0].stamp >= self._clock - span.seconds
        return len(ring) <= span.count + 1

    def oldest(self):
        """The stamp of the oldest driving record a trigger at the newest one can still keep (None before any):
        the start of the window it joins (once a part was written: the start of its span), else of the pre
        buffer, which holds ``pre`` before the newest record at most."""
        for window in (self._open, self._pending):
            if window is not None and (window.records or window.continued):
                if window.continued:
                    return window.since
                return min(window.records[0].stamp, window.before[0].stamp if window.before else math.inf)
        return self._ring[0].stamp if self._ring else None

    def _older_than(self, pre):
        """Take from the ring the driving records older than ``pre`` before the newest (still counted)."""
        ring, older = self._ring, []
        if pre.is_duration:
            while ring and ring[0].stamp < self._clock - pre.seconds:
                older.append(ring.popleft())
        else:
            while len(ring) > pre.count + 1:
                older.append(ring.popleft())
        return older

    @property
    def window_start(self):
        """Stamp of the first driving record of the open window (None when none is open or it was split)."""
        if self._open is None or not self._open.records or self._open.continued:
            return None
        return self._open.records[0].stamp

    def _trim_ring(self, pre):
        """Keep the newest driving record plus ``pre`` before it (the others stay outside every window);
        return whether any was dropped."""
        dropped = self._older_than(pre)
        for record in dropped:
            self._bytes -= record.cost
        return bool(dropped)

    def flush(self):
        """Complete every window now (end of stream): the open one is written with what it has, messages of
        other topics that came after its last driving message included (its span had not ended)."""
        done = []
        if self._pending is not None:
            done.extend(self._finish(self._pending))
        if self._open is not None:
            done.extend(self._finish(self._open, everything=True))
        self._pending = self._open = None
        return done

    def _finish(self, window, everything=False):
        """The last part of a window (or the whole window; ``everything``: with every side record held from its
        start on); nothing for a window that holds nothing."""
        if window.records or (everything and any(self._side.values())):
            return [self._emit(window, everything=everything)]
        if window.part:  # its records went out in parts: say that it ended
            return [LogWindow([], list(window.triggers), window.part, True, window.key)]
        return []

    def _reset(self):
        """Start over after time jumped backwards (bag loop, simulator reset)."""
        self.resets += 1
        self._bytes -= sum(record.cost for record in self._ring) + sum(self._side_bytes.values())
        self._ring.clear()
        self._side.clear()
        self._side_bytes.clear()
        self._clock = None

    def _costed(self, record):
        if record.cost:
            return record
        return record._replace(cost=self._cost.of(record))

    def _over_budget(self):
        return self.max_buffer_bytes and self._bytes + self._held_elsewhere() > self.max_buffer_bytes

    def _enforce_budget(self):
        """Stay within max_buffer_mb (see the module docstring); return the windows completed doing so."""
        done = []
        if not self.max_buffer_bytes or (self._bytes <= self._part_bytes and not self._over_budget()):
            return done
        window = self._open
        handed = window is not None and self._bytes > self._part_bytes and (window.records or any(self._side.values()))
        if handed:
            # Written in parts, as max_window splits: what the window holds now, with every side record held,
            # in parts of at most part_limit (a pre-buffer larger than that, at a window's start, goes on as several
            # parts: the writer frees each one as it is written, so the next parts of the window fit the budget).
            window.part = max(window.part, 1)
            whole = self._emit(window, everything=True, final=False)
            for records in _slices(whole.records, self._part_bytes):
                done.append(LogWindow(records, whole.triggers, window.part, False, window.key))
                window.part += 1
            window.records = []
            window.continued = True
        if self._over_budget() and self._pending is not None:
            done.extend(self._finish(self._pending))
            self._pending = None
        self._trim_to_budget(bool(handed))  # outside every window, or after the open one's end (budget_trim)
        return done

    def _full(self, window):
        if self.max_window.is_duration:
            return window.records[-1].stamp - window.records[0].stamp >= self.max_window.seconds
        return len(window.records) >= self.max_window.count

    def _split(self, window):
        """Emit the parts of a window that reached max_window; the rest goes on as the next part."""
        done = []
        while window.records and self._full(window):
            size = self.max_window.count or len(window.records)
            window.part = max(window.part, 1)
            done.append(self._emit(window, window.records[:size], final=False))
            window.part += 1
            window.records = window.records[size:]
            window.continued = True
        return done

    def _prune_side(self):
        """Drop records of other topics older than the span of the window that may still take them (outside
        every window: older than ``pre`` before the newest driving record, or than their topic's own ``pre``)."""
        if self._pending is not None and self._pending.records:
            oldest = self._pending.reach
        elif self._open is not None and self._open.records:
            oldest = self._open.reach
        elif self._ring:
            oldest = self._ring[0].stamp
            if self.pre.is_duration:  # a window opened now reaches back pre seconds, past its first driving record
                oldest = min(oldest, self._clock - self.pre.seconds)
        else:
            return
        free, ahead = self._open is None and self._pending is None, self._clock + self.max_ahead
        for topic, side in self._side.items():
            if side and side[-1].stamp > ahead:
                self._place_ahead(topic, side)
            older = next((k for k, record in enumerate(side) if record.stamp >= oldest), len(side))
            if older:
                self._drop_side(topic, older)
            limits = self.limits.get(topic)
            if free and limits is not None and side:
                self._limit_topic(topic, side, limits, self._clock)

    def _place_ahead(self, topic, side):
        """Place the records of a side topic stamped more than ``max_ahead`` after the driving clock at it."""
        placed = side_order.place_ahead(side, self._clock, self.max_ahead)
        if placed:
            self.restamped[topic] += placed

    def _emit(self, window, records=None, everything=False, final=True):
        """Turn a window (or the given first records of it) into a LogWindow with the side records of its
        time span (``everything``: every side record held from its start on), in stamp order. A part after
        the first takes the side records since the previous part (those of its time span and those between, none
        before the window's start: a late record stamped there is let go). A topic with its own ``pre`` or
        ``post`` (``limits``) keeps only what lies within them of the window's first and last trigger."""
        if window.before:  # a part goes out: no later trigger reaches back before it
            self._bytes -= sum(record.cost for record in window.before)
            window.before = []
        records = window.records if records is None else records
        start = window.since
        end = records[-1].stamp if records else float('-inf')
        if window.until is not None and (final or everything):
            end = max(end, window.until)  # its span ends at the post of its last trigger, not at a driving record
        elif everything:
            end = float('inf')
        cost = sum(record.cost for record in records)
        side = []
        triggers = window.triggers
        for topic, held in self._side.items():
            low, high = start, end
            limits = self.limits.get(topic)
            if limits is not None and triggers:
                if limits.pre is not None:
                    low = max(low, triggers[0].stamp - limits.pre)
                if limits.post is not None:
                    high = min(high, max(trigger.stamp for trigger in triggers) + limits.post)
            taken = 0
            while held and held[0].stamp <= end:
                record = held.popleft()
                taken += record.cost
                if low <= record.stamp <= high:
                    side.append(record)
            self._side_bytes[topic] -= taken
            cost += taken
        self._bytes -= cost
        if side:
            records = sorted(records + side, key=lambda record: record.stamp)
        return LogWindow(list(records), list(window.triggers), window.part, final, window.key)
