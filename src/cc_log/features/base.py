"""What every feature set shares: the registry, ``FeatureSet`` (message -> row), ``FeatureConfig``.

A feature set turns the messages of its input topics into per-message feature *rows* and a window of rows
into one fixed-length *vector* the model scores. It declares:

- ``inputs``: ``((role, message type), ...)``; the first input makes the rows (one per message, and its
  stamps are the feature window's clock); messages of the others only update the set's state
  (``observe``), e.g. the latest velocity command;
- ``columns``: the names of the row's entries; ``vector_names(span)`` those of the vector;
- ``read(msg)``: the numbers it takes from a message of the first input (a tuple of floats) and
  ``make_row(stamp, values)``: the row (a tuple of floats; None rejects the message);
- optionally ``read_raw(buff)``: the same numbers straight from the serialized bytes, and ``observe_raw``
  for the other inputs, for the message layouts whose md5sums are in ``raw_md5sums`` (fixed offsets, read
  with ``struct.unpack_from``); ``reads_raw(connection)`` says whether a connection's messages can be read
  so, otherwise they are decoded first;
- ``vector(array, span)``: the vector of a window (a 2-D array of rows, oldest first); by default the
  mean, std, min and max of every column (``ordered = False``: the order of the rows does not matter).

``register`` adds a class to the registry under its ``name``; ``get(name)`` finds it (ValueError naming the
feature set otherwise). The base class handles bad input and irregular time the same way for every set: a
message with a non-finite or missing field never raises, its row repeats the last good row (zeros before
any) and ``rejected`` counts it; a row value beyond +-CLIP (far beyond any physical range, or one that
overflowed to inf or NaN from finite input: ``linear.x = 1e200`` squared) is clipped to it and the row counted
in ``out_of_range``: a window holding such a row is anomalous whatever its score (``out_of_range(rows)``, read by
the classifier trigger), never a nominal-looking vector; sets that use derivatives call ``_step(stamp)``: a
repeated stamp (closer than ``min_dt``) keeps the previous derivatives, time going backwards or a gap longer
than ``max_dt`` restarts them (``restarts``), and ``covers(span, stamp)`` says whether the rows since then fill a
window.

Pure Python plus numpy: no rospy. Messages are read by attribute, so any object with the layout works.
"""
import collections
import math
import struct

import numpy as np

from cc_log.base.registry import Registry
from cc_log.base.spans import Range, Span

STATISTICS = ('mean', 'std', 'min', 'max')
DEFAULT_MAX_DT = 1.0    # seconds: a longer gap between messages restarts the derivatives
DEFAULT_MIN_DT = 1e-4   # seconds: a shorter step counts as a repeated stamp
CLIP = 1e6              # every row value is clipped to +-CLIP so window statistics stay finite; a value
#                         beyond it is out of any physical range (real odometry rows stay below 1e4)

RESTART, REPEAT, STEP = 'restart', 'repeat', 'step'

_REGISTRY = Registry('feature_set', 'name')
names = _REGISTRY.names
get = _REGISTRY.get


def register(cls):
    """Class decorator: add a FeatureSet subclass to the registry under ``cls.name``."""
    if not cls.name or not cls.inputs or not cls.columns:
        raise ValueError('feature set %s: needs a name, inputs and columns' % cls.__name__)
    return _REGISTRY.register(cls)


#: A feature window's sane messages and seconds (a window of 1e-300 s holds no row: no vector, ever).
WINDOW_RANGES = (Range(1, 100000, 'messages'), Range(0.01, 3600.0, 's'))


def _parse_window(value):
    return Span.parse(value, 'window', *WINDOW_RANGES)


DEFAULT_WINDOW = '2s'  # a duration: the same span of driving at any rate (500 messages: 5 s at 100 Hz, 100 s at 5 Hz)


