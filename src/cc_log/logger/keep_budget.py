"""The keep budget: at most ``max_windows_per_hour`` windows, the most anomalous ones, while the writer streams.

Windows are written as they open, so the budget cannot wait to see the hour and keep its best: it is a rising
threshold over a sliding span of message time. ``n = max_windows_per_hour`` (a number > 0; 0: no budget):

- until ``k`` windows opened in the last span (``k`` = n rounded up, the span ``k / n`` hours: a sliding hour
  for a whole ``n``, 10 h for 0.1, 72 min for 2.5), every Fire that opens a window opens it;
- after that, a Fire with a score opens a window only if the score is more anomalous (lower: scores are
  scikit-learn's, lower is more anomalous) than the k-th most anomalous window kept in the span. Every window
  opened past the budget is then one of the k most anomalous of the trailing span at its moment, and each one
  raises the threshold. (Against the least anomalous window kept instead, any Fire better than the hour's
  worst would open, however many better ones the hour already kept.) A refused Fire would not have been among
  the hour's k best when it came;
- a Fire without a score (NaN or None: the manual trigger, rules) always opens (a person or a rule asked for
  it) and counts against the budget as the most anomalous of windows (its score ranks as -inf);
- a Fire that extends an open window is never refused (the same event); its score, when lower, becomes the
  window's score (a window's score is the lowest of its Fires').

Refused Fires less than pre + post seconds apart (the logger's; at least ``MIN_JOIN``; a count of messages counts
as 0 s) are one skipped window, the one they would have opened; its score is the lowest of theirs. When a window
opens less than ``pre`` seconds after the last of them, they are in its ``pre``: the event's window opened a little
later, nothing was skipped. ``stats()`` counts the skipped windows and keeps the last ``SKIPS_KEPT`` (stamp of the
first refused Fire, trigger, score); ``report(stats)`` says it on /diagnostics and in ``cclog replay``.
Message time that jumps back (a bag played again, a simulator reset) starts the budget afresh. Pure.
"""
import collections
import heapq
import math
import threading

HOUR = 3600.0
MAX_PER_HOUR = 3600.0  # one window a second
MIN_JOIN = 1.0         # seconds: refused Fires closer than this are one skipped window whatever pre and post are
JUMP_BACK = 1.0        # seconds message time may go back before the budget starts afresh (as the window buffer)
SKIPS_KEPT = 10        # skipped windows kept for stats() (the last ones)
DRIFT_HINT = "the keep budget is spent: the robot's normal may have drifted (cclog replay reports drift)"

__all__ = ['KeepBudget', 'report', 'score_of', 'DRIFT_HINT', 'HOUR', 'MAX_PER_HOUR']


def score_of(fire):
    """A Fire's score as a float, None when it has none (None or NaN)."""
    score = getattr(fire, 'score', None)
    if score is None:
        return None
    score = float(score)
    return None if math.isnan(score) else score


class _Kept(object):
    """A window kept: when it opened and its score (-inf: a Fire without one)."""

    __slots__ = ('stamp', 'score')

    def __init__(self, stamp, score):
        self.stamp, self.score = stamp, score


class _Skip(object):
    """A skipped window: the stamp and trigger of its first refused Fire, its score (the lowest), its last stamp."""

    __slots__ = ('stamp', 'trigger', 'score', 'last')

    def __init__(self, stamp, trigger, score):
        self.stamp, self.trigger, self.score, self.last = stamp, trigger, score, stamp


