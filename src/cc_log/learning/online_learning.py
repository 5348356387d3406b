"""Online learning of nominal: refit a classifier's model from the vectors of spans no trigger flagged.

Off by default; a classifier's ``learn_online: true`` (the smart node's ``~learn_online``) turns it on. The
classifier tells every decision (``observe(stamp, vector, anomalous)``: a nominal vector is offered, an
anomalous score flags), and the node every window opened by any trigger (``flag(stamp)``). A vector waits
until ``guard`` of message time has passed after it; a flag within ``guard`` of it (before or after) drops it,
so nothing from around a flagged span is ever learned (``guard`` should cover the feature window and the
logger's pre and post).
Except in drift: while ``drifting()`` (set by ``drift.monitor_classifiers``: the classifier's drift monitor
reports drift) the classifier's own flags (``flag(stamp, own=True)``) are the new place's driving, not events,
and its anomalous vectors are offered too; flags of other triggers (rules, manual) still guard. The
vectors that pass go into a bounded reservoir (``keep`` vectors, a uniform sample of all of them, kept in time
order). Every ``every`` new vectors the model is refitted in a background thread with ``learning.train`` (the
same scaling, kernel and held-out threshold as learn mode) on the original model's support vectors (what the
model file keeps of its training data) followed by the reservoir; the classifier takes the new model at its
next message (``take()``), and it is saved to ``online_path(model file)``, beside the original, which is never
written (an atomic write: a crash mid-save leaves the previous file whole). A failed refit keeps the model in
use and says why in ``stats()['last_error']``.

The classifier scores with ``WidenedModel(original, refit)``: a vector is anomalous only when the original model
and the latest refit both say so. Online learning thus only ever widens what counts as nominal: in a new place
the refit stops the flood, and where the original fitted, a refit dominated by the last minutes of driving cannot
flag what the original did not (measured on the held-out tuc robot: docs/DETECTION.md).

Pure: numpy and learning; no rospy.
"""
import collections
import hashlib
import os
import random
import threading
import time

import numpy as np

from cc_log.learning import learning
from cc_log.base import safe_files
from cc_log.base.spans import Span

DEFAULT_EVERY = 2000    # new nominal vectors between refits
DEFAULT_KEEP = 5000     # vectors in the reservoir
DEFAULT_GUARD = '10s'   # message time around a flag whose vectors are never learned
ADAPT_HOLD = 300.0      # s of message time the learner goes on adapting after drift was last reported
ONLINE_MARK = '.online'


def online_path(path):
    """Where the refitted model of the model file ``path`` is saved: ``model.json`` -> ``model.online.json``."""
    root, ext = os.path.splitext(path)
    return root + ONLINE_MARK + (ext or '.json')


def fingerprint(model):
    """A short digest of what ``model`` scores with (scaling, kernel arrays, threshold): a refit names the original
    it widens by it."""
    digest = hashlib.sha256()
    for part in [model.mean, model.scale] + [model.kernel[key] for key in sorted(model.kernel)] + [model.threshold]:
        digest.update(np.ascontiguousarray(part, dtype=float).tobytes())
    return digest.hexdigest()[:16]


def training_support(model):
    """The training vectors the model keeps (support vectors, or the Nystroem components), unscaled."""
    centres = model.kernel['support_vectors' if model.kind == 'ocsvm' else 'components']
    return np.asarray(centres, dtype=float) * model.scale + model.mean


