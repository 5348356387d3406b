"""Rule triggers: declarative conditions on any topic, no learning.

One rule watches one topic for one of:

- ``when``: a field compared with a value, ``'twist.twist.linear.x > 2.0'``, ``'abs(twist.twist.angular.z) >=
  1.5'``, ``'status.status == 4'``, ``'status_list[0].text != "ok"'`` (operators ``< <= > >= == !=``; a number,
  ``true``/``false``, a quoted string, or ``nan`` with ``==`` / ``!=``: ``'twist.twist.linear.x == nan'`` holds
  for a value that is not a number, such as odometry gone NaN, which no other comparison holds for; at most
  MAX_CONDITION_CHARS characters). The text is read left to right, once, into a field path, an operator and a
  value: it is never evaluated as code. With the topic's message ``type`` the field and the value's type are
  checked at start (an unknown field is a ValueError naming it); without it, at the first message (a bad
  field then turns the rule off, and ``error`` says why);
- ``level``: a diagnostic_msgs/DiagnosticArray status at or above a level (``OK``, ``WARN``, ``ERROR``, ``STALE``
  or 0-3), optionally only statuses whose name matches ``status`` (a shell pattern, ``'motors*'``); the
  cc_log nodes' own statuses (``cc_log: ...``) are ignored;
- ``arrival``: any message arriving on the topic (a bumper, an e-stop);
- ``silent``: the topic silent for longer than a duration (``'2s'``), or ``min_rate``: fewer than that many
  messages per second over ``over`` (default 2 s): a sensor dying. Message time is the newest stamp the
  logger has seen on any topic; a topic that never published is given STARTUP_GRACE seconds more, counted
  from the first message of any topic (a subscriber takes a while to connect), and its rate is measured
  from its first message.

A rule fires at the onset of its condition: the first message on which it holds after one on which it did
not (or after more than ``hold_off`` without a message where it held: event topics such as a goal result), and
for silence when the topic falls silent or slow. It does not fire again within ``hold_off`` (default 5 s of
message time) of its last firing, so a flapping condition makes one window. A ``when`` rule comparing numbers says
why (``base.why``): the field, its value and the level it crossed. Pure: no rospy.
"""
import collections
import fnmatch
import math
import operator
import re

from cc_log.base import msg_codec, why
from cc_log.base.safe_input import brief
from cc_log.base.spans import Range, seconds
from cc_log.triggers.base import Trigger, register

DEFAULT_HOLD_OFF = '5s'
DEFAULT_OVER = '2s'
DEFAULT_DIAGNOSTICS_TOPIC = '/diagnostics'
DIAGNOSTIC_ARRAY = 'diagnostic_msgs/DiagnosticArray'
LEVELS = collections.OrderedDict([('OK', 0), ('WARN', 1), ('ERROR', 2), ('STALE', 3)])
OWN_STATUS = 'cc_log:'  # prefix of the cc_log nodes' own diagnostic statuses: never a reason to log
JUMP_BACK_TOLERANCE = 1.0
STARTUP_GRACE = 5.0  # seconds a silence or rate rule waits, before the topic's first message, on top of its own

MAX_CONDITION_CHARS = 1000
#: An array index of a field path: no message holds a million elements of an array a rule compares.
INDEXES = Range(0, 10 ** 6, 'elements')
_FIELD_PATH = re.compile(r'[A-Za-z0-9_.\[\]]*')  # the characters a field path may hold (one pass, no backtracking)
_PART = re.compile(r'([A-Za-z_][A-Za-z0-9_]*)(?:\[([0-9]{1,9})\])?\Z')
_NUMBER = re.compile(r'[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?\Z')
_STRING = re.compile(r'(?:"([^"\\]*)"|\'([^\'\\]*)\')')
OPERATORS = {'<': operator.lt, '<=': operator.le, '>': operator.gt, '>=': operator.ge, '==': operator.eq,
             '!=': operator.ne}
_NUMERIC = msg_codec.FLOAT_TYPES | msg_codec.INT_TYPES | frozenset(['bool'])


