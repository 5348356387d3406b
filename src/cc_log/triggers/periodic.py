"""The periodic trigger: a window every ``every`` of message time, whatever happens (like Apollo's
RegularIntervalTrigger).

It keeps a nominal sample of the robot's driving at regular intervals: ``pre`` before and ``post`` after the
newest driving message, every ``every`` (``10min``, ``30s``, ``1h``), reason ``periodic``. These samples are
what a model is retrained from when the robot drives unlike its training data (``drift``): a sample that
falls inside an anomaly's window merges with it into one file naming both triggers, so a retraining tool
takes the windows whose only name is the periodic trigger's. The first window comes ``every`` after the
first message; after a gap in message time (a pause, a bag of several runs) one window comes at the first
message past its due time, not one per period missed (and time going back before the last window starts the
count again). Pure: no rospy.
"""
import math
import re

from cc_log.base.spans import Span
from cc_log.triggers.base import Trigger, register

REASON = 'periodic'
_UNITS = {'ms': 0.001, 's': 1.0, 'min': 60.0, 'h': 3600.0}
_EVERY = re.compile(r'\s*([0-9]+(?:\.[0-9]*)?|\.[0-9]+)\s*(ms|s|min|h)\s*')


def parse_every(value, name='every'):
    """Seconds of a period given as ``500ms``, ``30s``, ``10min`` or ``1h`` (a Span of seconds is taken as is);
    ValueError('<name>: ...') for anything else or a period that is not positive."""
    if isinstance(value, Span) and value.is_duration:
        seconds = value.seconds
    else:
        match = _EVERY.fullmatch(value) if isinstance(value, str) else None
        if match is None:
            raise ValueError('%s: %s is not a duration like 30s, 10min or 1h' % (name, repr(value)[:40]))
        seconds = float(match.group(1)) * _UNITS[match.group(2)]
    if not seconds > 0 or not math.isfinite(seconds):
        raise ValueError('%s: %s must be a positive duration' % (name, repr(value)[:40]))
    return seconds


@register
class PeriodicTrigger(Trigger):
    """Fires every ``every`` seconds of message time (see the module docstring); watches no topic, only time.

    every: a duration (``parse_every``); pre, post: this trigger's window (None: the logger's)."""

    kind = 'periodic'
    config_keys = ('every',)
    watches_time = True

    def __init__(self, name='periodic', every=None, pre=None, post=None):
        super(PeriodicTrigger, self).__init__(name, pre, post)
        if every is None:
            raise ValueError('%s: every: required (a duration like 10min)' % name)
        self.every = parse_every(every, '%s: every' % name)
        self.every_text = str(every)
        self.reset()

    def reset(self):
        self._due = None  # message time of the next window (None: set by the next stamp)

    def on_time(self, stamp):
        if self._due is None or stamp < self._due - self.every:  # the start, or time went back past the last window
            self._due = stamp + self.every
            return []
        if stamp < self._due:
            return []
        self._due += self.every  # on the grid of the first message, without a burst after a gap
        if self._due <= stamp:
            self._due = stamp + self.every
        return [self.fire(REASON)]

    def describe(self):
        result = super(PeriodicTrigger, self).describe()
        result['every'] = self.every_text
        return result
