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

A name must be a legal ROS name (``rosgraph.names.is_legal_name``: a letter, ``/`` or ``~``, then letters, digits,
``_`` and ``/``, never ``//``; case-sensitive): an entry that is neither such a name nor a pattern of this grammar
(a glob such as ``/imu/*``, ``regex:...``) could never match a topic and is refused.

``names`` are the plain topic names (subscribed at start); ``dynamic`` says whether topics that appear later
must be discovered (``-a`` or a regular expression: see ``topic_watch``). Pure; a bad pattern raises
``ValueError('<name>: ...')``.

Python's regular expressions backtrack, so a pattern could take exponential time on one topic name. A pattern
is compiled once and refused when it is longer than MAX_PATTERN_CHARS or has a shape that backtracks badly: a
repetition inside a repetition (``(a+)+``, ``(a*b?)*``), alternatives inside a repetition (``(a|a)*``), a
back reference, or more work than MAX_MATCH_WORK on a name of MAX_NAME_CHARS characters. The work of a pattern
on a name of n characters (``match_work``) bounds the ways it can try: the product, over its repetitions in
sequence, of the counts each may take (``x{low,high}``: ``min(high, n) - low + 1``; a bounded ``.{0,9999}`` is
as wide as ``.*`` on a short name), alternatives adding up; MAX_MATCH_WORK is the work of three ``.*`` on the
longest name (``.*.*.*.*x`` and five ``.{0,9999}`` are refused). A name longer than MAX_NAME_CHARS is tried
against a pattern only while the pattern's work on it stays within MAX_MATCH_WORK; otherwise the pattern
neither selects nor excludes it, and ``too_long`` counts it. ``matches`` keeps its answer per topic (at most
CACHE_TOPICS topics), so the topic watcher's polls do not match again.
"""
import collections
import re
try:
    from re import _parser as _sre_parse  # Python >= 3.11
except ImportError:  # pragma: no cover
    import sre_parse as _sre_parse

from cc_log.base.safe_input import brief

__all__ = ['TopicSelection', 'topic_list', 'is_legal_name', 'ALL', 'REGEX', 'EXCLUDE']

ALL = '*'
REGEX = 're:'
EXCLUDE = '!'
MAX_PATTERN_CHARS = 256
MAX_NAME_CHARS = 256     # the longest topic name every accepted pattern is tried on
MAX_MATCH_WORK = (MAX_NAME_CHARS + 1) ** 3   # the work of ``.*.*.*x`` on a name of MAX_NAME_CHARS characters
CACHE_TOPICS = 10000
_LEGAL_NAME = re.compile(r'[~/A-Za-z][A-Za-z0-9_/]*')  # rosgraph.names.is_legal_name, ASCII

_REPEATS = frozenset(op for op in (getattr(_sre_parse, name, None) for name in (
    'MAX_REPEAT', 'MIN_REPEAT', 'POSSESSIVE_REPEAT')) if op is not None)


def _compile(pattern, name):
    """The compiled ``pattern``, after the checks of the module docstring; ValueError('<name>: ...')."""
    if len(pattern) > MAX_PATTERN_CHARS:
        raise ValueError('%s: regular expression %s is longer than %d characters'
                         % (name, brief(pattern), MAX_PATTERN_CHARS))
    try:
        compiled = re.compile(pattern)
        parsed = _sre_parse.parse(pattern)
        problem = _backtracking_shape(parsed, False)
    except re.error as error:
        raise ValueError('%s: %s is not a regular expression: %s' % (name, brief(pattern), error))
    if not problem and match_work(parsed, MAX_NAME_CHARS) > MAX_MATCH_WORK:
        problem = 'more than %d ways to try on a name of %d characters (at most three .* in a row)' % (
            MAX_MATCH_WORK, MAX_NAME_CHARS)
    if problem:
        raise ValueError('%s: regular expression %s is refused: %s (matching could take very long)'
                         % (name, brief(pattern), problem))
    return _Pattern(compiled, parsed)


class _Pattern(collections.namedtuple('_Pattern', 'compiled parsed')):
    """A compiled pattern and its parse (for ``match_work`` on a long name)."""

    __slots__ = ()

    @property
    def pattern(self):
        """The pattern's text."""
        return self.compiled.pattern

    def fullmatch(self, name):
        """``re.fullmatch`` of the whole ``name``; None when the work on a name that long would exceed
        MAX_MATCH_WORK (see the module docstring)."""
        if len(name) > MAX_NAME_CHARS and match_work(self.parsed, len(name)) > MAX_MATCH_WORK:
            return None
        return self.compiled.fullmatch(name)


def match_work(items, length):
    """A bound on the ways the parsed pattern ``items`` can try on a name of ``length`` characters (see the
    module docstring); patterns whose shape backtracks badly are refused before (``_backtracking_shape``)."""
    work = 1
    for op, value in items:
        if op in _REPEATS:
            low, high, body = value
            work *= max(1, min(high, length) - low + 1) * match_work(body, length)
        elif op == _sre_parse.BRANCH:
            work *= sum(match_work(part, length) for part in value[1])
        elif op == _sre_parse.SUBPATTERN:
            work *= match_work(value[-1], length)
        elif op in (_sre_parse.ASSERT, _sre_parse.ASSERT_NOT):
            work *= match_work(value[1], length)
        elif op == getattr(_sre_parse, 'ATOMIC_GROUP', None):
            work *= match_work(value, length)
    return work


def _backtracking_shape(items, in_repeat):
    """What makes the parsed pattern ``items`` backtrack badly, or ''."""
    for op, value in items:
        parts = []
        if op in _REPEATS:
            low, high, body = value
            if high > 1 and in_repeat:
                return 'a repetition inside a repetition'
            problem = _backtracking_shape(body, in_repeat or high > 1)
            if problem:
                return problem
            continue
        if op == _sre_parse.BRANCH:
            if in_repeat:
                return 'alternatives inside a repetition'
            parts = value[1]
        elif op in (_sre_parse.GROUPREF, getattr(_sre_parse, 'GROUPREF_EXISTS', None)):
            return 'a back reference'
        elif op == _sre_parse.SUBPATTERN:
            parts = [value[-1]]
        elif op in (_sre_parse.ASSERT, _sre_parse.ASSERT_NOT):
            parts = [value[1]]
        elif op == getattr(_sre_parse, 'ATOMIC_GROUP', None):
            parts = [value]
        for part in parts:
            problem = _backtracking_shape(part, in_repeat)
            if problem:
                return problem
    return ''


class TopicSelection(object):
    """Which topics to record (see the module docstring)."""

    def __init__(self, topics=(), all_topics=False, regex=(), exclude=(), name='topics'):
        self.names = list(dict.fromkeys(topics))
        self.all_topics = bool(all_topics)
        self.regex = [_compile(pattern, name) for pattern in regex]
        self.exclude = [_compile(pattern, name) for pattern in exclude]
        self.too_long = 0   # names a pattern was not tried on (see the module docstring)
        self._matched = {}

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
                if not is_legal_name(body):
                    raise ValueError('%s: %s is neither a topic name nor a pattern (a name, *, re:REGEX, !NAME, '
                                     '!re:REGEX; names are letters, digits, _ and /, case-sensitive)'
                                     % (name, brief(entry)))
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
        """Whether ``topic`` is selected (kept per topic)."""
        known = self._matched.get(topic)
        if known is not None:
            return known
        patterns = self.regex + self.exclude
        if len(topic) > MAX_NAME_CHARS and any(match_work(p.parsed, len(topic)) > MAX_MATCH_WORK for p in patterns):
            self.too_long += 1
        if any(pattern.fullmatch(topic) for pattern in self.exclude):
            selected = False
        else:
            selected = self.all_topics or topic in self.names or any(pattern.fullmatch(topic) for pattern in self.regex)
        if len(self._matched) >= CACHE_TOPICS:
            self._matched.clear()
        self._matched[topic] = selected
        return selected

    def resolved(self, resolve):
        """The same selection with its names resolved by ``resolve`` (patterns as they are)."""
        result = TopicSelection()
        result.__dict__.update(self.__dict__, names=[resolve(name) for name in self.names], _matched={})
        return result

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


def is_legal_name(name):
    """Whether ``name`` is a legal ROS graph name (relative, global or private), as ``rospy`` checks it."""
    return bool(_LEGAL_NAME.fullmatch(name)) and '//' not in name


def topic_list(value, name):
    """Topic names from a list or a space/comma-separated string (duplicates removed); ValueError('<name>: ...')."""
    if isinstance(value, str):
        items = value.replace(',', ' ').split()
    elif isinstance(value, (list, tuple)):
        items = list(value)
    else:
        raise ValueError('%s: %s is not a list of topic names' % (name, brief(value)))
    out = []
    for item in items:
        if not isinstance(item, str) or not item.strip():
            raise ValueError('%s: %s is not a topic name' % (name, brief(item)))
        if item.strip() not in out:
            out.append(item.strip())
    return out