class FeatureConfig(collections.namedtuple('FeatureConfig', 'feature_set window topic_type')):
    """What a model was trained on: feature set, feature window (``'500'`` or ``'5s'``), and the message type
    of the set's first input (None: the set's own).

    The window is normalised to its canonical text (``'500'``, ``'5s'``); bad values raise
    ``ValueError('<field>: <what is wrong>')``.
    """

    __slots__ = ()

    def __new__(cls, feature_set='motion', window=DEFAULT_WINDOW, topic_type=None):
        feature = get(feature_set)
        span = _parse_window(window)
        expected = feature.inputs[0][1]
        topic_type = expected if topic_type is None else topic_type
        if topic_type != expected:
            raise ValueError('topic_type: %r is not supported by the %s feature set (it reads %s)'
                             % (topic_type, feature_set, expected))
        if feature.count_window and span.is_duration:
            raise ValueError('window: the %s feature set needs a message count, not %s' % (feature_set, span))
        return super(FeatureConfig, cls).__new__(cls, feature_set, str(span), topic_type)

    @property
    def span(self):
        """The feature window as a Span."""
        return Span.parse(self.window, 'window')

    @property
    def feature(self):
        """The FeatureSet class of ``feature_set``."""
        return get(self.feature_set)

    def to_dict(self):
        """Plain dict (JSON-ready)."""
        return {'feature_set': self.feature_set, 'window': self.window, 'topic_type': self.topic_type}

    @classmethod
    def from_dict(cls, data):
        """Build from ``to_dict()`` output; raise ValueError for anything else."""
        if not isinstance(data, dict):
            raise ValueError('config: expected an object, got %s' % type(data).__name__)
        missing = [key for key in cls._fields if key not in data]
        if missing:
            raise ValueError('config: missing %s' % ', '.join(missing))
        extra = sorted(set(data) - set(cls._fields))
        if extra:
            raise ValueError('config: unknown field(s) %s' % ', '.join(map(str, extra)))
        for key in cls._fields:
            if not isinstance(data[key], str):
                raise ValueError('config: %s must be a string, got %r' % (key, data[key]))
        return cls(data['feature_set'], data['window'], data['topic_type'])


def stamp_of(msg, fallback):
    """``msg.header.stamp`` in float seconds when the message has a non-zero one, else ``fallback``."""
    header = getattr(msg, 'header', None)
    stamp = getattr(header, 'stamp', None)
    if stamp is not None:
        secs = getattr(stamp, 'secs', None)
        if secs is not None:
            value = secs + getattr(stamp, 'nsecs', 0) * 1e-9
            if value != 0:
                return float(value)
    if hasattr(fallback, 'to_sec'):
        return fallback.to_sec()
    return float(fallback)


def _clip(value):
    if value < -CLIP:
        return -CLIP
    if not value <= CLIP:  # beyond, or NaN (an overflow: inf - inf)
        return CLIP
    return value


def clipped(values):
    """``values`` (a tuple of floats) with every entry clipped to +-CLIP, NaN to +CLIP (itself when none is out of
    range: then the same object)."""
    if finite(values) and max(values) <= CLIP and min(values) >= -CLIP:
        return values
    return tuple(_clip(value) for value in values)


def out_of_range(rows):
    """Whether the rows of a feature window (a 2-D array) hold a value clipped at +-CLIP: a value out of any
    physical range, anomalous by construction."""
    return bool(len(rows)) and float(np.max(np.abs(rows))) >= CLIP


def finite(values):
    """Whether every float of ``values`` is finite."""
    # finite iff x - x == 0 (NaN and +-inf give NaN); the sum is the fast path
    return sum(values) * 0.0 == 0.0 or all(math.isfinite(x) for x in values)


def statistics(array):
    """mean, std, min, max of every column of a 2-D array, concatenated."""
    # the ufuncs' reductions themselves: what array.mean / min / max compute, without their Python wrappers
    count = array.shape[0]
    mean = np.add.reduce(array, axis=0) / count
    centred = array - mean
    std = np.sqrt(np.einsum('ij,ij->j', centred, centred) / count)
    return np.concatenate((mean, std, np.minimum.reduce(array, axis=0), np.maximum.reduce(array, axis=0)))


WINDOW_GRID = 32  # rows: window_statistics shares the blocks of this many rows between overlapping slices


