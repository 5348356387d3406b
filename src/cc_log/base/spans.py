"""The one grammar of quantities in cc_log: window sizes, durations and byte sizes.

- ``Span.parse``: a message count (``500``) or a duration (``5s``, ``250ms``, ``5m``, ``2h``);
- ``seconds``: a duration alone (``30``, ``30s``, ``250ms``, ``5m``, ``2h``: a bare number is seconds);
- ``megabytes``: a byte size in MB: a bare number is MB (or bytes where the option says so, as rosbag's
  ``--min-space`` does), ``64MB``/``2GB``/``500kB`` are powers of 1000, ``1.5GiB``/``512MiB`` and rosbag's
  ``1G``/``500M``/``100K`` powers of 1024 (``1G`` is 2^30 bytes everywhere).
"""
import collections
import math

from cc_log.base.safe_input import brief

#: Largest message count of a span (a billion messages: days of a 1 kHz topic).
MAX_COUNT = 10 ** 9
#: Longest duration of a span (seconds): about 115 days.
MAX_SECONDS = 1e7
#: Largest byte size (MB): a petabyte.
MAX_MEGABYTES = 1e9


class Range(collections.namedtuple('Range', 'low high unit off form')):
    """The sane values of a quantity an option reads: ``low`` to ``high`` ``unit`` (``'s'``, ``'messages'``,
    ``'MB'``, ...), or exactly ``off`` (a value that turns the option off, e.g. 0; None: none). ``form(amount)``
    writes an amount as a value of the option (default: by the unit), for the docs' examples and the tests."""

    __slots__ = ()

    def __new__(cls, low, high, unit, off=None, form=None):
        return super(Range, cls).__new__(cls, low, high, unit, off, form)

    def check(self, amount, value, name):
        """``amount`` (read from ``value``) when it is ``off`` or within the range; else
        ValueError('<name>: <value> is outside <low>..<high> <unit>')."""
        if (self.off is not None and amount == self.off) or self.low <= amount <= self.high:
            return amount
        raise ValueError('%s: %s is outside %s' % (name, brief(value), str(self)))

    def written(self, amount):
        """``amount`` as a value of the option (``form``, else by the unit: ``2.5s``, ``100``, ``64MB``)."""
        if self.form is not None:
            return self.form(amount)
        if self.unit in COUNTED:
            return str(int(amount))
        return '%r%s' % (float(amount), self.unit if self.unit in ('s', 'MB') else '')

    def __str__(self):
        return '%g..%g %s%s' % (self.low, self.high, self.unit,
                                ' (or %g: off)' % self.off if self.off is not None else '')


#: Units of whole counts (``Range.written`` writes them as integers; one past a bound is one more).
COUNTED = ('messages', 'files', 'KB', 'entries', 'characters')
#: The ranges of a span, a duration and a size where an option states none of its own.
COUNTS = Range(0, MAX_COUNT, 'messages')
DURATIONS = Range(0, MAX_SECONDS, 's')
SIZES = Range(0, MAX_MEGABYTES, 'MB')


class Span(collections.namedtuple('Span', 'count seconds')):
    """A window size: exactly one of ``count`` (messages) and ``seconds`` is set."""

    __slots__ = ()

    @classmethod
    def messages(cls, count):
        """A span of ``count`` messages."""
        return cls(int(count), None)

    @classmethod
    def duration(cls, seconds):
        """A span of ``seconds`` seconds."""
        return cls(None, float(seconds))

    @classmethod
    def parse(cls, value, name='size', counts=COUNTS, durations=DURATIONS):
        """Parse ``500``, ``'500'``, ``'5s'``, ``'2.5s'``, ``'250ms'``, ``'5m'`` or ``'2h'``; a Span is returned
        as is.

        Raises ValueError naming ``name`` when the value is not a count within ``counts`` (a Range of
        messages; default 0 to MAX_COUNT) or a duration within ``durations`` (default 0 to MAX_SECONDS).
        """
        if isinstance(value, cls):
            return value
        text = str(value).strip().lower()
        try:
            seconds = _duration(text)
            if seconds is not None:
                span = cls.duration(seconds)
            else:
                number = float(text)
                if number != int(number):
                    raise ValueError(text)
                span = cls.messages(int(number))
        except (ValueError, OverflowError):
            raise ValueError('%s: %s is not a message count (500) or a duration (5s)' % (name, brief(value)))
        if span.count is not None:
            counts.check(span.count, value, name)
        else:
            durations.check(span.seconds, value, name)
        return span

    @property
    def is_duration(self):
        """True for a duration, False for a message count."""
        return self.seconds is not None

    def __str__(self):
        if self.is_duration:
            return '%gs' % self.seconds
        return str(self.count)


