"""A batch of records into the window buffer at once (``WindowBuffer.add_batch``).

The same as ``add`` of each driving record and ``add_side`` of each other one in turn, without a call per record
in the common case: the open window (if any) taking every driving record of the batch and not reaching
``max_window``, the buffer staying within half its budget (with no window open: within its whole budget, with the
parts handed to the writer; a pre buffer of cameras and lidar holds more than half, and the per-record path then
does nothing more), no topic with limits of its own, and driving stamps that
do not go backwards in the batch (then every threshold the per-record path trims and prunes by only rises, so
trimming and pruning once, at the last driving record, leaves what trimming at each one leaves), and no side record
more than ``max_ahead`` after the clock of the driving record after it (which the per-record path places at that
clock; the batch places it so when each side topic's stamps rise through the batch: ``_placed``). A pending window
is completed by ``add`` of the record that completes it, the records before and after it going by slices. Any
other batch goes record by record.
"""
import bisect
import collections
import itertools
import math
import operator

from cc_log.buffer import side_order

_STAMP = operator.attrgetter('stamp')
_COST = operator.attrgetter('cost')
_TOPIC = operator.attrgetter('topic')


class BatchAdd(object):
    """``add_batch`` for WindowBuffer (which holds the state it reads and the per-record ``add``/``add_side``)."""

    def add_batch(self, records, topics, driving):
        """Add ``records`` in order (``topics``: theirs; ``driving``: the driving topic); return the windows this
        completes, as ``add``/``add_side`` of each in turn would."""
        if len(records) < 2:
            return [] if not records else self.add(records[0]) if topics[0] == driving else self.add_side(records[0])
        mask = list(map(driving.__eq__, topics))
        drivings = list(itertools.compress(records, mask))
        ends = self._open_ends(drivings)
        if ends is not None:  # the open window stops at that driving record: the records before and after as batches
            at = [index for index, is_driving in enumerate(mask) if is_driving][ends]
            done = self.add_batch(records[:at], topics[:at], driving) + self.add(records[at])
            return done + self.add_batch(records[at + 1:], topics[at + 1:], driving)
        costs = list(map(_COST, records))
        if not self._batchable(drivings, costs, records, mask):
            done = []
            for record, is_driving in zip(records, mask):
                done.extend(self.add(record) if is_driving else self.add_side(record))
            return done
        ends = self._pending_ends(drivings)
        if ends is not None:  # the pending window completes at that driving record: the rest goes as a batch again
            at = [index for index, is_driving in enumerate(mask) if is_driving][ends]
            done = self.add_batch(records[:at], topics[:at], driving) + self.add(records[at])
            return done + self.add_batch(records[at + 1:], topics[at + 1:], driving)
        self._bytes += sum(costs)
        if not drivings:
            self._extend_side(records, mask)
            return []
        last = len(mask) - 1 - mask[::-1].index(True)
        stamps = list(map(_STAMP, drivings))
        clock = self._clock
        if self._clock is None or stamps[-1] > self._clock:
            self._clock = stamps[-1]
        window = self._open
        if window is not None:
            window.records.extend(drivings)
            window.remaining = max(0, window.remaining - len(drivings))
            self._extend_side(records, mask)
            return []
        self._ring.extend(drivings)
        self._trim_ring(self.pre if self._pending is None else self._bridge)  # (pending: nothing goes, see above)
        self._extend_side(self._placed(records[:last], mask[:last], stamps, clock), mask[:last])
        if self._side:
            self._prune_side()
        self._extend_side(records[last + 1:], mask[last + 1:])
        return []

    def _batchable(self, drivings, costs, records, mask):
        """Whether a batch (its driving records, the costs of all, its records and which are driving ones) can go by
        slices (see the module docstring)."""
        if self.limits or not all(costs) or (self._pending is not None and not self._ring):
            return False
        if self.max_buffer_bytes and self._bytes + sum(costs) > self._part_bytes and (
                self._open is not None or self._bytes + sum(costs) + self._held_elsewhere() > self.max_buffer_bytes):
            return False  # (no window open and within the budget: the per-record path's _enforce_budget does nothing)
        if not drivings:
            return True
        stamps = list(map(_STAMP, drivings))
        if not all(map(operator.le, stamps, stamps[1:])):
            return False
        clock = stamps[-1] if self._clock is None else max(self._clock, stamps[-1])
        if self._clock is not None and stamps[0] < self._clock - self.jump_back_tolerance:
            return False
        window = self._open
        if window is not None:
            if not (window.remaining >= len(drivings) or (window.until is not None and clock <= window.until)):
                return False
            if self.max_window.is_duration:
                first = window.records[0] if window.records else drivings[0]
                return stamps[-1] - first.stamp < self.max_window.seconds
            return len(window.records) + len(drivings) < self.max_window.count
        # one by one, a side record more than max_ahead after the clock of the driving record after it is placed there
        # (``_placed``: as it comes, when each side topic's stamps rise through the batch from what is held)
        sides = list(itertools.compress(records, map(operator.not_, mask)))
        newest = max(map(_STAMP, sides), default=-math.inf)
        first = stamps[0] if self._clock is None else max(self._clock, stamps[0])
        if not side_order.none_ahead(newest, first, self._side.values(), self.max_ahead) and not self._rising(sides):
            return False
        if self._pending is not None:  # until it completes, the ring only grows and the side threshold stays
            return True
        if self.pre.is_duration:  # the newest record stays in the ring: thresholds rise with the clock
            return self._clock is None or stamps[0] >= self._clock - self.pre.seconds
        ring = list(self._ring) + drivings  # the first record held after each driving one: its stamp must rise
        fronts = ring[max(0, len(self._ring) + 1 - (self.pre.count + 1)):max(0, len(ring) - self.pre.count)]
        fronts = list(map(_STAMP, fronts))
        return all(map(operator.le, fronts, fronts[1:]))

    def _rising(self, sides):
        """Whether the stamps of each side topic's records ``sides`` (in arrival order) never go down, from the last
        record held of the topic on."""
        for topic in dict.fromkeys(map(_TOPIC, sides)):
            held = self._side.get(topic)
            stamps = [held[-1].stamp] if held else []
            stamps.extend(record.stamp for record in sides if record.topic == topic)
            if not all(map(operator.le, stamps, stamps[1:])):
                return False
        return True

    def _placed(self, records, mask, stamps, clock):
        """``records`` (those up to the batch's last driving record; ``mask``: True for driving ones, ``stamps``:
        theirs; ``clock``: the buffer's before the batch) with each side record stamped more than ``max_ahead``
        after the clock of the driving record after it placed at that clock (counted in ``restamped``), and the
        held ones the first driving record places first, as ``add`` of each driving record places them
        (``side_order.place_ahead``; ``_batchable``: each topic's stamps rise)."""
        first = stamps[0] if clock is None else max(clock, stamps[0])
        for topic, held in self._side.items():
            if held and held[-1].stamp > first + self.max_ahead:
                self.restamped[topic] += side_order.place_ahead(held, first, self.max_ahead)
        ahead, sides = first + self.max_ahead, list(map(operator.not_, mask))
        late = [index for index in itertools.compress(range(len(records)), sides) if records[index].stamp > ahead]
        if not late:
            return records
        drivings = list(itertools.compress(range(len(records)), mask))
        placed = list(records)
        for index in late:  # (a batch spanning more than max_ahead: only its last side records are looked at)
            at = stamps[bisect.bisect_right(drivings, index)]
            next_clock = at if clock is None else max(clock, at)
            if records[index].stamp > next_clock + self.max_ahead:
                placed[index] = records[index]._replace(stamp=next_clock)
                self.restamped[records[index].topic] += 1
        return placed

    def _open_ends(self, drivings):
        """The index among ``drivings`` (their stamps rising) of the record the open window does not take, its
        ``post`` over (``add`` makes it pending there), None when it takes them all (or none is open). ``add`` takes a
        record while ``remaining`` counts are left or the clock is within ``until``: both hold for a first run."""
        window = self._open
        if window is None or window.remaining >= len(drivings):
            return None
        stamps = list(map(_STAMP, drivings))
        if not all(map(operator.le, stamps, stamps[1:])):
            return None  # (the batch goes record by record)
        takes = window.remaining
        if window.until is not None:
            clock = -math.inf if self._clock is None else self._clock
            takes = max(takes, bisect.bisect_right(stamps, window.until) if clock <= window.until else 0)
        return takes if takes < len(drivings) else None

    def _pending_ends(self, drivings):
        """The index among ``drivings`` of the record after which the pending window completes (a record more than
        ``pre + post`` after it), None when none does (or none is pending). While a window is pending the ring holds
        every driving record after it and drops none, so its first record stays: the first driving record whose
        clock lies more than ``pre + post`` after it ends the wait (counts: the one past ``pre + post`` records)."""
        if self._pending is None or not drivings:
            return None
        bridge, ring = self._bridge, self._ring
        if bridge.is_duration:
            first, seconds, clock = ring[0].stamp, bridge.seconds, self._clock
            ends = bisect.bisect_left(drivings, True, key=lambda record: first < max(clock, record.stamp) - seconds)
        else:
            ends = max(0, bridge.count + 1 - len(ring))
        return ends if ends < len(drivings) else None

    def _extend_side(self, records, mask):
        """Append the records of other topics (``mask``: False for them) to their topics' deques, costs counted."""
        side, side_bytes = self._side, self._side_bytes
        for record in itertools.compress(records, map(operator.not_, mask)):
            topic = record.topic
            held = side.get(topic)
            if held is None:
                held = side[topic] = collections.deque()
                side_bytes[topic] = 0
            if held and record.stamp < held[-1].stamp:  # (side_order.insert; appended inline, the common case)
                side_order.insert(held, record)
            else:
                held.append(record)
            side_bytes[topic] += record.cost