def _ranges(lows, highs):
    """The indices of the ranges ``[low, high)`` one after the other (a 1-D int array)."""
    sizes = highs - lows
    return np.arange(sizes.sum()) + np.repeat(lows - (np.cumsum(sizes) - sizes), sizes)


def _pieces(rows, cuts, sizes):
    """Sum, mean, squared deviation from the mean, min and max of the pieces ``rows[cut:cut + size]`` (one after
    the other, none empty), each a row of a 2-D array."""
    sums = np.add.reduceat(rows, cuts, axis=0)
    means = sums / sizes[:, None]
    centred = rows - np.repeat(means, sizes, axis=0)
    return (sums, means, np.add.reduceat(centred * centred, cuts, axis=0), np.minimum.reduceat(rows, cuts, axis=0),
            np.maximum.reduceat(rows, cuts, axis=0))


def window_statistics(array, starts, ends, origin=0, cache=None):
    """``statistics(array[start:end])`` of every ``(start, end)`` pair (non-empty slices of a 2-D array), as the
    rows of a 2-D array, computed together.

    Overlapping slices share the work: each slice is cut into the whole blocks of WINDOW_GRID rows it holds
    (row ``origin + i`` of a count kept since the first: a block starts at a multiple of WINDOW_GRID) between a
    head and a tail of its own; the sum, mean, squared deviation from its mean, min and max of every block and
    every head and tail are taken once, and a slice's statistics combined from its pieces' in order (its squared
    deviation as the pieces' own plus size * (piece mean - slice mean)^2 each: no cancellation). The pieces of
    a slice do not depend on the other slices, so a slice gives the same floats in any batch. ``cache``: a
    BlockCache of this array, used for a single slice.
    """
    if len(starts) == 1:
        return _one_window_statistics(array, int(starts[0]), int(ends[0]), origin, cache)
    starts, ends = np.asarray(starts, dtype=np.intp), np.asarray(ends, dtype=np.intp)
    if len(starts) == 0:
        return np.empty((0, 4 * array.shape[1]))
    lengths = ends - starts
    if lengths.min() < 1:
        raise ValueError('rows: the feature window is empty')
    grid = WINDOW_GRID
    blocks_lo = starts + (-(starts + origin)) % grid
    blocks_hi = ends - (ends + origin) % grid
    blocks = np.maximum(blocks_hi - blocks_lo, 0) // grid
    blocks_lo = np.where(blocks > 0, blocks_lo, ends)  # no whole block: the slice is its own head
    blocks_hi = np.where(blocks > 0, blocks_hi, ends)
    heads, tails = blocks_lo > starts, ends > blocks_hi
    tables, first = [], np.zeros(len(starts), dtype=np.intp)
    if blocks.any():
        low, high = blocks_lo[blocks > 0].min(), blocks_hi[blocks > 0].max()
        count = (high - low) // grid
        tables.append(_pieces(array[low:high], np.arange(0, high - low, grid), np.full(count, grid)))
        first = (blocks_lo - low) // grid  # the number of each slice's first block
    else:
        count = 0
    own_lo = np.concatenate((starts[heads], blocks_hi[tails]))
    own_hi = np.concatenate((blocks_lo[heads], ends[tails]))
    own_sizes = own_hi - own_lo
    if len(own_sizes):
        tables.append(_pieces(array[_ranges(own_lo, own_hi)], np.cumsum(own_sizes) - own_sizes, own_sizes))
    sums, means, squares, lows, highs = (np.concatenate(column) for column in zip(*tables))
    sizes = np.concatenate((np.full(count, grid), own_sizes))
    head = count + np.cumsum(heads) - 1
    tail = count + heads.sum() + np.cumsum(tails) - 1
    # the pieces of each slice in order (head, blocks, tail), the slices one after the other
    counts = heads + blocks + tails
    offsets = np.cumsum(counts) - counts
    which = np.repeat(np.arange(len(starts)), counts)
    position = np.arange(counts.sum()) - offsets[which]
    in_blocks = position - heads[which]
    piece = np.where(heads[which] & (position == 0), head[which],
                     np.where(in_blocks < blocks[which], first[which] + in_blocks, tail[which]))
    length = lengths[:, None]
    mean = np.add.reduceat(sums[piece], offsets, axis=0) / length
    deviation = means[piece] - mean[which]
    spread = np.add.reduceat(squares[piece] + sizes[piece, None] * deviation * deviation, offsets, axis=0)
    return np.concatenate((mean, np.sqrt(spread / length), np.minimum.reduceat(lows[piece], offsets, axis=0),
                           np.maximum.reduceat(highs[piece], offsets, axis=0)), axis=1)


