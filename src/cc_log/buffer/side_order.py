"""The order of a side topic's records in the window buffer: by stamp, and never far ahead of the driving clock.

``WindowBuffer`` lets a side topic's records go from the front of its deque as the driving clock passes them
(dropped when no window wants them, written when one does). That holds nothing back only when the deque is in
stamp order and holds no stamp the clock will not reach: a record that comes after a later stamped one is put at
its stamp's place (``insert``), and when the driving clock moves on, a record stamped more than ``max_ahead``
seconds after it (a wrong header stamp: 2106, a clock jump) is placed at the clock (``place_ahead``), counted by
the buffer, so it goes into the window at that clock or is let go with the records of its time, and the later
records of its topic flow as before. Pure: records are ``base.records.Record``s, stamps float seconds.
"""
import bisect
import operator

__all__ = ['insert', 'place_ahead', 'none_ahead']

_STAMP = operator.attrgetter('stamp')


def insert(held, record):
    """Put ``record`` into ``held`` (a deque in stamp order) at its stamp's place, after those of the same stamp."""
    if not held or held[-1].stamp <= record.stamp:
        held.append(record)
    else:
        held.insert(bisect.bisect_right(held, record.stamp, key=_STAMP), record)


def place_ahead(held, clock, max_ahead):
    """Place the records of ``held`` (in stamp order) stamped more than ``max_ahead`` seconds after ``clock`` at
    ``clock``, in their order, after those stamped at ``clock`` or before; return how many."""
    limit = clock + max_ahead
    if not held or not held[-1].stamp > limit:
        return 0
    later = []  # the records after the clock, the newest first
    while held and held[-1].stamp > clock:
        later.append(held.pop())
    later.reverse()
    placed = [record._replace(stamp=clock) for record in later if record.stamp > limit]
    held.extend(placed)
    held.extend(record for record in later if record.stamp <= limit)
    return len(placed)


def none_ahead(newest, clock, held, max_ahead):
    """Whether neither ``newest`` (the newest stamp of side records to come) nor any record ``held`` (the deques of
    each topic, in stamp order) lies more than ``max_ahead`` seconds after ``clock``."""
    limit = clock + max_ahead
    return newest <= limit and all(not side or side[-1].stamp <= limit for side in held)