class OnlineLearner(object):
    """Learns nominal online for one model (see the module docstring). ``save_path``: None = not saved;
    ``background=False`` refits in the caller's thread (tests, offline replay)."""

    def __init__(self, model, save_path=None, every=DEFAULT_EVERY, keep=DEFAULT_KEEP, guard=DEFAULT_GUARD,
                 seed=0, background=True):
        every, keep = _count(every, 'learn_every', 1), _count(keep, 'learn_keep', learning.MIN_VECTORS)
        guard = Span.parse(guard, 'learn_guard')
        if not guard.is_duration:
            raise ValueError('learn_guard: %s must be a duration such as 10s' % (guard,))
        self.model = model
        self.save_path = save_path
        self.every, self.keep, self.guard = every, keep, guard.seconds
        self.background = background
        self._support = training_support(model)
        self._original = fingerprint(model)
        self.resumed = None                   # a line: the earlier run's refit resumed, or why not (``resume``)
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._pending = collections.deque()   # (stamp, vector) younger than guard
        self._reservoir = []                  # (arrival index, vector)
        self._last_flag = -float('inf')
        self._arrived = 0                     # vectors that passed the guard
        self._new = 0                         # ... since the last refit started
        self._ready = None                    # a refitted model not taken yet
        self._thread = None
        self.seen = self.refused = self.refits = 0
        self.last_refit = None                # wall time of the last refit that finished
        self.last_error = None
        self.drifting = None                  # callable: the classifier's drift monitor reports drift (or None)
        self.adapted = 0                      # vectors offered while adapting that the model had flagged
        self.adapting = False                 # learning the classifier's own flags (``adapting_at``)
        self._adapt_until = -float('inf')

    def adapting_at(self, stamp):
        """Whether the classifier's own flags are learned at ``stamp``: while its drift monitor reports drift and
        ADAPT_HOLD after (else adaptation would stop just below the drift limit, with the new place half learned)."""
        if self.drifting is not None and self.drifting():
            self._adapt_until = stamp + ADAPT_HOLD
        self.adapting = stamp <= self._adapt_until
        return self.adapting

    def observe(self, stamp, vector, anomalous):
        """One decision of the classifier: a nominal vector is offered, an anomalous one flags; while adapting to
        drift (``adapting_at``, asked at every decision: the reservoir follows the state too) both are offered."""
        adapting = self.adapting_at(stamp)
        if anomalous and not adapting:
            self.flag(stamp, own=True)
        else:
            self.offer(stamp, vector, flagged=anomalous)

    def flag(self, stamp, own=False):
        """Something was flagged at ``stamp``: vectors within ``guard`` of it are never learned (thread-safe);
        ``own``: by this classifier (its anomalous score or a window it opened), ignored while ``adapting``."""
        if own and self.adapting:
            return
        with self._lock:
            self._last_flag = max(self._last_flag, stamp)
            while self._pending and self._pending[-1][0] >= stamp - self.guard:
                self._pending.pop()
                self.refused += 1

    def offer(self, stamp, vector, flagged=False):
        """A vector scored nominal at ``stamp`` (message time, increasing), or ``flagged`` while adapting; starts a
        refit when due."""
        with self._lock:
            self.seen += 1
            self.adapted += flagged
            if stamp - self._last_flag <= self.guard:
                self.refused += 1
                return
            if self._pending and stamp < self._pending[-1][0]:  # time went back (a bag played again)
                self.refused += len(self._pending)
                self._pending.clear()
            self._pending.append((stamp, np.array(vector, dtype=float)))
            while self._pending and self._pending[0][0] < stamp - self.guard:
                self._absorb(self._pending.popleft()[1])
            due = self._new >= self.every and self._thread is None
            if due:
                self._new = 0
                vectors = np.vstack([self._support] + [v for _, v in sorted(self._reservoir, key=lambda e: e[0])])
        if due:
            if self.background:
                self._thread = threading.Thread(target=self._refit, args=(vectors,), name='cc_log-online-learning')
                self._thread.daemon = True
                self._thread.start()
            else:
                self._thread = True
                self._refit(vectors)

    def _absorb(self, vector):
        """Reservoir sampling: every vector that passed has the same chance to be in the reservoir."""
        self._arrived += 1
        self._new += 1
        if len(self._reservoir) < self.keep:
            self._reservoir.append((self._arrived, vector))
        else:
            # in drift the newest driving displaces the old at once (the place changed); else a uniform sample
            slot = self._rng.randrange(self.keep if self.adapting else self._arrived)
            if slot < self.keep:
                self._reservoir[slot] = (self._arrived, vector)

    def _refit(self, vectors):
        started = time.time()
        try:
            model, info = learning.train(vectors, config=self.model.config)
            model.info['online'] = {'original': self._original, 'support_vectors_kept': len(self._support),
                                    'reservoir': len(vectors) - len(self._support), 'learned': self._arrived,
                                    'refit': self.refits + 1, 'seconds': time.time() - started}
            if self.save_path is not None:
                model.save(self.save_path)
            with self._lock:
                self._ready = model
                self.refits += 1
                self.last_refit = time.time()
                self.last_error = None
        except Exception as error:  # a refit must never stop the logger: the model in use stays
            with self._lock:
                self.last_error = '%s: %s' % (type(error).__name__, error)
        finally:
            self._thread = None

    def resume(self, load):
        """Go on from the refit an earlier run saved at ``save_path`` (``load(path)``: the model, or ValueError): when
        it widens this same model, the classifier takes it at its first message and its training vectors seed the
        reservoir (the next refit keeps what was learned). Returns ``resumed``: a line saying so, or why it was not
        resumed (it is then replaced at the next refit); None without such a file."""
        path = self.save_path
        if path is None or not os.path.exists(path):
            return None
        try:
            refit = load(path)
        except ValueError as error:
            self.resumed = 'not resumed: %s' % error
            return self.resumed
        online = refit.info.get('online') if isinstance(refit.info.get('online'), dict) else {}
        if 'original' not in online:
            self.resumed = 'not resumed: %s names no original model (saved by an older cc_log or not a refit)' % path
            return self.resumed
        if online['original'] != self._original or refit.config.to_dict() != self.model.config.to_dict():
            self.resumed = 'not resumed: %s widens another model (replaced at the next refit)' % path
            return self.resumed
        with self._lock:
            self._ready = refit
            for vector in training_support(refit):
                self._absorb(vector)
            self._new = 0
        counts = [online.get(key) if isinstance(online.get(key), int) else '?' for key in ('refit', 'learned')]
        self.resumed = 'resumed from %s (its refit %s, %s vectors learned then)' % tuple([path] + counts)
        return self.resumed

    def take(self):
        """The refitted model once it is ready (then None until the next one)."""
        if self._ready is None:
            return None
        with self._lock:
            model, self._ready = self._ready, None
        self.model = model
        return model

    def wait(self, timeout=None):
        """Wait for a refit under way (tests, shutdown); True when none is left."""
        thread = self._thread
        if isinstance(thread, threading.Thread):
            thread.join(timeout)
            return not thread.is_alive()
        return True

    def stats(self):
        """Counters for the diagnostics: vectors seen, learned (passed the guard), refused (near a flag), in the
        reservoir, refits, last refit (wall time, None before the first), last error."""
        with self._lock:
            return {'vectors_seen': self.seen, 'vectors_learned': self._arrived, 'vectors_refused': self.refused,
                    'reservoir': len(self._reservoir), 'refits': self.refits, 'last_refit': self.last_refit,
                    'refitting': self._thread is not None, 'last_error': self.last_error,
                    'adapting': self.adapting, 'vectors_adapted': self.adapted, 'resumed': self.resumed}