_DURATION_UNITS = (('ms', 1e-3), ('s', 1.0), ('m', 60.0), ('h', 3600.0))  # 'ms' before 'm' and 's'


def _duration(text):
    """Seconds of ``text`` (lower case) ending in a duration unit, None when it has none."""
    for unit, factor in _DURATION_UNITS:
        if text.endswith(unit):
            return float(text[:-len(unit)]) * factor
    return None


def seconds(value, name='duration', positive=False, within=DURATIONS):
    """Seconds (a float >= 0, > 0 when ``positive``, within the Range ``within``: default 0 to MAX_SECONDS)
    of a duration: a number of seconds (``30``, ``'30'``) or one with a unit (``'30s'``, ``'250ms'``, ``'5m'``,
    ``'2h'``). ValueError naming ``name`` otherwise."""
    number = float('nan')
    if not isinstance(value, bool) and isinstance(value, (int, float, str)):
        text = str(value).strip().lower()
        try:
            number = _duration(text)
            number = float(text) if number is None else number
        except (ValueError, OverflowError):
            number = float('nan')
    if not math.isfinite(number):
        raise ValueError('%s: %s is not a duration (30s, 250ms, 5m, 2h; a number is seconds)'
                         % (name, brief(value)))
    if positive and number == 0:
        raise ValueError('%s: %s is not a duration > 0' % (name, brief(value)))
    return within.check(number, value, name)


# Byte sizes: a bare number is MB (10^6 bytes), as the ``*_mb`` parameters always took, unless the option
# says otherwise (``bare``); rosbag's one-letter units are powers of 1024, as rosbag reads them.
_BYTE_UNITS = {'b': 1e-6, 'kb': 1e-3, 'mb': 1.0, 'gb': 1e3, 'tb': 1e6,
               'kib': 1024 / 1e6, 'mib': 1024 ** 2 / 1e6, 'gib': 1024 ** 3 / 1e6, 'tib': 1024 ** 4 / 1e6,
               'k': 1024 / 1e6, 'm': 1024 ** 2 / 1e6, 'g': 1024 ** 3 / 1e6, 't': 1024 ** 4 / 1e6}


def megabytes(value, name='size', bare='mb', within=SIZES):
    """MB (10^6 bytes) of a number (of MB; of ``bare``, a unit of _BYTE_UNITS, when given) or a size with a
    unit (``'64MB'``, ``'2GB'``, ``'500kB'``, ``'1.5GiB'``, ``'1G'``, ``'100B'``; units case-insensitive),
    within the Range ``within`` (default 0 to MAX_MEGABYTES). ValueError naming ``name`` otherwise."""
    number = float('nan')
    if not isinstance(value, bool) and isinstance(value, (int, float, str)):
        text = str(value).strip().lower().replace(' ', '')
        digits = text.rstrip('abcdefghijklmnopqrstuvwxyz')
        factor = _BYTE_UNITS.get(text[len(digits):] if digits != text else bare, None)
        try:
            number = float(digits) * factor if factor is not None else number
        except (ValueError, OverflowError):
            pass
    if not math.isfinite(number):
        raise ValueError('%s: %s is not a size (%s as a number, or 64MB, 2GB, 500kB, 1.5GiB, 1G)'
                         % (name, brief(value), (bare or 'mb').upper()))
    return within.check(number, value, name)


class Rotation(collections.namedtuple('Rotation', 'span bytes')):
    """When to start a new file: after ``span`` (messages or a duration) or ``bytes`` raw row-JSON bytes."""

    __slots__ = ()

    @classmethod
    def parse(cls, value, name='rotate', ranges=None):
        """``'6000'`` (messages), ``'60s'``/``'5m'`` (a duration) or a size with a unit (``'20MB'``, ``'1GiB'``);
        a Rotation is returned as is. ``ranges``: (messages, seconds, MB) Ranges (default ``ROTATIONS``)."""
        if isinstance(value, cls):
            return value
        counts, durations, sizes = ranges or ROTATIONS
        try:
            span = Span.parse(value, name, counts, durations)
        except ValueError as error:
            if ' is outside ' in str(error):
                raise
            try:
                size = megabytes(value, name, bare=None, within=SIZES)
            except ValueError:
                raise ValueError('%s: %s is not a message count (6000), a duration (60s) or a size (20MB)'
                                 % (name, brief(value)))
            return cls(None, int(round(sizes.check(size, value, name) * 1e6)))
        return cls(span, None)

    def __str__(self):
        return str(self.span) if self.span is not None else '%dB' % self.bytes


#: A rotation's sane messages, seconds and MB: a file per message, per millisecond or per byte is none.
ROTATIONS = (Range(1, MAX_COUNT, 'messages'), Range(1, 86400, 's'), Range(0.001, 1e6, 'MB'))
