"""The feature window and the one feature-vector step of every mode.

``FeatureWindow`` holds the rows of the last ``count`` messages or ``seconds`` contiguous in a preallocated
array and gives the window vector of the set. ``FeatureStream`` is the step collect mode (live and from
bags), smart mode's classifiers, learning and the benchmarks all share: message -> row (the feature set) ->
feature window -> a vector every ``every`` messages or seconds, once the window holds a whole window of
continuous data (no gap, no backwards time since its rows began). It works a batch at a time: the rows of a
batch go into the array behind the rows held, each due vector's window is a slice of it, and the vectors of
all slices are computed together (``base.window_statistics``); one message is a batch of one.

Pure: numpy only.
"""
import numpy as np

from cc_log.base.spans import Span
from cc_log.features.base import BlockCache, FeatureSet, get, window_statistics

JUMP_BACK_TOLERANCE = 1.0  # seconds a stamp may go backwards before the stream starts over (as WindowBuffer)
SMALL_BLOCK = 8            # rows: add_block finds the slices of fewer in plain Python
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
    """The feature window: the rows held lie contiguous, oldest first, in one preallocated array.

    ``add(stamp, row)`` then ``vector()`` gives ``window_vector(rows, config)`` of the rows held (to rounding)
    without building an array from a list at every message; ``add_block`` appends many rows at once and says
    which rows each of them sees, as slices ``[start, end)`` of ``buffer`` (so the vectors of a batch are
    computed together, ``vectors``). It keeps the last ``count`` rows, or the rows no older than ``seconds``
    before the newest. ``full``: the window spans ``count`` rows, or ``seconds`` since its first row after
    ``clear`` or after a gap longer than the window.
    """

    def __init__(self, config, capacity=64):
        self.config = config
        self.span = config.span
        self.feature = config.feature
        self._width = len(self.feature.columns)
        size = self.span.count if not self.span.is_duration else max(1, int(capacity))
        self._data = np.zeros((size + 1, self._width))
        self._stamps = np.zeros(size + 1)
        self._hi = 0   # the rows held are _data[_lo:_hi]
        self._origin = 0  # rows added before the one at _data[0] (window_statistics' blocks count from the first)
        self.clear()
        vector = getattr(self.feature.vector, '__func__', None)
        self._statistics = vector is not None and vector is FeatureSet.vector.__func__
        self._blocks = BlockCache()  # the statistics of whole blocks of rows, for one window at a time

    def clear(self):
        """Drop every row (slices of ``buffer`` given out before stay as they are until the next ``reserve``)."""
        self._lo = self._hi
        self._since = None

    def __len__(self):
        return self._hi - self._lo

    @property
    def buffer(self):
        """The array the rows are held in (``add_block``'s slices index it; valid until the next ``reserve``)."""
        return self._data

    @property
    def full(self):
        """True once the window spans ``count`` rows or ``seconds`` (see the class docstring)."""
        if self._hi == self._lo:
            return False
        if self.span.is_duration:
            return self._stamps[self._hi - 1] - self._since >= self.span.seconds
        return self._hi - self._lo >= self.span.count

    def reserve(self, count):
        """Room for ``count`` more rows after the ones held: moves them to the front of the array (or into a
        larger one) when needed, which ends the slices given out before."""
        held = self._hi - self._lo
        size = len(self._stamps)
        if self._hi + count <= size:
            return
        if 2 * (held + count) > size:
            size = 2 * (held + count)
            data, stamps = np.zeros((size, self._width)), np.zeros(size)
        else:
            data, stamps = self._data, self._stamps
        data[:held] = self._data[self._lo:self._hi]
        stamps[:held] = self._stamps[self._lo:self._hi]
        self._origin += self._lo
        self._data, self._stamps, self._lo, self._hi = data, stamps, 0, held

    def add(self, stamp, row):
        """Append a row (newest) and drop the rows that left the window."""
        self.add_block([stamp], [row])

    def add_block(self, stamps, rows):
        """Append rows (a 2-D array or a list of rows) at ``stamps`` (floats, none before the newest held),
        oldest first. Returns ``(starts, ends, full)``: the window after each row is ``buffer[start:end]``
        (arrays of ints) and ``full`` (a list of bools) says whether it was full then."""
        count = len(stamps)
        if count == 0:
            return np.zeros(0, dtype=int), np.zeros(0, dtype=int), []
        self.reserve(count)
        lo, hi, seconds = self._lo, self._hi, self.span.seconds
        end = hi + count
        self._data[hi:end] = rows
        self._stamps[hi:end] = stamps
        if count <= SMALL_BLOCK:
            return self._add_few(stamps, lo, hi, end)
        ends = np.arange(hi + 1, end + 1)
        if self.span.is_duration:
            starts = lo + np.searchsorted(self._stamps[lo:end], self._stamps[hi:end] - seconds)
            full = self._filled(stamps, lo, hi)
        else:
            starts = np.maximum(ends - self.span.count, lo)
            full = (ends - starts >= self.span.count).tolist()
        self._lo, self._hi = int(starts[-1]), end
        return starts, ends, full

    def _filled(self, stamps, lo, hi):
        """Whether a duration window is full after each of ``stamps`` (rows stored from ``hi`` on)."""
        seconds, full, since = self.span.seconds, [], self._since
        prev = None if hi == lo else float(self._stamps[hi - 1])
        for stamp in stamps:
            if since is None or (prev is not None and stamp - prev > seconds):
                since = stamp  # after a gap longer than the window, it fills again from here
            full.append(stamp - since >= seconds)
            prev = stamp
        self._since = since
        return full

    def _add_few(self, stamps, lo, hi, end):
        """``add_block``'s slices for a few rows (already stored) in plain Python: the same starts as its
        ``searchsorted`` (the first row no older than ``seconds`` before each row; stamps never go back)."""
        ends = list(range(hi + 1, end + 1))
        if self.span.is_duration:
            seconds, held = self.span.seconds, self._stamps
            starts, first = [], lo
            for j in range(len(stamps)):
                limit = held[hi + j] - seconds
                while held[first] < limit:
                    first += 1
                starts.append(first)
            full = self._filled(stamps, lo, hi)
        else:
            count = self.span.count
            starts = [max(e - count, lo) for e in ends]
            full = [e - b >= count for b, e in zip(starts, ends)]
        self._lo, self._hi = starts[-1], end
        return starts, ends, full

    def rows(self):
        """The rows, oldest first, as a 2-D array (a copy)."""
        return self._data[self._lo:self._hi].copy()

    def newest(self, span):
        """The rows of the newest ``span`` (a Span: that many messages, or no older than that many seconds
        before the newest row; at least one row), oldest first, as a 2-D array (a copy)."""
        return self.newest_of(self._lo, self._hi, span).copy()

    def newest_of(self, start, end, span):
        """``newest(span)`` of the window ``buffer[start:end]`` (a slice from ``add_block``) as a view of it."""
        span = Span.parse(span, 'span')
        if end == start:
            return self._data[start:end]
        if span.is_duration:
            first = start + int(np.searchsorted(self._stamps[start:end], self._stamps[end - 1] - span.seconds))
        else:
            first = end - span.count
        return self._data[min(end - 1, max(start, first)):end]

    def vector(self):
        """The window vector of the rows held (ValueError when empty, or for raw when not full)."""
        if self._hi == self._lo:
            raise ValueError('rows: the feature window is empty')
        return self.feature.vector(self._data[self._lo:self._hi], self.span)

    def vectors(self, starts, ends):
        """The window vectors of the windows ``buffer[start:end]`` (slices from ``add_block``) as the rows of a
        2-D array: the statistics of all of them at once for a set whose vector is the default one, else
        one ``vector`` each."""
        if self._statistics:
            return window_statistics(self._data, starts, ends, self._origin, self._blocks)
        vectors = [self.feature.vector(self._data[start:end], self.span) for start, end in zip(starts, ends)]
        return np.array(vectors, dtype=float).reshape(len(vectors), self.feature.vector_length(self.span))