class WidenedModel(object):
    """The original model and a refit of it as one model: anomalous only when both are (module docstring).

    ``score`` is the larger of the two scores' distances above their thresholds (``threshold`` 0), so a vector is
    anomalous (``score < 0``) exactly when each model finds it below its own threshold."""

    threshold = 0.0

    def __init__(self, original, refit):
        self.original, self.refit = original, refit
        self.config = original.config
        self.info = refit.info

    def score_each(self, vectors):
        """The combined score of each vector of a list (each model's ``score_each``, so batches score as one)."""
        first = self.original.score_each(vectors)
        second = self.refit.score_each(vectors)
        low, high = self.original.threshold, self.refit.threshold
        return [max(a - low, b - high) for a, b in zip(first, second)]

    def is_anomalous(self, vector):
        """``(score < 0, score)``."""
        value = self.score_each([vector])[0]
        return value < self.threshold, value


def _count(value, name, minimum):
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError('%s: %r must be a whole number >= %d' % (name, value, minimum))
    return value


def from_options(model, path, options, load=None, directory=None):
    """The OnlineLearner of a classifier entry's ``learn_*`` keys (popped from ``options``), or None when
    ``learn_online`` is not true. ``path``: the model file (the refitted model goes beside it); ``load``: the
    model reader, to resume the refit an earlier run saved there (``learn_resume``, default true; ``resume``).
    ``directory``: a run's own directory instead (a bag of a fleet replay): refits go there, none is resumed."""
    enabled = options.pop('learn_online', False)
    keep_learned = options.pop('learn_resume', True)
    keys = dict((key[len('learn_'):], options.pop(key)) for key in ('learn_every', 'learn_keep', 'learn_guard')
                if key in options)
    for key, value in (('learn_online', enabled), ('learn_resume', keep_learned)):
        if not isinstance(value, bool):
            raise ValueError('%s: %r must be true or false' % (key, value))
    if not enabled:
        return None
    saved = (online_path(path) if directory is None
             else safe_files.inside(directory, os.path.basename(online_path(path)), 'model'))
    learner = OnlineLearner(model, saved, **keys)
    if keep_learned and load is not None and directory is None:
        learner.resume(load)
    return learner
