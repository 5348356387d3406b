"""What ``WindowBuffer`` lets go to stay within its memory budget (``max_buffer_mb``), the oldest first.

Outside every window: the oldest records of the ``pre`` buffer and of the side topics go (the newest driving record
stays: a trigger needs it), counted in ``trimmed``. Inside a window nothing goes: its records are handed on in parts.

The driving topic silent while a window is open (an odometry driver dying during an anomaly): the driving clock
ends a window (a duration ``post`` ends it ``post`` after its last trigger, once a driving record shows the clock
past that), and it stands still, so the window stays open while the side topics (cameras, lidar) go on. Its parts
take every side record held up to its end (a ``post`` of messages still to come: every one, the end not known yet);
what they leave lies after its end, outside the window as the driving clock would have judged it had it gone on.
Those records, once a part has been handed on and the budget is still exceeded, go the oldest first, counted in
``trimmed_silent`` (they used to pile up without bound: the window's end never came and the budget did not trim
while it was open). The side stamps advance no clock: the window keeps its end and stays open, a trigger still
extends it, and it ends as always when the driving topic comes back (its first record past the end) or at the end
of the stream. So no side record within the window's span is dropped, its parts hold what a buffer without a budget
writes, and memory stays within the budget.
"""

__all__ = ['BudgetTrim']


class BudgetTrim(object):
    """``_trim_to_budget`` for WindowBuffer (which holds the state it reads and ``_drop_side``)."""

    def _trim_to_budget(self, handed):
        """Let the oldest records go while over the budget: outside every window, or, the open window's records
        ``handed`` on in parts by this call, the side records after its end (see the module docstring)."""
        while self._over_budget() and (self._open is None or handed):
            heads = [(side[0].stamp, topic) for topic, side in self._side.items() if side]
            oldest = min(heads) if heads else None
            if oldest is not None and (len(self._ring) <= 1 or oldest[0] <= self._ring[0].stamp):
                self._drop_side(oldest[1])
            elif len(self._ring) > 1:
                self._bytes -= self._ring.popleft().cost
            else:
                break
            if self._open is None:
                self.trimmed += 1
            else:
                self.trimmed_silent += 1