class WindowBatch(object):
    """The window vectors of a batch of rows (``FeatureStream.add_rows`` / ``add_records``).

    ``steps``: one per record, None for a record of another input, else ``(reset, whole, k)``: whether time
    went back at it (the window started over), whether the window was whole after it, and the number of its
    vector in ``vectors`` (None when none was due). ``rows(k)`` and ``newest(k, span)`` are the window of
    vector ``k`` and its newest rows, views of the window's array valid until the stream's next row.
    """

    def __init__(self, window, steps, vectors, starts, ends):
        self.window = window
        self.steps = steps
        self.vectors = vectors
        self._starts = starts
        self._ends = ends

    def rows(self, k):
        """The rows of the window vector ``k`` was computed from, oldest first (a view)."""
        return self.window.buffer[self._starts[k]:self._ends[k]]

    def newest(self, k, span):
        """``FeatureWindow.newest(span)`` of the window of vector ``k`` (a view)."""
        return self.window.newest_of(self._starts[k], self._ends[k], span)


class FeatureStream(object):
    """Messages of a feature set's inputs -> rows -> feature window -> a vector every ``every``.

    ``add(msg, stamp)`` takes a message of the set's first input and returns its window vector (a numpy
    array) when one is due, else None; ``observe(role, msg, stamp)`` takes a message of another input;
    ``add_records(records, roles)`` takes a batch of both and computes its rows and vectors together (one
    code path: the others are a batch of one).
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
        self._no_vectors = np.zeros((0, vector_length(config)))
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
        """A ``records.Record`` of the first input (``role`` None) or of the input ``role``: read from
        its bytes when it has no decoded message, else from the message."""
        if role is None:
            return _only_vector(self.add_records([record], {}))
        if record.msg is None:
            return self.observe_raw(role, record.raw, record.stamp)
        return self.observe(role, record.msg, record.stamp)

    def add_row(self, row, stamp):
        """As ``add``, for a row already made by ``self.features``."""
        return _only_vector(self.add_rows([row], [stamp], [self.features.covers(self.span, stamp)]))

    def add_records(self, records, roles):
        """A batch of ``records.Record``s in order: those whose topic is in ``roles`` (``{topic: role}``)
        are ``observe``d, the others are of the first input. Each run of consecutive records of the first input
        gets its rows from the set's ``row_block``; then the window takes all rows. Returns a ``WindowBatch``
        (views of the window: use it before the next row)."""
        if len(records) <= SMALL_BLOCK:
            return self._add_few_records(records, roles)
        rows, stamps, covered, steps = [], [], [], []
        run = []

        def flush():
            raw = run[0].msg is None
            block, covers = self.features.row_block([r.raw if raw else r.msg for r in run], [r.stamp for r in run],
                                                    raw, self.span)
            rows.append(block)
            covered.extend(covers.tolist())
            del run[:]

        for record in records:
            role = roles.get(record.topic)
            if role is not None:
                if run:
                    flush()
                self.add_record(record, role)
                steps.append(False)
                continue
            if run and (run[0].msg is None) != (record.msg is None):
                flush()
            run.append(record)
            stamps.append(record.stamp)
            steps.append(True)
        if run:
            flush()
        batch = self.add_rows(np.concatenate(rows) if rows else (), stamps, covered)
        first = iter(batch.steps)
        batch.steps = [next(first) if mine else None for mine in steps]
        return batch

    def _add_few_records(self, records, roles):
        """``add_records`` of a few records (a live batch) one by one, without the block machinery: the same
        rows (``row_values(_raw)``), window slices and vectors."""
        features, span = self.features, self.span
        self.window.reserve(len(records))  # no slice of this batch moves
        steps, starts, ends = [], [], []
        for record in records:
            role = roles.get(record.topic)
            if role is not None:
                self.add_record(record, role)
                steps.append(None)
                continue
            stamp = record.stamp
            if record.msg is None:
                row = features.row_values_raw(record.raw, stamp)
            else:
                row = features.row_values(record.msg, stamp)
            steps.append(self._add_one(row, stamp, features.covers(span, stamp), starts, ends))
        vectors = self.window.vectors(starts, ends) if starts else self._no_vectors
        return WindowBatch(self.window, steps, vectors, starts, ends)

    def _add_one(self, row, stamp, covered, starts, ends):
        """One row through the window as ``add_rows`` takes it; its slice appended to ``starts``/``ends`` when
        a vector is due. Returns its step."""
        reset = self._advance_clock(stamp)
        if reset:
            self.resets += 1
            self.window.clear()
        lows, highs, full = self.window.add_block([self._clock], [row])
        step = self._step(full[0] and covered, stamp, lows[0], highs[0], starts, ends)
        return (True,) + step[1:] if reset else step

    def _advance_clock(self, stamp):
        """Move the stream's clock to ``stamp`` (never back, but for a jump back beyond the tolerance, when it
        starts over at ``stamp``); True for such a jump."""
        reset = self._clock is not None and stamp < self._clock - self.jump_back_tolerance
        if reset or self._clock is None or stamp > self._clock:
            self._clock = stamp
        return reset

    def _step(self, whole, stamp, start, end, starts, ends):
        """The step ``(False, whole, k)`` of a row after which the window is ``buffer[start:end]`` (``whole``:
        full and covered); its slice appended to ``starts``/``ends`` when a vector is due."""
        self.whole = whole
        if not whole:
            self._since = self._at = None  # a vector as soon as the window is whole again
            return (False, False, None)
        if not self._due(stamp):
            return (False, True, None)
        starts.append(int(start))
        ends.append(int(end))
        return (False, True, len(starts) - 1)

    def add_rows(self, rows, stamps, covered):
        """Rows already made by ``self.features`` (a 2-D array or a list of rows) at ``stamps``, ``covered``:
        the set's ``covers`` right after each. The window bookkeeping row by row, then the vectors of every
        row where one is due at once. Returns a ``WindowBatch`` (one step per row)."""
        window = self.window
        window.reserve(len(stamps))  # no slice of this batch moves (clear keeps the rows where they are)
        steps, starts, ends = [], [], []
        first, clocks, resets = 0, [], []
        for i, stamp in enumerate(stamps):
            if self._advance_clock(stamp):
                resets.append(i)
            clocks.append(self._clock)
        for last in resets + [len(stamps)]:
            if last > first:
                segment = window.add_block(clocks[first:last], rows[first:last])
                self._bookkeeping(segment, stamps, covered, first, steps, starts, ends)
            if last < len(stamps):
                self.resets += 1
                window.clear()
                first = last
        for i in resets:
            steps[i] = (True,) + steps[i][1:]
        vectors = window.vectors(starts, ends) if starts else self._no_vectors
        return WindowBatch(window, steps, vectors, starts, ends)

    def _bookkeeping(self, segment, stamps, covered, first, steps, starts, ends):
        """The steps of the rows ``first``... of a segment without a reset (``add_block``'s slices)."""
        lows, highs, full = segment
        for j, full_now in enumerate(full):
            i = first + j
            steps.append(self._step(full_now and covered[i], stamps[i], lows[j], highs[j], starts, ends))

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


def _only_vector(batch):
    """The vector of a batch of one row, or None."""
    k = batch.steps[0][2]
    return None if k is None else batch.vectors[k]
