"""The feature window and the one feature-vector step of every mode.

``FeatureWindow`` holds the rows of the last ``count`` messages or ``seconds`` as a preallocated ring array
and gives the window vector of the set. ``FeatureStream`` is the step collect mode (live and from bags),
smart mode's classifiers, learning and the benchmarks all share: message -> row (the feature set) -> feature
window -> a vector every ``every`` messages or seconds, once the window holds a whole window of continuous
data (no gap, no backwards time since its rows began).

Pure: numpy only.
"""
import numpy as np

from ..spans import Span
from .base import get

JUMP_BACK_TOLERANCE = 1.0  # seconds a stamp may go backwards before the stream starts over (as WindowBuffer)
EVERY_SLACK = 1e-5         # seconds: stamps 10 ms apart add up to 50 ms give or take float rounding


def _array_of(rows, config):
    feature = config.feature
    if len(rows) == 0:
        raise ValueError('rows: the feature window is empty')
    try:
        array = np.asarray(rows, dtype=float)
    except (ValueError, TypeError):
        array = None
    if array is None or array.ndim != 2 or array.shape[1] != len(feature.columns):
        raise ValueError('rows: expected rows of %d %s channels' % (len(feature.columns), feature.name))
    return array


def window_vector(rows, config):
    """One fixed-length float vector from a feature window (a list of rows, oldest first) of ``config``."""
    return config.feature.vector(_array_of(rows, config), config.span)


def vector_names(config):
    """Names of the entries of ``window_vector(rows, config)``."""
    return config.feature.vector_names(config.span)


def vector_length(config):
    """Length of the vectors of ``config``."""
    return config.feature.vector_length(config.span)


def columns(feature_set):
    """Names of the per-message row channels of a feature set."""
    return get(feature_set).columns


class FeatureWindow(object):
    """The feature window as a preallocated ring array.

    ``add(stamp, row)`` then ``vector()`` gives ``window_vector(rows, config)`` of the rows held (to rounding)
    without building an array from a list at every message. It keeps the last ``count`` rows, or the rows no
    older than ``seconds`` before the newest. ``full``: the window spans ``count`` rows, or ``seconds`` since
    its first row after ``clear`` or after a gap longer than the window.
    """

    def __init__(self, config, capacity=64):
        self.config = config
        self.span = config.span
        self.feature = config.feature
        self._width = len(self.feature.columns)
        size = self.span.count if not self.span.is_duration else max(1, int(capacity))
        self._data = np.zeros((size, self._width))
        self._stamps = np.zeros(size)
        self.clear()

    def clear(self):
        """Drop every row."""
        self._start = 0   # index of the oldest row in the ring
        self._n = 0
        self._since = None

    def __len__(self):
        return self._n

    def _newest(self):
        return self._stamps[(self._start + self._n - 1) % len(self._stamps)]

    @property
    def full(self):
        """True once the window spans ``count`` rows or ``seconds`` (see the class docstring)."""
        if self._n == 0:
            return False
        if self.span.is_duration:
            return self._newest() - self._since >= self.span.seconds
        return self._n >= self.span.count

    def add(self, stamp, row):
        """Append a row (newest) and drop the rows that left the window."""
        size = len(self._stamps)
        if self.span.is_duration:
            if self._since is None or (self._n and stamp - self._newest() > self.span.seconds):
                self._since = stamp  # after a gap longer than the window, it fills again from here
            limit = stamp - self.span.seconds
            while self._n and self._stamps[self._start] < limit:
                self._start = (self._start + 1) % size
                self._n -= 1
            if self._n == size:
                self._grow()
                size = len(self._stamps)
        elif self._n == size:
            self._start = (self._start + 1) % size
            self._n -= 1
        index = (self._start + self._n) % size
        self._data[index] = row
        self._stamps[index] = stamp
        self._n += 1

    def _grow(self):
        order = (self._start + np.arange(self._n)) % len(self._stamps)
        data = np.zeros((2 * len(self._stamps), self._width))
        stamps = np.zeros(2 * len(self._stamps))
        data[:self._n] = self._data[order]
        stamps[:self._n] = self._stamps[order]
        self._data, self._stamps, self._start = data, stamps, 0

    def rows(self):
        """The rows, oldest first, as a 2-D array (a copy)."""
        order = (self._start + np.arange(self._n)) % len(self._stamps)
        return self._data[order]

    def newest(self, span):
        """The rows of the newest ``span`` (a Span: that many messages, or no older than that many seconds
        before the newest row; at least one row), oldest first, as a 2-D array (a copy)."""
        span = Span.parse(span, 'span')
        if self._n == 0:
            return self._data[:0].copy()
        if span.is_duration:
            order = (self._start + np.arange(self._n)) % len(self._stamps)
            count = int(np.count_nonzero(self._stamps[order] >= self._newest() - span.seconds))
        else:
            count = span.count
        count = min(self._n, max(1, count))
        order = (self._start + np.arange(self._n - count, self._n)) % len(self._stamps)
        return self._data[order]

    def vector(self):
        """The window vector of the rows held (ValueError when empty, or for raw when not full)."""
        if self._n == 0:
            raise ValueError('rows: the feature window is empty')
        if self.feature.ordered:
            array = self.rows()
        else:
            size = len(self._stamps)
            if self._start + self._n <= size:
                array = self._data[self._start:self._start + self._n]
            else:
                # the vector does not depend on row order: the ring's rows are the first n, wrapped or not
                array = self._data if self._n == size else self.rows()
        return self.feature.vector(array, self.span)