class Condition(object):
    """A parsed ``when`` text: ``path`` ([(field, index or None)]), ``op``, ``value``, ``absolute``."""

    def __init__(self, text, name='when'):
        parsed = _split_condition(text) if isinstance(text, str) and len(text) <= MAX_CONDITION_CHARS else None
        if parsed is None:
            raise ValueError('%s: %s is not "<field> <op> <value>" (op: < <= > >= == !=; at most %d characters)'
                             % (name, brief(text), MAX_CONDITION_CHARS))
        self.text = ' '.join(text.split())
        self.absolute, field, self.path, self.op_text, raw = parsed
        for part, index in self.path:
            if index is not None:
                INDEXES.check(index, '%s[%d]' % (part, index), name)
        self.field = field
        self.op = OPERATORS[self.op_text]
        string = _STRING.fullmatch(raw)
        if string:
            self.value = string.group(1) if string.group(1) is not None else string.group(2)
        elif raw in ('true', 'false'):
            self.value = raw == 'true'
        elif raw == 'nan':
            self.value = float('nan')
            if self.op_text not in ('==', '!='):
                raise ValueError('%s: nan compares only with == or != (%s)' % (name, brief(text)))
        elif _NUMBER.match(raw):
            self.value = float(raw)
        else:
            raise ValueError('%s: value %s of %s is not a number, true, false or a quoted string'
                             % (name, brief(raw), brief(text)))
        if isinstance(self.value, str) and (self.absolute or self.op_text not in ('==', '!=')):
            raise ValueError('%s: a string compares only with == or != (%s)' % (name, brief(text)))

    def check(self, msg_type, definition, name='when'):
        """Raise ValueError('<name>: ...') unless the field exists in ``msg_type`` (full ``definition``) and is
        a number or string fitting the value."""
        classes = msg_codec.message_classes(msg_type, definition)
        cls, where = classes[msg_type], msg_type
        for position, (field, index) in enumerate(self.path):
            slots = list(cls.__slots__)
            if field not in slots:
                raise ValueError('%s: %s has no field %r (fields: %s)' % (name, where, field, ', '.join(slots)))
            base, is_array, length = msg_codec.split_type(cls._slot_types[slots.index(field)])
            if index is not None and not is_array:
                raise ValueError('%s: %s.%s is not an array' % (name, where, field))
            if index is not None and length is not None and index >= length:
                raise ValueError('%s: %s.%s[%d] is outside 0..%d elements (it has %d)'
                                 % (name, where, field, index, length - 1, length))
            if is_array and index is None:
                raise ValueError('%s: %s.%s is an array: give an index, %s[0]' % (name, where, field, field))
            base = msg_codec._resolve(base, cls._type)
            last = position == len(self.path) - 1
            if last:
                if base == 'string' and not isinstance(self.value, str):
                    raise ValueError('%s: %s is a string: compare it with a quoted string' % (name, self.field))
                if base in _NUMERIC and isinstance(self.value, str):
                    raise ValueError('%s: %s is a number (%s), not a string' % (name, self.field, base))
                if base not in _NUMERIC and base != 'string':
                    raise ValueError('%s: %s is %s, not a number or a string' % (name, self.field, base))
            elif base in msg_codec.PRIMITIVE_TYPES:
                raise ValueError('%s: %s.%s is %s and has no fields' % (name, where, field, base))
            else:
                cls, where = classes[base], '%s.%s' % (where, field)

    def value_of(self, msg):
        """The field's value in ``msg`` (AttributeError, IndexError, TypeError when it has none)."""
        value = msg
        for field, index in self.path:
            value = getattr(value, field)
            if index is not None:
                value = value[index]
        return value

    def holds(self, msg):
        """Whether the condition holds for ``msg`` and the value compared (False when unreadable or NaN)."""
        value = self.value_of(msg)
        if isinstance(value, bytes):
            value = value.decode('utf-8', 'replace')
        if isinstance(self.value, str):
            return self.op(str(value), self.value), value
        number = float(value)
        if self.absolute:
            number = abs(number)
        if self.value != self.value:  # == nan, != nan
            return math.isnan(number) == (self.op_text == '=='), number
        if math.isnan(number):
            return False, number
        return self.op(number, float(self.value)), number


def _split_condition(text):
    """``(absolute, field, path, op, value text)`` of a ``when`` text read left to right, or None."""
    rest = text.strip()
    absolute = rest.startswith('abs(')
    if absolute:
        close = rest.find(')')
        if close < 0:
            return None
        field, rest = rest[4:close].strip(), rest[close + 1:].lstrip()
    else:
        field = _FIELD_PATH.match(rest).group()
        rest = rest[len(field):].lstrip()
    path = []
    for item in field.split('.'):
        part = _PART.match(item)
        if part is None:
            return None
        path.append((part.group(1), None if part.group(2) is None else int(part.group(2))))
    op = rest[:2] if rest[:2] in OPERATORS else rest[:1] if rest[:1] in OPERATORS else None
    if op is None:
        return None
    return absolute, field, path, op, rest[len(op):].strip()


