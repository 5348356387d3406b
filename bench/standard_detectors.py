"""The window detectors of ``bench/detectors.py``, on its windows of the 19 envelope features: ``fit(X)`` on the
training windows sets ``zero`` (the median training score) and ``extreme`` (the most anomalous one), ``score(X)``
is lower for more anomalous windows, ``threshold(level)`` flags below ``zero - level x (zero - extreme)``."""
import os
import sys
import warnings

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import detection_heldout as heldout  # noqa: E402

from cc_log.learning import envelope  # noqa: E402

TOPIC = heldout.TOPIC
WINDOW, STRIDE = 1.0, 0.25


class Detector(object):
    """A window detector: ``fit(X)`` on training windows sets ``zero`` and ``extreme``; ``score(X)``."""

    def threshold(self, level):
        """Flag a window whose score is below this."""
        return self.zero - level * (self.zero - self.extreme)


class Envelope(Detector):
    """The physics envelope (``learning.envelope``): per-feature training maximum floored; score = -(largest ratio to
    it), so level 2 is the envelope trigger's default factor."""

    def fit(self, X):
        self.limits = envelope.learn([X], TOPIC, WINDOW, STRIDE, len(X) * STRIDE, joint=False, local=False).trained()
        self.zero, self.extreme = 0.0, -1.0
        return self

    def ratios(self, X):
        return envelope.ratios(X, self.limits)

    def score(self, X):
        return -self.ratios(X).max(axis=1) if len(X) else np.zeros(0)


class Standardised(Detector):
    """A standard detector on standardised features; ``zero`` / ``extreme``: median / lowest training score."""

    def __init__(self, make):
        self.make = make

    def fit(self, X):
        from sklearn.preprocessing import StandardScaler
        self.scaler = StandardScaler().fit(X)
        self.model = self.make()
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            train = np.asarray(self.model.fit(self.scaler.transform(X)), dtype=float)
        self.zero, self.extreme = float(np.median(train)), float(train.min())
        return self

    def score(self, X):
        if not len(X):
            return np.zeros(0)
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            return np.asarray(self.model.score(self.scaler.transform(X)), dtype=float)


class Knn(object):
    """Mean or largest distance to the k nearest training windows (training: the window itself left out)."""

    def __init__(self, how, k=5):
        self.how, self.k = how, k

    def fit(self, X):
        from sklearn.neighbors import NearestNeighbors
        self.tree = NearestNeighbors(n_neighbors=self.k).fit(X)
        return -self._agg(self.tree.kneighbors(X, self.k + 1)[0][:, 1:])

    def score(self, X):
        return -self._agg(self.tree.kneighbors(X, self.k)[0])

    def _agg(self, distances):
        return distances.mean(axis=1) if self.how == 'mean' else distances.max(axis=1)


class Sklearn(object):
    """An sklearn estimator: ``fit`` then its training scores by ``train`` and others by ``test`` (method names)."""

    def __init__(self, estimator, train, test):
        self.estimator, self.train, self.test = estimator, train, test

    def fit(self, X):
        self.estimator.fit(X)
        found = getattr(self.estimator, self.train)
        return found(X) if callable(found) else found

    def score(self, X):
        return getattr(self.estimator, self.test)(X)


class Mahalanobis(object):
    """Minus the squared Mahalanobis distance to the robust (minimum covariance determinant) centre."""

    def fit(self, X):
        from sklearn.covariance import MinCovDet
        self.mcd = MinCovDet(random_state=0).fit(X)
        return self.score(X)

    def score(self, X):
        return -self.mcd.mahalanobis(X)


class Tails(object):
    """ECOD (``copod=False``) or COPOD: per feature -log of its empirical left / right tail probability among the
    training windows (the scored window counted once), the skewness-chosen tail; ECOD takes the largest of the
    three per feature, COPOD the larger of the skew tail and the mean of both; summed over features, negated."""

    def __init__(self, copod):
        self.copod = copod

    def fit(self, X):
        from scipy.stats import skew
        self.sorted = np.sort(X, axis=0)
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            self.sign = np.nan_to_num(np.sign(skew(X, axis=0)))
        return self.score(X)

    def score(self, X):
        n = len(self.sorted)
        below = np.stack([np.searchsorted(self.sorted[:, j], X[:, j], side='right') for j in range(X.shape[1])], 1)
        above = n - np.stack([np.searchsorted(self.sorted[:, j], X[:, j], side='left') for j in range(X.shape[1])], 1)
        left, right = -np.log((below + 1.0) / (n + 1.0)), -np.log((above + 1.0) / (n + 1.0))
        skewed = np.where(self.sign < 0, left, np.where(self.sign > 0, right, left + right))
        if self.copod:
            per = np.maximum(skewed, 0.5 * (left + right))
        else:
            per = np.maximum(np.maximum(left, right), skewed)
        return -per.sum(axis=1)