class BlockCache(object):
    """The pieces (sum, mean, squared deviation, min, max) of the whole blocks of WINDOW_GRID rows of one growing
    array of rows, by block number, so consecutive windows of a stream compute each block once. A row, once
    added, never changes (``FeatureWindow`` only appends), so a block's pieces hold for good."""

    def __init__(self):
        self._first = 0      # number of the block in row 0 of the tables
        self._count = 0      # blocks held
        self._tables = None  # five 2-D arrays, a row per block

    def pieces(self, array, low, count, number):
        """The pieces of the ``count`` blocks from ``array[low]`` on, the first being block ``number``."""
        first, held = self._first, self._count
        if not (first <= number <= first + held):
            first = self._first = number
            held = self._count = 0
        if number + count > first + held:  # the blocks not held yet, from the first missing one on
            start = max(first + held, number)
            new = number + count - start
            begin = low + (start - number) * WINDOW_GRID
            made = _pieces(array[begin:begin + new * WINDOW_GRID], np.arange(0, new * WINDOW_GRID, WINDOW_GRID),
                           np.full(new, WINDOW_GRID))
            keep = first + held - number  # held blocks still wanted (older ones are dropped)
            if self._tables is None or len(self._tables[0]) < keep + new or number > first:
                old = self._tables
                size = max(64, 2 * (keep + new))
                self._tables = [np.empty((size, array.shape[1])) for _ in range(5)]
                if keep:
                    for table, before in zip(self._tables, old):
                        table[:keep] = before[number - first:number - first + keep]
                first = self._first = number
                held = keep
            for table, part in zip(self._tables, made):
                table[held:held + new] = part
            self._count = held + new
        return [table[number - first:number - first + count] for table in self._tables]