def parse_level(value, name='level'):
    """A diagnostic level from its name or number; ValueError('<name>: ...')."""
    if isinstance(value, str) and value.upper() in LEVELS:
        return LEVELS[value.upper()]
    if isinstance(value, int) and not isinstance(value, bool) and value in LEVELS.values():
        return value
    raise ValueError('%s: %s is not one of %s (or 0-3)' % (name, brief(value), ', '.join(LEVELS)))


def level_name(level):
    """``2`` -> ``'ERROR'``."""
    for text, number in LEVELS.items():
        if number == level:
            return text
    return str(level)


@register
class RuleTrigger(Trigger):
    """A declarative rule on one topic (see the module docstring); give exactly one of ``when``, ``level``,
    ``arrival``, ``silent``, ``min_rate``. ``type``: the topic's message type (checked at start for ``when``)."""

    kind = 'rule'
    config_keys = ('topic', 'type', 'when', 'level', 'status', 'arrival', 'silent', 'min_rate', 'over', 'hold_off')

    @classmethod
    def from_config(cls, name, options, context):
        """The rule on its resolved topic, its ``when`` checked against ``type`` (which must be installed)."""
        options = dict(options)
        if options.get('topic') is not None and not isinstance(options['topic'], str):
            raise ValueError('topic: %s is not a topic name' % brief(options['topic']))
        if options.get('topic'):
            options['topic'] = context.resolve(options['topic'])
        rule = cls(name, **options)
        if rule.type is not None:
            msg_class = context.message_class(rule.type)
            if msg_class is None:
                raise ValueError('type: unknown message type %s (not installed)' % brief(rule.type))
            rule.check(msg_class)
        return rule

    def __init__(self, name, topic=None, when=None, type=None, level=None, status=None, arrival=False,
                 silent=None, min_rate=None, over=DEFAULT_OVER, hold_off=DEFAULT_HOLD_OFF, pre=None, post=None):
        super(RuleTrigger, self).__init__(name, pre, post)
        given = [key for key, value in (('when', when), ('level', level), ('arrival', arrival or None),
                                        ('silent', silent), ('min_rate', min_rate)) if value not in (None, '')]
        if len(given) != 1:
            raise ValueError('%s: give exactly one of when, level, arrival, silent, min_rate (got %s)'
                             % (name, ', '.join(given) or 'none'))
        self.what = given[0]
        if self.what == 'level':
            topic = topic or DEFAULT_DIAGNOSTICS_TOPIC
            if type not in (None, DIAGNOSTIC_ARRAY):
                raise ValueError('%s: type: a level rule reads %s, not %s' % (name, DIAGNOSTIC_ARRAY, type))
            type = DIAGNOSTIC_ARRAY
        if not isinstance(topic, str) or not topic:
            raise ValueError('%s: topic: required (the topic the rule watches)' % name)
        self.topic = topic
        self.topics = frozenset([topic])
        self.type = type
        self.hold_off = seconds(hold_off, '%s: hold_off' % name)
        self.error = ''
        self.condition = Condition(when, '%s: when' % name) if when is not None else None
        self.level = parse_level(level, '%s: level' % name) if level is not None else None
        if status is not None and (self.level is None or not isinstance(status, str) or not status):
            raise ValueError('%s: status: a name pattern of a level rule' % name)
        self.status = status
        self.silent = seconds(silent, '%s: silent' % name) if silent is not None else None
        self.min_rate = None
        if min_rate is not None:
            if isinstance(min_rate, bool) or not isinstance(min_rate, (int, float)) or not min_rate > 0 \
                    or not math.isfinite(min_rate):
                raise ValueError('%s: min_rate: %s must be a positive number of messages per second'
                                 % (name, brief(min_rate)))
            self.min_rate = float(min_rate)
        self.over = seconds(over, '%s: over' % name)
        self.watches_time = self.silent is not None or self.min_rate is not None
        self._checked = False
        self.reset()

    def check(self, msg_class):
        """Check the ``when`` field against a message class (with ``_type`` and ``_full_text``); ValueError."""
        if self.condition is not None:
            self.condition.check(msg_class._type, msg_class._full_text, '%s: when' % self.name)
        self._checked = True

    def topic_types(self):
        return {self.topic: self.type} if self.type else {}

    def reset(self):
        self._active = False        # the condition held at the last message
        self._last_true = None      # stamp of the last message where it held
        self._last_fire = None
        self._now = None            # message time (newest stamp seen)
        self._since = None          # when the watching began (first message of any topic, or a restart)
        self._last_seen = None      # stamp of the topic's last message
        self._first_seen = None     # stamp of the topic's first message
        self._recent = collections.deque()  # stamps of the topic's messages within ``over``
        self._slow = False          # silent or slow now (fired for this episode)

    # -- message conditions ---------------------------------------------------------------------------

    def needs_message(self, record):
        return not (self.watches_time or self.what == 'arrival')  # these read the stamp only

    def on_record(self, record):
        if self.watches_time:
            self._seen(record.stamp)
            return []
        if self.error:
            return []
        if self.what == 'arrival':
            return self._update(True, record.stamp, 'message on %s' % self.topic, event=True)
        if self.what == 'level':
            holds, reason = self._diagnostics(record.msg)
            return self._update(holds, record.stamp, reason)
        if not self._checked:
            try:
                self.check(type(record.msg))
            except (ValueError, AttributeError) as error:
                self.error = str(error)
                return []
        try:
            holds, value = self.condition.holds(record.msg)
        except (AttributeError, IndexError, TypeError, ValueError, OverflowError):
            holds, value = False, None
        return self._update(holds, record.stamp, '%s (%s)' % (self.condition.text, _short(value)), value=value)

    def _why(self, value):
        """The ``why`` of a ``when`` condition that holds: the field, its value and the level it crossed (a
        numeric comparison only; () otherwise)."""
        if self.condition is None:
            return ()
        level = self.condition.value
        if isinstance(level, (bool, str)) or isinstance(value, (bool, str)) or level != level \
                or not isinstance(value, (int, float)) or not math.isfinite(value):
            return ()
        field = ('abs(%s)' % self.condition.field) if self.condition.absolute else self.condition.field
        text = '%s %s %s %s' % (field, why.number_text(value), self.condition.op_text, why.number_text(level))
        return (why.entry(field, value, level, text=text[:why.MAX_TEXT]),)

    def _diagnostics(self, msg):
        for status in getattr(msg, 'status', None) or ():
            name = str(getattr(status, 'name', ''))
            if name.startswith(OWN_STATUS):
                continue
            if self.status is not None and not fnmatch.fnmatchcase(name, self.status):
                continue
            level = getattr(status, 'level', 0)
            level = ord(level) if isinstance(level, bytes) else int(level)
            if level >= self.level:
                return True, '%s: %s %s' % (name, level_name(level), str(getattr(status, 'message', '')))[:200]
        return False, ''

    def _update(self, holds, stamp, reason, event=False, value=None):
        fires = []
        if holds:
            last = self._last_true
            onset = event or not self._active or last is None or stamp < last or stamp - last > self.hold_off
            self._last_true = stamp
            if onset and self._may_fire(stamp):
                fires.append(self.fire(reason, why=self._why(value)))
        self._active = holds
        return fires

    def _may_fire(self, stamp):
        last = self._last_fire
        if last is not None and last <= stamp < last + self.hold_off:
            return False
        self._last_fire = stamp
        return True

    # -- silence --------------------------------------------------------------------------------------

    def _seen(self, stamp):
        self._last_seen = stamp if self._last_seen is None else max(self._last_seen, stamp)
        if self._first_seen is None:
            self._first_seen = stamp
        if self.min_rate is not None:
            self._recent.append(stamp)

    def on_time(self, stamp):
        if self._now is not None and stamp < self._now - JUMP_BACK_TOLERANCE:
            self.reset()  # time went back (a bag played again): watch afresh
        if self._now is None or stamp > self._now:
            self._now = stamp
        if self._since is None:
            self._since = stamp
        now = self._now
        if self.silent is not None:
            since = self._last_seen if self._last_seen is not None else self._since + STARTUP_GRACE
            slow = now - since > self.silent
            reason = '%s silent for more than %gs' % (self.topic, self.silent)
        else:
            recent = self._recent
            while recent and recent[0] <= now - self.over:
                recent.popleft()
            start = self._first_seen if self._first_seen is not None else self._since + STARTUP_GRACE
            slow = now - start >= self.over and len(recent) < self.min_rate * self.over
            reason = '%s below %g Hz (%d messages in %gs)' % (self.topic, self.min_rate, len(recent), self.over)
        fires = []
        if slow and not self._slow and self._may_fire(now):
            fires.append(self.fire(reason))
        self._slow = slow
        return fires

    def stats(self):
        result = super(RuleTrigger, self).stats()
        if self.error:
            result['error'] = self.error
        return result

    def describe(self):
        result = super(RuleTrigger, self).describe()
        condition = {'when': self.condition.text if self.condition else None,
                     'level': level_name(self.level) if self.level is not None else None, 'status': self.status,
                     'arrival': self.what == 'arrival' or None, 'silent': self.silent, 'min_rate': self.min_rate}
        result.update((key, value) for key, value in condition.items() if value is not None)
        result['hold_off'] = self.hold_off
        return result


def _short(value):
    if isinstance(value, float):
        return '%.6g' % value
    return repr(value)[:60]
