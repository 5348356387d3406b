"""What a logger's counters say about it on /diagnostics: the level and the message (pure).

Levels are diagnostic_msgs' (``OK``, ``WARN``, ``ERROR``). ``smart_head(stats)`` is the smart logger's own
status before the writer's and the disk's part: WARN while it is paused (nothing is kept) or when messages of
the wrong type were refused. ``not_kept(stats, overflowed)`` lists the messages that belonged in a window and
are not on disk: thinned while the writer fell behind, trimmed from the buffer to stay within
``max_buffer_mb`` (a window opened then starts later than ``pre``; side messages after an open window's end while
the driving topic is silent), or dropped by a full intake queue; each is a WARN. ``skipped(stats)``: the windows
the keep budget did not open (WARN: the robot's normal may have drifted).
``DrivingWatch`` says when the driving topic is silent and where its message type is published instead;
``NamedWatch`` says which topics the configuration names have had no message since start, and which published
topics look like each (``alike``: a name the same ignoring case, the same last component, the same type).
``worst(level, message, problems)`` adds problems to a status.
"""
from cc_log.logger import keep_budget

OK, WARN, ERROR = 0, 1, 2  # diagnostic_msgs/DiagnosticStatus levels
SILENCE = 5.0  # seconds without a driving message (after start or the last one) before the node warns
MAX_ALIKE = 5  # published topics named as looking like a silent one

__all__ = ['OK', 'WARN', 'ERROR', 'SILENCE', 'smart_head', 'not_kept', 'skipped', 'worst', 'per_topic',
           'DrivingWatch', 'NamedWatch', 'alike']


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
    if stats['buffer_trimmed_silent']:
        problems.append((WARN, '%d side messages after an open window\'s end trimmed to stay within ~max_buffer_mb: '
                               'its end waits for the driving topic (silent?)' % stats['buffer_trimmed_silent']))
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


def alike(topic, msg_type, published):
    """The ``[(topic, type)]`` of ``published`` (the master's list) that look like ``topic``: the same name
    ignoring case, then the same last component (ignoring case), then the same type (``msg_type``, else the type
    the list gives ``topic``); at most MAX_ALIKE, each group sorted by name. ``topic`` itself is not one."""
    listed = dict(published)
    msg_type = msg_type or listed.get(topic)
    last = topic.rsplit('/', 1)[-1].lower()

    def rank(name, kind):
        if name.lower() == topic.lower():
            return 0
        if name.rsplit('/', 1)[-1].lower() == last:
            return 1
        return 2 if msg_type and kind == msg_type else None
    ranked = sorted((rank(name, kind), name, kind) for name, kind in listed.items()
                    if name != topic and rank(name, kind) is not None)
    return [(name, kind) for _, name, kind in ranked[:MAX_ALIKE]]


def _alike_text(topic, found, advertised):
    """What is published that looks like ``topic`` (``found``: ``alike``'s answer; ``advertised``: its type
    when the master lists ``topic`` itself, else None)."""
    text = 'published: %s' % ', '.join('%s (%s)' % item for item in found) if found else \
        'no published topic looks like it'
    if advertised:
        text = 'advertised (%s) but nothing came; %s' % (advertised, text)
    return text


class NamedWatch(object):
    """Which of the topics the configuration names (``topics``: names, not patterns, the node subscribes) have
    had no message since the watch began ``silence`` seconds ago or more; ``types``: ``{topic: type}`` known.

    ``check(now, counts, published)``: ``now`` in seconds of a monotonic clock, ``counts`` the node's ``{topic:
    messages received}``, ``published`` the master's ``[(topic, type)]`` or a function returning it (asked only
    while a name is silent, at most every ``silence`` seconds). Returns ``[(topic, text)]``, e.g. ``no message
    on /IMU/data for 5 s; published: /imu/data (sensor_msgs/Imu)``. A name once heard is never said again: a
    topic silent later is a silence rule's business (``triggers.rule``). ``state``: ``{topic: what is said of
    it}`` of the silent names (the node logs a name once, when it first appears there);
    ``summary(now)``: the silent names in one line for /diagnostics ('' when none).
    """

    def __init__(self, topics, now, types=None, silence=SILENCE):
        self.topics, self.types, self.silence = list(dict.fromkeys(topics)), dict(types or {}), float(silence)
        self._since, self._asked, self._published = now, None, []
        self._heard = set()
        self.state = {}

    def check(self, now, counts, published):
        """The silent names and what is said of each (see the class)."""
        self._heard.update(topic for topic in self.topics if counts.get(topic))
        silent = [topic for topic in self.topics if topic not in self._heard]
        if not silent or now - self._since < self.silence:
            self.state = {}
            return []
        if self._asked is None or now - self._asked >= self.silence:
            self._asked = now
            self._published = list(published() if callable(published) else published)
        listed = dict(self._published)
        self.state = dict((topic, _alike_text(topic, alike(topic, self.types.get(topic), self._published),
                                              listed.get(topic))) for topic in silent)
        return [(topic, 'no message on %s for %.0f s; %s' % (topic, now - self._since, self.state[topic]))
                for topic in silent]

    def summary(self, now):
        """The silent names (of the last ``check``) in one line, each with what looks like it; '' when none."""
        if not self.state:
            return ''
        return 'no message for %.0f s on %s' % (now - self._since, '; '.join(
            '%s (%s)' % (topic, self.state[topic]) for topic in self.topics if topic in self.state))