class KeepBudget(object):
    """Which Fires may open a window (see the module docstring). ``max_windows_per_hour``: a number from 0 (no
    budget) to MAX_PER_HOUR; ``pre``, ``post``: the logger's, in seconds (None or 0 for a count of messages).
    Thread-safe: ``admit`` from the message path, ``stats`` from another thread."""

    def __init__(self, max_windows_per_hour=0, pre=0.0, post=0.0):
        self.max_windows_per_hour = check_rate(max_windows_per_hour)
        rate = self.max_windows_per_hour
        self.count = int(math.ceil(rate)) if rate else 0   # k: windows per span
        self.span = HOUR * self.count / rate if rate else HOUR  # seconds of the sliding span
        self.pre = float(pre or 0.0)
        self.join = max(MIN_JOIN, self.pre + float(post or 0.0))
        self._kept = collections.deque()  # _Kept of the span, oldest first
        self._open = None                 # the _Kept of the newest window (extensions lower its score)
        self._newest = None               # newest stamp seen
        self._skips = collections.deque(maxlen=SKIPS_KEPT)  # the last skipped windows: _Skip
        self._skip = None                 # the newest, while a Fire may still join it or a window take it in
        self.skipped = 0                  # skipped windows before _skip
        self._low = self._high = None     # score range of those
        self._lock = threading.Lock()

    def admit(self, stamp, fire, opens=True):
        """Whether ``fire`` (a Fire) at message time ``stamp`` may open a window (``opens``; False: it extends
        the open window, always admitted). A refused Fire is counted as (part of) a skipped window."""
        if not self.count:
            return True
        score = score_of(fire)
        with self._lock:
            self._advance(stamp)
            if not opens:
                if self._open is not None and score is not None and score < self._open.score:
                    self._open.score = score
                return True
            threshold = self._threshold()
            if score is not None and threshold is not None and not score < threshold:
                self._refuse(stamp, fire.name, score)
                return False
            if self._skip is not None and 0 <= stamp - self._skip.last < self.pre:
                self._skip = None  # its Fires are in this window's pre
            self._open = _Kept(stamp, -math.inf if score is None else score)
            self._kept.append(self._open)
            return True

    def threshold(self):
        """The score a Fire must be below to open a window now (None: the budget is not spent)."""
        with self._lock:
            return self._threshold()

    def _threshold(self):
        if len(self._kept) < self.count:
            return None
        return heapq.nsmallest(self.count, (kept.score for kept in self._kept))[-1]

    def _advance(self, stamp):
        """Message time is ``stamp``: windows older than the span leave it; a jump back starts afresh."""
        if self._newest is not None and stamp < self._newest - JUMP_BACK:
            self._kept.clear()
            self._open = None
            self._newest = None
        if self._newest is None or stamp > self._newest:
            self._newest = stamp
        while self._kept and self._kept[0].stamp <= self._newest - self.span:
            self._kept.popleft()

    def _refuse(self, stamp, name, score):
        skip = self._skip
        if skip is not None and 0 <= stamp - skip.last < self.join:  # the same would-be window
            skip.score, skip.last = min(skip.score, score), stamp
            return
        self._settle()
        self._skip = _Skip(stamp, name, score)

    def _settle(self):
        """The newest skipped window is one for good: counted, in the range and the last ones."""
        skip, self._skip = self._skip, None
        if skip is not None:
            self.skipped += 1
            self._skips.append(skip)
            self._low = skip.score if self._low is None else min(self._low, skip.score)
            self._high = skip.score if self._high is None else max(self._high, skip.score)

    def stats(self):
        """``{'max_windows_per_hour', 'windows_skipped', 'skipped_scores' (of the last skipped windows, oldest
        first), 'skipped' ([{stamp, trigger, score}] of those), 'skipped_score_range' ((lowest, highest) score of
        the skipped windows, None before any), 'keep_threshold' (``threshold()``)}``."""
        with self._lock:
            skips = list(self._skips)[1 if self._skip is not None and len(self._skips) == SKIPS_KEPT else 0:]
            skips += [self._skip] if self._skip is not None else []
            scores = [skip.score for skip in skips] + [score for score in (self._low, self._high) if score is not None]
            return {'max_windows_per_hour': self.max_windows_per_hour,
                    'windows_skipped': self.skipped + (self._skip is not None),
                    'skipped_scores': [skip.score for skip in skips],
                    'skipped': [{'stamp': skip.stamp, 'trigger': skip.trigger, 'score': skip.score} for skip in skips],
                    'skipped_score_range': (min(scores), max(scores)) if scores else None,
                    'keep_threshold': self._threshold() if self.count else None}


def check_rate(value, name='max_windows_per_hour'):
    """``value`` as a float from 0 to MAX_PER_HOUR; ValueError('<name>: ...') otherwise."""
    try:
        rate = float(value or 0)
    except (TypeError, ValueError):
        rate = math.nan
    if isinstance(value, bool) or not 0 <= rate <= MAX_PER_HOUR:
        raise ValueError('%s: %r must be a number of windows from 0 (no budget) to %g' % (name, value, MAX_PER_HOUR))
    return rate


def report(stats):
    """'' while no window was skipped, else what the keep budget skipped, in one line: the count, the score range
    and ``DRIFT_HINT`` (``stats``: a logger's, with ``stats()``'s keys)."""
    if not stats.get('windows_skipped'):
        return ''
    low, high = stats['skipped_score_range']
    return '%d window(s) skipped (keep budget %g/h; scores %.3g .. %.3g): %s' % (
        stats['windows_skipped'], stats['max_windows_per_hour'], low, high, DRIFT_HINT)
