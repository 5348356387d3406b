"""What every trigger shares: ``Trigger`` (records in, "keep a window around here" out), ``Fire``, the registry.

A trigger looks at the records of its topics (``on_record``) and at the passing of message time
(``on_time``, for triggers that watch for something *not* happening) and returns ``Fire``s: keep a window
around the newest message, with the trigger's ``name``, a ``reason`` and a ``score`` (NaN when it has none),
which go into the window's metadata, its file name and the ``AnomalyEvent``; ``pre`` and ``post`` (Spans or
None: the logger's) may widen or narrow that window. ``SmartLogger`` runs a list of triggers; their windows
merge in ``WindowBuffer`` (one file for overlapping spans).

``register`` adds a Trigger subclass under its ``kind``; ``get(kind)`` finds it (ValueError naming the
trigger kind otherwise). Each kind declares the keys of its configuration entry (``config_keys``) and builds
itself from one (``from_config``; see ``config``). Pure: no rospy.
"""
import collections
import re

from cc_log.base.registry import Registry
from cc_log.base.safe_input import brief
from cc_log.base.spans import Span

Context = collections.namedtuple('Context', 'load_model message_class resolve online_dir', defaults=(None,))
Context.__doc__ = """What building a trigger from a configuration may need: ``load_model(path)`` (a model; ValueError
naming the file), ``message_class(type)`` (an installed class or None), ``resolve(topic)`` (a full name),
``online_dir`` (where classifiers learning online keep their refits; None: beside their model files)."""

Fire = collections.namedtuple('Fire', 'name reason score pre post why', defaults=(None, None, ()))
Fire.__doc__ = """A trigger's decision to keep a window: its name, a reason (text), a score (float; NaN when none),
optional ``pre`` / ``post`` Spans for this window (None: the logger's) and ``why``: the features that stood out,
most outstanding first (a tuple of at most 3 dicts, ``base.why``)."""

NAN = float('nan')
_NAME = re.compile(r'[A-Za-z][A-Za-z0-9_-]{0,63}')
_KINDS = Registry('kind', 'kind')
register = _KINDS.register
kinds = _KINDS.names
get = _KINDS.get


def check_name(name):
    """A trigger name (it goes into file names): a letter, then letters, digits, '_' or '-'."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValueError('trigger name: %s must be a letter then letters, digits, "_" or "-" (64 at most)'
                         % brief(name))
    return name


def optional_span(value, name):
    """None, or a Span parsed from ``value`` (ValueError naming ``name``)."""
    return None if value in (None, '') else Span.parse(value, name)


class Trigger(object):
    """Base of every trigger (see the module docstring).

    ``topics``: the topics whose records ``on_record`` wants (a frozenset); ``topic_types()``: the message type
    each of them must carry, where the trigger knows it (a dict); ``watches_time``: True when ``on_time``
    must be called as message time passes. ``pre``, ``post``: this trigger's window, or None for the logger's.
    """

    kind = None
    watches_time = False
    batched = False   # True when ``on_records`` does better than ``on_record`` of each record
    config_keys = ()  # the keys of its configuration entry besides name, kind, pre and post

    @classmethod
    def from_config(cls, name, options, context):
        """The trigger of a configuration entry (``options``: its keys but name and kind; ``context``: a
        Context); ValueError('<what>: ...')."""
        return cls(name, **options)

    def __init__(self, name, pre=None, post=None):
        self.name = check_name(name)
        self.pre = optional_span(pre, '%s: pre' % name)
        self.post = optional_span(post, '%s: post' % name)
        self.topics = frozenset()
        self.fired = 0

    def topic_types(self):
        """``{topic: message type}`` this trigger requires."""
        return {}

    def on_record(self, record):
        """The Fires a record of one of ``topics`` causes (a list, often empty)."""
        return []

    def on_records(self, records):
        """The Fires of each of a batch of records of ``topics`` (a list of lists, one per record, in order): the
        same as ``on_record`` of each in turn."""
        return [self.on_record(record) for record in records]

    def needs_message(self, record):
        """Whether ``on_record`` reads the decoded message of ``record`` (a record of serialized bytes is
        then decoded first); False when it reads the bytes (or nothing)."""
        return True

    def on_time(self, stamp):
        """The Fires of message time reaching ``stamp`` (only called when ``watches_time``)."""
        return []

    def reset(self):
        """Forget everything seen (the logger was paused, or restarted)."""

    def stats(self):
        """Counters of this trigger (a dict; ``fired``: Fires returned)."""
        return {'fired': self.fired}

    def describe(self):
        """What this trigger is, for window metadata (a JSON-able dict)."""
        return {'kind': self.kind, 'name': self.name, 'topics': sorted(self.topics)}

    def fire(self, reason, score=NAN, why=()):
        """A Fire of this trigger (counted); ``why``: the features that stood out (``base.why``)."""
        self.fired += 1
        return Fire(self.name, reason, score, self.pre, self.post, tuple(why))
