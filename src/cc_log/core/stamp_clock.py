"""The one clock that places messages in windows: the driving topic's header stamps set it, and a message
whose header stamp is off that clock is placed at its arrival instead. Pure: used by ``smart.SmartLogger``."""
import operator

__all__ = ['StampClock']


class StampClock(object):
    """The driving topic's header stamps set the clock: its offset from the arrival (receipt or bag time) of
    each of its messages (0 before the first; a bag played without its clock keeps its own stamps). Any other
    message whose header stamp is more than ``tolerance`` seconds from its arrival on that clock is placed at
    that arrival instead: a sensor stamping by another clock (wall time next to a bag's, a camera without time
    sync, a stamp in the future) can neither stretch a window nor hold others back."""

    def __init__(self, driving_topic, tolerance):
        self.driving_topic = driving_topic
        self.tolerance = float(tolerance)
        self.offset = 0.0  # the driving topic's header stamps minus their arrival

    def place(self, stamps, arrivals, topics):
        """``(the stamps that place the messages in windows, the topics of those restamped or None)``."""
        tolerance, driving, offset = self.tolerance, self.driving_topic, self.offset
        if not stamps:
            return stamps, None
        differences = list(map(operator.sub, stamps, arrivals))
        if all(arrivals) and max(differences) - min(differences) <= tolerance \
                and offset - tolerance <= min(differences) and max(differences) <= offset + tolerance:
            # every stamp within the tolerance of the clock and of each other: none is off, whatever the driving
            # messages among them set the clock to (the common case, checked without a Python step per message)
            if driving in topics:
                self.offset = differences[len(topics) - 1 - topics[::-1].index(driving)]
            return stamps, None
        restamped = None
        for k, (stamp, arrival, topic) in enumerate(zip(stamps, arrivals, topics)):
            if not arrival:  # the clock has not started (use_sim_time before /clock)
                continue
            if topic == driving:
                offset = stamp - arrival
            elif not -tolerance <= stamp - arrival - offset <= tolerance:
                if restamped is None:
                    stamps, restamped = list(stamps), []
                stamps[k] = arrival + offset
                restamped.append(topic)
        self.offset = offset
        return stamps, restamped