def _one_window_statistics(array, start, end, origin, cache=None):
    """``window_statistics`` of one slice (a live batch's usual case): the same pieces in the same order and the
    same reductions, so the same floats, with its bookkeeping in plain integers (and its whole blocks from
    ``cache``, a BlockCache of ``array``, when given)."""
    if end <= start:
        raise ValueError('rows: the feature window is empty')
    grid = WINDOW_GRID
    low, high = start + (-(start + origin)) % grid, end - (end + origin) % grid
    count = max(high - low, 0) // grid
    if not count:
        low = high = end
    own = [(a, b) for a, b in ((start, low), (high, end)) if b > a]
    tables, sizes = [], []
    if own:
        own_sizes = np.array([b - a for a, b in own], dtype=np.intp)
        rows = array[own[0][0]:own[0][1]] if len(own) == 1 else np.concatenate([array[a:b] for a, b in own])
        own_table = _pieces(rows, np.cumsum(own_sizes) - own_sizes, own_sizes)
    if start < low:  # the head
        tables.append([column[:1] for column in own_table])
        sizes.append(own_sizes[:1])
    if count:
        if cache is None:
            tables.append(_pieces(array[low:high], np.arange(0, high - low, grid), np.full(count, grid)))
        else:
            tables.append(cache.pieces(array, low, count, (low + origin) // grid))
        sizes.append(np.full(count, grid))
    if high < end:  # the tail
        tables.append([column[-1:] for column in own_table])
        sizes.append(own_sizes[-1:])
    sums, means, squares, lows, highs = (np.concatenate(column) for column in zip(*tables))
    sizes = np.concatenate(sizes)
    offsets = np.zeros(1, dtype=np.intp)
    length = np.array([[end - start]], dtype=np.intp)
    mean = np.add.reduceat(sums, offsets, axis=0) / length
    deviation = means - mean
    spread = np.add.reduceat(squares + sizes[:, None] * deviation * deviation, offsets, axis=0)
    return np.concatenate((mean, np.sqrt(spread / length), np.minimum.reduceat(lows, offsets, axis=0),
                           np.maximum.reduceat(highs, offsets, axis=0)), axis=1)


_UINT32 = struct.Struct('<I')


def after_header(buff):
    """Offset of the first byte after the std_msgs/Header (seq, stamp, frame_id) a message's bytes start with."""
    return 16 + _UINT32.unpack_from(buff, 12)[0]


def after_string(buff, offset):
    """Offset of the first byte after the string (uint32 length, then its bytes) at ``offset``."""
    return offset + 4 + _UINT32.unpack_from(buff, offset)[0]


def xyz(vector):
    """``(x, y, z)`` of a geometry_msgs/Vector3 or Point as floats."""
    return (float(vector.x), float(vector.y), float(vector.z))


class FeatureSet(object):
    """A feature set: per-message rows of its first input, a vector per window (see the module docstring).

    Instances are stateful (derivatives need the previous message): one per stream of messages.
    ``row(msg, stamp)`` returns a new 1-D float array (never NaN or inf), ``row_values(msg, stamp)`` the
    same row as a tuple of plain floats (the per-message fast path), ``observe(role, msg, stamp)`` takes a
    message of another input.
    """

    name = None
    inputs = ()          # ((role, message type), ...): the first makes the rows
    columns = ()
    ordered = False      # True when the window vector depends on the order of the rows
    count_window = False  # True when the window must be a message count
    raw_md5sums = frozenset()  # md5sums of the input layouts read_raw / observe_raw read from bytes

    def __init__(self, config=None, max_dt=DEFAULT_MAX_DT, min_dt=DEFAULT_MIN_DT):
        self.config = config if config is not None else FeatureConfig(self.name)
        if not isinstance(self.config, FeatureConfig):
            raise ValueError('config: expected a FeatureConfig, got %s' % type(self.config).__name__)
        if self.config.feature_set != self.name:
            raise ValueError('config: feature set %r, not %r' % (self.config.feature_set, self.name))
        if not (max_dt > min_dt > 0):
            raise ValueError('max_dt: must be larger than min_dt (%r) and positive' % min_dt)
        self.max_dt = float(max_dt)
        self.min_dt = float(min_dt)
        self.rejected = 0
        self.out_of_range = 0  # rows with a value clipped at +-CLIP
        self.restarts = 0
        self.reset()

    # -- what a set defines ---------------------------------------------------------------------------

    def read(self, msg):
        """The floats this set takes from a message of its first input (AttributeError etc. when missing)."""
        raise NotImplementedError

    def read_raw(self, buff):
        """``read`` of the serialized bytes of a message of the first input (a layout of ``raw_md5sums``)."""
        raise NotImplementedError

    def observe_raw(self, role, buff, stamp):
        """``observe`` of the serialized bytes of a message of another input (a layout of ``raw_md5sums``)."""
        raise NotImplementedError

    @classmethod
    def reads_raw(cls, connection):
        """Whether messages of ``connection`` (a connection header dict, or None) are read from their bytes."""
        return connection is not None and connection.get('md5sum') in cls.raw_md5sums

    def make_row(self, stamp, values):
        """The row of ``values`` (from ``read``) at ``stamp``, or None to reject the message."""
        raise NotImplementedError

    def observe(self, role, msg, stamp):
        """Take a message of another input (``role`` as in ``inputs``); the default ignores it."""

    def reset_state(self):
        """Forget what the set keeps between messages (called by ``reset``)."""

    @classmethod
    def vector(cls, array, span):
        """The vector of a window of rows (2-D array, oldest first); default: mean, std, min, max."""
        return statistics(array)

    @classmethod
    def vector_names(cls, span):
        """Names of the entries of ``vector``."""
        return ['%s(%s)' % (stat, name) for stat in STATISTICS for name in cls.columns]

    @classmethod
    def vector_length(cls, span):
        """Length of ``vector``."""
        return len(cls.vector_names(span))

    # -- shared machinery -----------------------------------------------------------------------------

    def reset(self):
        """Forget the previous message (derivatives restart at the next one)."""
        self._prev_stamp = None   # stamp of the last message a derivative was taken against
        self._last_row = None
        self.segment_start = None  # stamp of the first row since the derivatives last restarted
        self.segment_rows = 0      # rows since then
        self.reset_state()

    def row(self, msg, stamp):
        """The feature row of ``msg`` received at ``stamp`` (float seconds)."""
        return np.array(self.row_values(msg, stamp), dtype=float)

    def row_values(self, msg, stamp):
        """``row(msg, stamp)`` as a tuple of plain floats (no numpy)."""
        return self._row_of(self.read, msg, stamp)

    def row_values_raw(self, buff, stamp):
        """``row_values`` of a message's serialized bytes (see ``read_raw``)."""
        return self._row_of(self.read_raw, buff, stamp)

    def row_block(self, items, stamps, raw, span):
        """Rows of consecutive messages of the first input: ``items`` are serialized bytes when ``raw``, else
        messages, at ``stamps`` (floats). Returns ``(rows, covered)``: an (n, width) float array equal to
        ``row_values(_raw)`` called on each in turn, and an (n,) bool array, ``covers(span, stamp)`` right
        after each row; the set's state afterwards is as after those calls. A set may compute a block at once
        (numpy) where it gives the same floats; this default goes message by message."""
        row_of = self.row_values_raw if raw else self.row_values
        rows = np.empty((len(items), len(self.columns)))
        covered = np.empty(len(items), dtype=bool)
        for i, (item, stamp) in enumerate(zip(items, stamps)):
            rows[i] = row_of(item, stamp)
            covered[i] = self.covers(span, stamp)
        return rows, covered

    def _row_of(self, read, msg, stamp):
        try:
            values = read(msg)
            stamp = float(stamp)
            ok = finite(values + (stamp,))
        except (AttributeError, TypeError, ValueError, OverflowError, struct.error):
            ok = False
        row = self.make_row(stamp, values) if ok else None
        if row is None:
            return self._reject()
        within = clipped(row)
        if within is not row:
            self.out_of_range += 1
        row = self._last_row = within
        return row

    def covers(self, span, stamp):
        """True when the rows since the last restart (gap, backwards time) fill ``span`` up to ``stamp``.

        A feature window is time-based and may hold rows from before a gap or only a few rows after one;
        callers that want only whole windows of continuous data check this as well.
        """
        span = Span.parse(span, 'window')
        if self.segment_start is None:
            return False
        if span.is_duration:
            return stamp - self.segment_start >= span.seconds
        return self.segment_rows >= span.count

    def _reject(self):
        self.rejected += 1
        if self._last_row is None:
            return (0.0,) * len(self.columns)
        return self._last_row

    def _count(self, stamp):
        if self.segment_start is None:
            self.segment_start = stamp
        self.segment_rows += 1

    def _step(self, stamp):
        """``(RESTART | REPEAT | STEP, dt)`` of a message at ``stamp`` against the previous one, counting the
        row: RESTART for the first message, time going backwards or a gap beyond max_dt (the stamp becomes
        the reference), REPEAT for a step below min_dt (the reference stays), STEP otherwise (``stamp``
        becomes the reference)."""
        prev = self._prev_stamp
        dt = None if prev is None else stamp - prev
        if dt is None or dt < 0 or dt > self.max_dt:
            if prev is not None:
                self.segment_start = None
                self.segment_rows = 0
            self.restarts += 1
            self._prev_stamp = stamp
            kind = RESTART
        elif dt < self.min_dt:
            kind = REPEAT
        else:
            kind = STEP
            self._prev_stamp = stamp
        self._count(stamp)
        return kind, dt
