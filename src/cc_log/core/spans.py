"""Window sizes as a message count (``500``) or a duration (``5s``, ``250ms``); byte sizes in MB or with a unit."""
import collections
import math

from cc_log.core.safe_input import brief

#: Largest message count of a span (a billion messages: days of a 1 kHz topic).
MAX_COUNT = 10 ** 9
#: Longest duration of a span (seconds): about 115 days.
MAX_SECONDS = 1e7
#: Largest byte size (MB): a petabyte.
MAX_MEGABYTES = 1e9


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
    def parse(cls, value, name='size'):
        """Parse ``500``, ``'500'``, ``'5s'``, ``'2.5s'`` or ``'250ms'``; a Span is returned as is.

        Raises ValueError naming ``name`` when the value is not a count or duration from 0 to MAX_COUNT
        messages or MAX_SECONDS seconds.
        """
        if isinstance(value, cls):
            return value
        text = str(value).strip().lower()
        try:
            if text.endswith('ms'):
                span = cls.duration(float(text[:-2]) / 1000.0)
            elif text.endswith('s'):
                span = cls.duration(float(text[:-1]))
            else:
                number = float(text)
                if number != int(number):
                    raise ValueError(text)
                span = cls.messages(int(number))
        except (ValueError, OverflowError):
            raise ValueError('%s: %s is not a message count (500) or a duration (5s)' % (name, brief(value)))
        amount = span.count if span.count is not None else span.seconds
        if amount < 0 or not math.isfinite(amount):
            raise ValueError('%s: %s must be zero or positive' % (name, brief(value)))
        if amount > (MAX_COUNT if span.count is not None else MAX_SECONDS):
            raise ValueError('%s: %s is more than %s' % (
                name, brief(value), MAX_COUNT if span.count is not None else '%gs' % MAX_SECONDS))
        return span

    @property
    def is_duration(self):
        """True for a duration, False for a message count."""
        return self.seconds is not None

    def __str__(self):
        if self.is_duration:
            return '%gs' % self.seconds
        return str(self.count)


# Byte sizes: a bare number is MB (10^6 bytes), as the ``*_mb`` parameters always took.
_BYTE_UNITS = {'b': 1e-6, 'kb': 1e-3, 'mb': 1.0, 'gb': 1e3, 'tb': 1e6,
               'kib': 1024 / 1e6, 'mib': 1024 ** 2 / 1e6, 'gib': 1024 ** 3 / 1e6, 'tib': 1024 ** 4 / 1e6}


def megabytes(value, name='size'):
    """MB (10^6 bytes) of a number of MB (``64``, ``'64'``) or a size with a unit (``'64MB'``, ``'2GB'``,
    ``'500kB'``, ``'1.5GiB'``, ``'100B'``; units case-insensitive), at most MAX_MEGABYTES. ValueError naming
    ``name`` otherwise."""
    number = float('nan')
    if not isinstance(value, bool) and isinstance(value, (int, float, str)):
        text = str(value).strip().lower().replace(' ', '')
        digits = text.rstrip('abcdefghijklmnopqrstuvwxyz')
        factor = _BYTE_UNITS.get(text[len(digits):], None) if digits != text else 1.0
        try:
            number = float(digits) * factor if factor is not None else number
        except (ValueError, OverflowError):
            pass
    if not number >= 0 or not math.isfinite(number):
        raise ValueError('%s: %s is not a size >= 0 (MB as a number, or 64MB, 2GB, 500kB, 1.5GiB)'
                         % (name, brief(value)))
    if number > MAX_MEGABYTES:
        raise ValueError('%s: %s is more than %gMB' % (name, brief(value), MAX_MEGABYTES))
    return number
