"""The one clock that places messages in windows: the driving topic's header stamps set it, and a message
whose header stamp is off that clock is placed at its arrival instead. Pure: used by ``smart.SmartLogger``."""
import math
import operator

__all__ = ['StampClock', 'FOLLOW_AFTER', 'MAX_STAMP']

FOLLOW_AFTER = 3  # driving messages in a row, off the clock and agreeing with each other, that the clock follows
MAX_STAMP = 2.0 ** 33  # seconds beyond any ROS time (uint32 seconds and nanoseconds): a stamp from no clock


class StampClock(object):
    """The driving topic's header stamps set the clock: its offset from the arrival (receipt or bag time) of
    each of its messages (a bag played without its clock keeps its own stamps). Any other message whose header
    stamp is more than ``tolerance`` seconds from its arrival on that clock is placed at that arrival instead
    (before the first driving message, only one stamped after its own arrival: there is no clock yet, and a side
    topic that starts first, a bag's day next to today's arrivals, keeps its stamps): a sensor stamping by another
    clock (wall time next to a bag's, a camera without time sync, a stamp in the future) can neither stretch a
    window nor hold others back.

    A driving message off the clock in the same way (one stamp in 2106, in 1970, 100 s ahead) is placed at its
    arrival too and counted, so one bad stamp cannot flush the messages held before a trigger; FOLLOW_AFTER of
    them in a row whose offsets agree within ``tolerance`` are a real jump of the clock (a bag looped, a clock
    set): the clock follows from the last of them on. An arrival that is no time (NaN, infinite, negative, past
    ``MAX_STAMP``) is the previous arrival (0 before any: the clock has not started), and counted."""

    def __init__(self, driving_topic, tolerance):
        self.driving_topic = driving_topic
        self.tolerance = float(tolerance)
        self.offset = None  # the driving topic's header stamps minus their arrival (None: no driving stamp yet)
        self._jump = []  # the offsets of the driving messages in a row off the clock that agree with each other
        self._arrival = 0.0  # the last arrival that is a time

    def place(self, stamps, arrivals, topics):
        """``(the stamps that place the messages in windows, the topics of those restamped or None)``."""
        if not stamps:
            return stamps, None
        odd = None
        if not (all(map(math.isfinite, arrivals)) and 0 <= min(arrivals) and max(arrivals) < MAX_STAMP):
            stamps, arrivals, odd = self._times(stamps, arrivals, topics)
        self._arrival = arrivals[-1]
        stamps, restamped = self._place(stamps, arrivals, topics)
        return stamps, (restamped or []) + odd if odd else restamped

    def _times(self, stamps, arrivals, topics):
        """``(stamps, arrivals, topics of those replaced)``: each arrival that is no time replaced by the arrival
        before it, and so is the stamp of such a message when it is no time either (it had no header stamp)."""
        stamps, arrivals, odd, last = list(stamps), list(arrivals), [], self._arrival
        for k, arrival in enumerate(arrivals):
            if 0 <= arrival < MAX_STAMP:
                last = arrival
                continue
            arrivals[k] = last
            odd.append(topics[k])
            if not 0 <= stamps[k] < MAX_STAMP:
                stamps[k] = last
        return stamps, arrivals, odd

    def _place(self, stamps, arrivals, topics):
        tolerance, driving = self.tolerance, self.driving_topic
        differences = list(map(operator.sub, stamps, arrivals))
        offset = 0.0 if self.offset is None else self.offset
        if all(arrivals) and max(differences) - min(differences) <= tolerance and self.offset is not None \
                and offset - tolerance <= min(differences) and max(differences) <= offset + tolerance:
            # every stamp within the tolerance of the clock and of each other: none is off, whatever the driving
            # messages among them set the clock to (the common case, checked without a Python step per message)
            if driving in topics:
                self.offset = differences[len(topics) - 1 - topics[::-1].index(driving)]
                self._jump = []
            return stamps, None
        restamped = None
        for k, (difference, arrival, topic) in enumerate(zip(differences, arrivals, topics)):
            if not arrival:  # the clock has not started (use_sim_time before /clock)
                continue
            if topic == driving and (self.offset is None or self._follows(difference, offset)):
                offset = self.offset = difference
            elif difference > offset + tolerance if self.offset is None else \
                    not -tolerance <= difference - offset <= tolerance:
                # before the first driving message there is no clock to judge by: a message keeps its own
                # stamp (a bag played without its clock: the bag's day) unless that is after its arrival
                if restamped is None:
                    stamps, restamped = list(stamps), []
                stamps[k] = arrival + offset
                restamped.append(topic)
        return stamps, restamped

    def _follows(self, difference, offset):
        """Whether the clock takes a driving message's offset ``difference`` (the clock at ``offset``): one
        within the tolerance, or the last of FOLLOW_AFTER in a row off it that agree with each other."""
        if -self.tolerance <= difference - offset <= self.tolerance:
            self._jump = []
            return True
        if self._jump and abs(difference - self._jump[-1]) > self.tolerance:
            self._jump = []
        self._jump.append(difference)
        if len(self._jump) < FOLLOW_AFTER:
            return False
        self._jump = []
        return True
