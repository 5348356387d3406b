"""The manual trigger: a window on request (the nodes' ``~trigger`` and ``~trigger_window`` services).

``request(reason, before, after)`` fires at once with the request's reason (default ``'manual'``) and,
optionally, its own span: ``before`` seconds of the past (as much of it as the logger still holds: at most
its ``pre``) and ``after`` seconds of the future (any length), as rosbag_snapshot's ``TriggerSnapshot``
has start and stop times, with the after-part too. Pure: no rospy.
"""
import math

from cc_log.base.safe_input import brief
from cc_log.base.spans import Span
from cc_log.triggers.base import Fire, Trigger, register

DEFAULT_REASON = 'manual'
MAX_REASON = 200  # characters of a request's reason kept (it goes into metadata and events)
MAX_SECONDS = 86400.0  # the longest before / after a request may ask for (a day: a window streams to disk)


@register
class ManualTrigger(Trigger):
    """Fires on request (see the module docstring); watches no topic."""

    kind = 'manual'

    def __init__(self, name='manual', pre=None, post=None):
        super(ManualTrigger, self).__init__(name, pre, post)

    def request(self, reason='', before=None, after=None):
        """The Fire of one request; ``before``, ``after``: seconds (None or 0: the trigger's or the logger's).
        ValueError('before: ...') for a negative or non-finite span."""
        spans = []
        for name, value, default in (('before', before, self.pre), ('after', after, self.post)):
            if value in (None, 0, 0.0):
                spans.append(default)
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value < 0 or value > MAX_SECONDS:
                raise ValueError('%s: %s must be a number of seconds from 0 to %g' % (name, brief(value), MAX_SECONDS))
            spans.append(Span.duration(value))
        text = ' '.join(str(reason or '').split())[:MAX_REASON] or DEFAULT_REASON
        self.fired += 1
        return Fire(self.name, text, float('nan'), spans[0], spans[1])

    @staticmethod
    def cut_note(before, held, pre):
        """What a reply adds when ``before`` asked for more than the ``held`` seconds (``pre``: the logger's)."""
        if not before or before <= held:
            return ''
        return '; before %g s cut to %.3f s: nothing older is held (the logger keeps ~pre %s)' % (before, held, pre)
