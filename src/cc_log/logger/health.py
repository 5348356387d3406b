"""What a logger's counters say about it on /diagnostics: the level and the message (pure).

Levels are diagnostic_msgs' (``OK``, ``WARN``, ``ERROR``). ``smart_head(stats)`` is the smart logger's own
status before the writer's and the disk's part: WARN while it is paused (nothing is kept) or when messages of
the wrong type were refused. ``not_kept(stats, overflowed)`` lists the messages that belonged in a window and
are not on disk: thinned while the writer fell behind, trimmed from the buffer to stay within
``max_buffer_mb`` (a window opened then starts later than ``pre``), or dropped by a full intake queue; each is
a WARN. ``skipped(stats)``: the windows the keep budget did not open (WARN: the robot's normal may have drifted).
``DrivingWatch`` says when the driving topic is silent and where its message type is published instead.
``worst(level, message, problems)`` adds problems to a status.
"""
from cc_log.logger import keep_budget

OK, WARN, ERROR = 0, 1, 2  # diagnostic_msgs/DiagnosticStatus levels
SILENCE = 5.0  # seconds without a driving message (after start or the last one) before the node warns

__all__ = ['OK', 'WARN', 'ERROR', 'SILENCE', 'smart_head', 'not_kept', 'skipped', 'worst', 'per_topic',
           'DrivingWatch']


def per_topic(counts):
    """``{topic: n}`` as one line, largest first ('none' when empty)."""
    return ', '.join('%s: %d' % item for item in sorted(counts.items(), key=lambda item: (-item[1], item[0]))) or 'none'


def smart_head(stats):
    """``(level, message)`` of a smart logger's ``stats()`` before the writer's part: paused (WARN), messages
    of the wrong type refused (WARN), else OK 'logging'."""
    if not stats['enabled']:
        return WARN, 'paused (~enable false): nothing is kept until it is enabled'
    if stats['messages_refused']:
        return WARN, '%d messages of the wrong type refused (last: %s)' % (
            stats['messages_refused'], stats['last_refused'])
    return OK, 'logging'


def not_kept(stats, overflowed=0):
    """``[(WARN, text)]``: the messages that belonged in a window and are not on disk (see the module)."""
    problems = []
    if stats['messages_shed']:
        problems.append((WARN, '%d messages of windows not written: the writer fell behind (%s)' % (
            stats['messages_shed'], per_topic(stats['shed_by_topic']))))
    if stats['buffer_trimmed']:
        problems.append((WARN, '%d messages trimmed from the buffer to stay within ~max_buffer_mb (a window '
                               'then starts later than ~pre)' % stats['buffer_trimmed']))
    if overflowed:
        problems.append((WARN, '%d messages dropped: intake queue full (the node falls behind)' % overflowed))
    return problems


def skipped(stats):
    """``[(WARN, text)]`` once the keep budget skipped a window (``keep_budget.report``), else ``[]``."""
    text = keep_budget.report(stats)
    return [(WARN, text)] if text else []


def skipped_value(stats):
    """The diagnostics value of the windows the keep budget skipped: their count and score range."""
    if not stats.get('windows_skipped'):
        return '0' if stats.get('max_windows_per_hour') else '0 (no keep budget)'
    return '%d (scores %.3g .. %.3g)' % ((stats['windows_skipped'],) + tuple(stats['skipped_score_range']))


def worst(level, message, problems):
    """``(level, message)`` with each ``(level, text)`` of ``problems`` added: the most severe level, the
    texts appended."""
    for problem_level, text in problems:
        level = max(level, problem_level)
        message += '; ' + text
    return level, message


class DrivingWatch(object):
    """Whether the driving topic ``topic`` (of type ``msg_type``, None when unknown) is silent.

    ``check(now, received, published)``: ``now`` in seconds of a monotonic clock, ``received`` the driving
    messages received so far, ``published`` the master's ``[(topic, type)]`` or a function returning it (asked
    only while silent, at most every ``silence`` seconds). Returns '' while messages come, else a message
    naming the topics that carry ``msg_type`` instead. Silent: no message for ``silence`` seconds after the
    watch began or after the last one. ``state``: None while messages come, else the tuple of those topics
    (it changes only when what is to be said changes: the node logs it then, once).
    """

    def __init__(self, topic, msg_type, now, silence=SILENCE):
        self.topic, self.msg_type, self.silence = topic, msg_type, float(silence)
        self._since, self._received = now, 0
        self._asked = None  # when the master was last asked
        self.state = None

    def check(self, now, received, published):
        """'' or what is wrong (see the class)."""
        if received != self._received:
            self._since, self._received = now, received
        if now - self._since < self.silence:
            self.state, self._asked = None, None
            return ''
        if self._asked is None or now - self._asked >= self.silence:
            self._asked = now
            listed = published() if callable(published) else published
            self.state = tuple(sorted(topic for topic, kind in listed
                                      if self.msg_type and kind == self.msg_type and topic != self.topic))
        text = 'no %s on %s for %.0f s' % (self.msg_type or 'message', self.topic, now - self._since)
        if self.state:
            return '%s; %s is published on %s: remap the driving topic (%s:=%s)' % (
                text, self.msg_type, ', '.join(self.state), self.topic, self.state[0])
        return '%s; %s' % (text, 'no other topic carries %s' % self.msg_type if self.msg_type else 'is it published?')
