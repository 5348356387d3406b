"""Topic selection as ``rosbag record`` users know it: all topics, regular expressions, exclusions.

``TopicSelection(topics=(), all_topics=False, regex=(), exclude=())``: ``matches(topic)`` is True for a topic
named in ``topics``, or matching one of the ``regex`` patterns (whole name, ``re.fullmatch``, like
``rosbag record -e``), or any topic with ``all_topics`` (``-a``), unless it matches an ``exclude`` pattern
(``-x``). Names are compared as given (resolve them first).

``TopicSelection.parse(entries)`` reads the configuration's ``topics`` list, whose entries may be patterns:

- ``/scan``: a topic name;
- ``*``: every topic (``-a``);
- ``re:/camera/.*``: a regular expression (``-e``);
- ``!re:/camera/.*/compressed``, ``!/tf``: an exclusion (``-x``; a name excludes that topic only).

``names`` are the plain topic names (subscribed at start); ``dynamic`` says whether topics that appear later
must be discovered (``-a`` or a regular expression: see ``topic_watch``). Pure; a bad pattern raises
``ValueError('<name>: ...')``.
"""
import re

from .safe_input import brief

__all__ = ['TopicSelection', 'ALL', 'REGEX', 'EXCLUDE']

ALL = '*'
REGEX = 're:'
EXCLUDE = '!'


def _compile(pattern, name):
    try:
        return re.compile(pattern)
    except re.error as error:
        raise ValueError('%s: %s is not a regular expression: %s' % (name, brief(pattern), error))


class TopicSelection(object):
    """Which topics to record (see the module docstring)."""

    def __init__(self, topics=(), all_topics=False, regex=(), exclude=(), name='topics'):
        self.names = list(dict.fromkeys(topics))
        self.all_topics = bool(all_topics)
        self.regex = [_compile(pattern, name) for pattern in regex]
        self.exclude = [_compile(pattern, name) for pattern in exclude]

    @classmethod
    def parse(cls, entries, name='topics'):
        """A selection from configuration entries (names, ``*``, ``re:...``, ``!...``)."""
        topics, regex, exclude, all_topics = [], [], [], False
        for entry in entries:
            if not isinstance(entry, str) or not entry.strip():
                raise ValueError('%s: %s is not a topic name or pattern' % (name, brief(entry)))
            entry = entry.strip()
            negated = entry.startswith(EXCLUDE)
            body = entry[len(EXCLUDE):] if negated else entry
            if body.startswith(REGEX):
                pattern = body[len(REGEX):]
                if not pattern:
                    raise ValueError('%s: %s has an empty regular expression' % (name, brief(entry)))
            elif body == ALL and not negated:
                all_topics = True
                continue
            elif not body or body == ALL:
                raise ValueError('%s: %s excludes nothing (a name, or re:PATTERN)' % (name, brief(entry)))
            else:
                pattern = None
            if negated:
                exclude.append(pattern if pattern is not None else re.escape(body))
            elif pattern is not None:
                regex.append(pattern)
            else:
                topics.append(body)
        return cls(topics, all_topics, regex, exclude, name)

    @staticmethod
    def is_pattern(entry):
        """Whether a configuration entry is a pattern (``*``, ``re:...``, ``!...``) rather than a name."""
        return isinstance(entry, str) and (entry.strip() == ALL or entry.strip().startswith((REGEX, EXCLUDE)))

    @property
    def dynamic(self):
        """Whether topics not named must be discovered as they appear (``-a`` or a regular expression)."""
        return self.all_topics or bool(self.regex)

    def matches(self, topic):
        """Whether ``topic`` is selected."""
        if any(pattern.fullmatch(topic) for pattern in self.exclude):
            return False
        return self.all_topics or topic in self.names or any(pattern.fullmatch(topic) for pattern in self.regex)

    def select(self, topics):
        """The selected topics of ``topics``, in order."""
        return [topic for topic in topics if self.matches(topic)]

    def describe(self):
        """One line for the log."""
        parts = (['all topics'] if self.all_topics else []) + self.names + \
            ['re:' + pattern.pattern for pattern in self.regex]
        text = ', '.join(parts) or 'no topics'
        if self.exclude:
            text += ' except ' + ', '.join('re:' + pattern.pattern for pattern in self.exclude)
        return text