class FeatureStream(object):
    """Messages of a feature set's inputs -> rows -> feature window -> a vector every ``every``.

    ``add(msg, stamp)`` takes a message of the set's first input and returns its window vector (a numpy
    array) when one is due, else None; ``observe(role, msg, stamp)`` takes a message of another input.
    Rows enter the window at the stream's clock (the newest stamp; stamps may jitter backwards a little);
    time going back more than ``jump_back_tolerance`` clears the window (``resets`` counts it). A vector
    needs a full window of continuous data (``whole``: the set's ``covers`` too); then the first one is
    computed at once and the next after ``every`` messages (a count) or seconds (a duration), counted
    afresh whenever the window stops being whole.
    """

    def __init__(self, config, every=1, max_dt=None, jump_back_tolerance=JUMP_BACK_TOLERANCE):
        self.config = config
        self.span = config.span
        self.every = Span.parse(every, 'every')
        if self.every.count == 0:
            raise ValueError('every: 0 messages; use 1 for a vector at every message')
        kwargs = {} if max_dt is None else {'max_dt': max_dt}
        self.features = config.feature(config, **kwargs)
        self.window = FeatureWindow(config)
        self.jump_back_tolerance = float(jump_back_tolerance)
        self.resets = 0
        self.whole = False   # the window held a whole window of continuous data at the last message
        self._clock = None
        self._since = None   # messages since the last vector (None: a vector at the next whole window)
        self._at = None      # stamp of the last vector

    def observe(self, role, msg, stamp):
        """A message of another input of the set."""
        self.features.observe(role, msg, stamp)

    def observe_raw(self, role, buff, stamp):
        """``observe`` of a message's serialized bytes (the set ``reads_raw`` its connection)."""
        self.features.observe_raw(role, buff, stamp)

    def add(self, msg, stamp):
        """A message of the first input at ``stamp`` (float s); returns the vector when one is due."""
        return self.add_row(self.features.row_values(msg, stamp), stamp)

    def add_raw(self, buff, stamp):
        """``add`` of a message's serialized bytes (the set ``reads_raw`` its connection)."""
        return self.add_row(self.features.row_values_raw(buff, stamp), stamp)

    def add_record(self, record, role=None):
        """A ``window_buffer.Record`` of the first input (``role`` None) or of the input ``role``: read from
        its bytes when it has no decoded message, else from the message."""
        if record.msg is None:
            if role is not None:
                return self.observe_raw(role, record.raw, record.stamp)
            return self.add_raw(record.raw, record.stamp)
        if role is not None:
            return self.observe(role, record.msg, record.stamp)
        return self.add(record.msg, record.stamp)

    def add_row(self, row, stamp):
        """As ``add``, for a row already made by ``self.features``."""
        if self._clock is not None and stamp < self._clock - self.jump_back_tolerance:
            self.resets += 1
            self.window.clear()
            self._clock = None
        self._clock = stamp if self._clock is None or stamp > self._clock else self._clock
        self.window.add(self._clock, row)
        self.whole = self.window.full and self.features.covers(self.span, stamp)
        if not self.whole:
            self._since = self._at = None  # a vector as soon as the window is whole again
            return None
        if not self._due(stamp):
            return None
        return self.window.vector()

    def _due(self, stamp):
        every = self.every
        if self._since is not None:
            self._since += 1
            if every.is_duration:
                if stamp - self._at < every.seconds - EVERY_SLACK and stamp >= self._at:
                    return False
            elif self._since < every.count:
                return False
        self._since = 0
        self._at = stamp
        return True
