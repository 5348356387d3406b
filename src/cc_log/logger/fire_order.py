"""When a side record's Fire applies: at the last driving record stamped before it, whatever order topics arrive in.

A Fire marks the newest driving record (``WindowBuffer.trigger``). A side record (an IMU message, a status on a
rule's topic) can be taken before driving records stamped before it: they came on another connection, read later
(the live intake reads every socket in turn), or the driving topic's stamps lag. Its Fires then wait here
(``HeldFires.hold``) and apply just before the first driving record stamped after the side record
(``HeldFires.add``), so the window's span follows the stamps, not the order of arrival; replay and the live node
keep the same window; so does a side record taken before the first driving record. A Fire waits only while what
comes is stamped within ``max_ahead`` of it (past that, the driving topic is silent or its stamps lag: it applies at
the clock, as it would have at once), and never across a jump back of the driving clock; the logger applies what
waits before a flush, a pause or a close. A side record taken after driving records stamped later than it fires at
once, at the newest (it arrived late). Pure.
"""
import bisect
import math

__all__ = ['HeldFires']


class HeldFires(object):
    """The Fires of side records stamped after the driving clock, in the order of their stamps."""

    def __init__(self, driving_topic, max_ahead):
        self.driving_topic = driving_topic
        self.max_ahead = float(max_ahead)
        self._stamps, self._fires = [], []

    def __bool__(self):
        return bool(self._stamps)

    def hold(self, stamp, fires, clock):
        """Hold ``fires`` of a record stamped ``stamp`` when it lies after the driving ``clock`` (the newest driving
        stamp), by ``max_ahead`` at most, or comes before any driving record (``clock`` None: one stamped before the
        first driving record applies before it, where nothing is held yet); return whether they were held."""
        if not (stamp == stamp and (clock is None or clock < stamp <= clock + self.max_ahead)):  # (NaN: never)
            return False
        at = bisect.bisect_right(self._stamps, stamp)
        self._stamps.insert(at, stamp)
        self._fires.insert(at, fires)
        return True

    def release(self, before=math.inf):
        """The held Fires of records stamped before ``before`` (every one by default), in stamp order, let go."""
        at = bisect.bisect_left(self._stamps, before)
        fires = [fire for held in self._fires[:at] for fire in held]
        del self._stamps[:at], self._fires[:at]
        return fires

    def add(self, records, topics, clock, add, fire):
        """Buffer ``records`` (of ``topics``) with ``add(records, topics)``, calling ``fire(Fires)`` with the held
        Fires where they apply among them; ``clock``: the newest driving stamp before them."""
        driving, max_ahead = self.driving_topic, self.max_ahead
        start = 0
        for index, (record, topic) in enumerate(zip(records, topics)):
            if not self._stamps:
                break
            stamp = record.stamp
            if topic == driving:
                due = math.inf if clock is not None and stamp < clock else stamp  # jumped back: every one applies
                clock = stamp
            elif stamp > self._stamps[0] + max_ahead:
                due = stamp - max_ahead  # the driving topic lags: what waited longer applies at the clock
            else:
                continue
            if due > self._stamps[0]:
                if index > start:
                    add(records[start:index], topics[start:index])
                start = index
                fire(self.release(due))
        if start < len(records):
            add(records[start:], topics[start:])
