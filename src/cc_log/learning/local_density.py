"""The envelope's local-density part: a window unusual for its neighbourhood among the training windows.

The per-feature limits and the joint check see windows far from all of nominal driving; a window in a sparse gap
between two dense kinds of driving (inside every limit, near the robust centre) they cannot see. The local outlier
factor (Breunig et al. 2000; scikit-learn's ``LocalOutlierFactor(novelty=True)``) does: a window whose ``K``
nearest training windows lie much closer to their own neighbours than to it. ``LocalDensity`` holds what scoring
needs, learned on the training windows (``learn``; at most ``MAX_WINDOWS`` of them, evenly subsampled beyond):

- ``mean``, ``scale``: each feature standardised as scikit-learn's StandardScaler (population deviation; a feature
  constant up to rounding taken as 1), the deviation floored at ``RESOLUTION`` as the joint check's (a feature
  that spreads less is float rounding, not driving, and a live window's rounding must not look new);
- ``training``: the standardised training windows, ``distances`` their k-distance (to their K-th nearest other
  training window) and ``densities`` their local reachability density (1 / (the mean over their K nearest of
  max(distance, the neighbour's k-distance) + 1e-10));
- ``typical``, ``extreme``: the median and the lowest training score.

A window's score is minus its local outlier factor (the mean of its K neighbours' density over its own; lower is
more anomalous: 1 is typical, a training window's is its ``negative_outlier_factor_``), its *ratio*
``(typical - score) / (factor x (typical - extreme))`` (> 1: flagged), the envelope's direction everywhere
(docs/DESIGN.md: the trigger turns the ratio into its score as it does the joint ratio). Brute-force distances in
numpy (each batch chunked to at most ``CHUNK_BYTES``; the candidates picked by one matrix product, ``_nearest``).
Pure: numpy only (no scikit-learn, no pickle); the file block is read with bounds (``from_dict``: one-line
ValueErrors). In the file (``to_dict``) each array is ``ENCODING``: its float64 numbers, little-endian, in base64 (a
string of plain data, parsed in one call and bit for bit the same numbers); ``windows`` says the training windows.
The envelope file's version 3 held them as lists of numbers (``from_dict(..., compact=False)``).
"""
import base64
import binascii
import collections
import math

import numpy as np

from cc_log.base.safe_input import brief

K = 20                      # neighbours (the detector benchmark's ``lof``)
MAX_WINDOWS = 10000         # training windows kept at most (evenly subsampled beyond)
CHUNK_BYTES = 50 << 20      # the largest temporary a batch of distances allocates
DENSITY_EPSILON = 1e-10     # scikit-learn's: a density of duplicates stays finite
MAX_NEIGHBOURS = 1000       # the largest K a file may say
RESOLUTION = 1e-6           # the smallest scale of a feature (as the joint check's: below it is float rounding)
REACH_RESOLUTION = 1e-6     # the smallest reach distance (standardised): below it windows are alike up to rounding
_ARRAYS = ('mean', 'scale', 'training', 'distances', 'densities')
ENCODING = 'float64 little-endian, base64'   # the arrays of the file's block (``to_dict``)
_COMPACT_KEYS = ('k', 'encoding', 'windows') + _ARRAYS + ('typical', 'extreme')


class LocalDensity(collections.namedtuple('LocalDensity', 'k mean scale training distances densities typical '
                                                          'extreme')):
    """The local-density part of the training windows (see the module docstring): ``k`` neighbours; ``mean``,
    ``scale`` (per feature), ``training`` (n x features, standardised), ``distances``, ``densities`` (n) arrays;
    ``typical``, ``extreme``: the median and the lowest training score."""

    __slots__ = ()

    def standardised(self, matrix):
        """Each row of ``matrix`` standardised."""
        return (np.asarray(matrix, dtype=float) - self.mean) / self.scale

    def neighbours(self, matrix):
        """(distances, indices) of the ``k`` nearest training windows of each row (nearest first)."""
        return self._neighbours(np.atleast_2d(self.standardised(matrix)))

    def _neighbours(self, z):
        chunks = _chunks(len(z), len(self.training), z.shape[1])
        if len(chunks) == 1:
            return _nearest(z, self.training, self.k)
        distances = np.empty((len(z), self.k))
        indices = np.empty((len(z), self.k), dtype=int)
        for start, stop in chunks:
            near, found = _nearest(z[start:stop], self.training, self.k)
            distances[start:stop], indices[start:stop] = near, found
        return distances, indices

    def scores(self, matrix):
        """Minus the local outlier factor of each row of ``matrix`` (lower is more anomalous; ~ -1 typical)."""
        matrix = np.asarray(matrix, dtype=float)
        if matrix.ndim == 1:
            return self.scores(matrix[None])[0]
        distances, indices = self.neighbours(matrix)
        return _outlier_scores(self.densities[indices], _density(distances, self.distances[indices]))

    def training_scores(self):
        """The score of each training window among the others (scikit-learn's ``negative_outlier_factor_``)."""
        _, indices = _training_neighbours(self.training, self.k)
        return _outlier_scores(self.densities[indices], self.densities)

    def ratios(self, matrix, factor):
        """The local ratio of each row: ``(typical - score) / (factor x (typical - extreme))`` (> 1: flagged)."""
        return (self.typical - self.scores(matrix)) / (factor * (self.typical - self.extreme))

    def deviations(self, row, count=3):
        """Of one window: the ``count`` features (indices) farthest, standardised, from the mean of its ``k``
        nearest training windows, farthest first."""
        z = self.standardised(row)
        _, indices = self._neighbours(z[None])
        gap = np.abs(z - self.training[indices[0]].mean(axis=0))
        return [int(i) for i in np.argsort(-gap, kind='stable')[:count]]

    def to_dict(self):
        """The file's block: ``k``, ``encoding``, ``windows``, each array a string (``ENCODING``), ``typical``,
        ``extreme``."""
        return collections.OrderedDict(
            [('k', int(self.k)), ('encoding', ENCODING), ('windows', len(self.training))] +
            [(key, encode_array(getattr(self, key))) for key in _ARRAYS] +
            [('typical', float(self.typical)), ('extreme', float(self.extreme))])

    def summary(self):
        """What ``cclog learn-envelope --json`` shows of the part: ``k``, ``windows`` (training windows kept),
        ``typical``, ``extreme`` (its arrays stay in the file)."""
        return collections.OrderedDict([('k', int(self.k)), ('windows', len(self.training)),
                                        ('typical', float(self.typical)), ('extreme', float(self.extreme))])

    def __eq__(self, other):
        return isinstance(other, LocalDensity) and all(np.array_equal(a, b) for a, b in zip(self, other))

    def __ne__(self, other):
        return not self == other

    __hash__ = None


def shortfall(windows, k=K):
    """Why ``windows`` training windows cannot set the local part ('' when they are enough: more than ``k``)."""
    return '' if windows > k else '%d training windows, fewer than %d' % (windows, k + 1)


def subsample(matrix, most=MAX_WINDOWS):
    """At most ``most`` rows of ``matrix``, evenly spread over it (all of them when there are no more)."""
    if len(matrix) <= most:
        return matrix
    return matrix[np.round(np.linspace(0, len(matrix) - 1, most)).astype(int)]


def distinct(matrix):
    """The distinct rows of ``matrix`` (in their first order): a robot standing still makes many identical windows,
    and K copies of one window have an infinite density (scikit-learn's 1e10) that makes every window near them
    look new."""
    if not len(matrix) or not np.all(np.isfinite(matrix)):
        return matrix
    _, first = np.unique(matrix, axis=0, return_index=True)
    return matrix[np.sort(first)]


def learn(matrix, k=K):
    """The ``LocalDensity`` of the training windows ``matrix`` (n, features; ``subsample``d to MAX_WINDOWS), or
    None when ``shortfall`` says they are too few, a value is not finite, or every window scores alike."""
    matrix = subsample(distinct(np.asarray(matrix, dtype=float)))
    if shortfall(len(matrix), k) or not np.all(np.isfinite(matrix)):
        return None
    n = len(matrix)
    mean, variance = matrix.mean(axis=0), matrix.var(axis=0)
    eps = np.finfo(float).eps
    constant = variance <= n * eps * variance + (n * mean * eps) ** 2   # as StandardScaler's _is_constant_feature
    scale = np.where(constant, 1.0, np.maximum(np.sqrt(variance), RESOLUTION))
    training = (matrix - mean) / scale
    distances, indices = _training_neighbours(training, k)
    k_distances = distances[:, -1]
    densities = _density(distances, k_distances[indices])
    train = _outlier_scores(densities[indices], densities)
    typical, extreme = float(np.median(train)), float(np.min(train))
    if not (np.all(np.isfinite(train)) and extreme < typical):
        return None
    return LocalDensity(k, mean, scale, training, k_distances, densities, typical, extreme)


def _training_neighbours(training, k):
    """(distances, indices) of the ``k`` nearest other training windows of each training window."""
    n = len(training)
    distances = np.empty((n, k))
    indices = np.empty((n, k), dtype=int)
    for start, stop in _chunks(n, n, training.shape[1]):
        near, found = _nearest(training[start:stop], training, k, exclude=np.arange(start, stop))
        distances[start:stop], indices[start:stop] = near, found
    return distances, indices


def _outlier_scores(neighbour_densities, densities):
    """Minus the local outlier factor: the mean of each window's neighbours' densities over its own."""
    with np.errstate(over='ignore', invalid='ignore', divide='ignore'):
        return -np.mean(neighbour_densities / densities[:, None], axis=1)


def _density(distances, k_distances):
    """The local reachability density of windows at ``distances`` from their neighbours of ``k_distances``."""
    reach = np.maximum(np.maximum(distances, k_distances), REACH_RESOLUTION)
    return 1.0 / (np.mean(reach, axis=1) + DENSITY_EPSILON)


def _chunks(rows, training, features):
    """(start, stop) of row blocks whose distances to ``training`` windows take at most CHUNK_BYTES."""
    step = max(1, CHUNK_BYTES // (8 * max(1, training) * (features + 1)))
    return [(start, min(start + step, rows)) for start in range(0, rows, step)]


def _nearest(rows, training, k, exclude=None):
    """(distances, indices) of the ``k`` nearest ``training`` windows of each of ``rows``, nearest first (ties:
    the lower index); ``exclude``: per row, a training index left out (the window itself). The candidates are
    picked by a matrix product (|a|^2 + |b|^2 - 2 a.b) with a margin wider than its rounding can err, then the
    distances of the candidates computed from the differences as ``_nearest_brute`` does: the same neighbours and
    distances at a fraction of the memory traffic. The product is numpy's einsum, not BLAS: OpenBLAS's threads
    would spin on the other cores after each call, costing more CPU than the product."""
    k = min(k, training.shape[0] - (exclude is not None))
    transposed, training_norms, farthest = _prepared(training)
    row_norms = np.einsum('ij,ij->i', rows, rows)
    if k >= training.shape[0] or not len(rows) or not (farthest < _LARGEST and np.max(row_norms) < _LARGEST):
        return _nearest_brute(rows, training, k, exclude)   # values too large to square: every distance computed
    estimate = np.einsum('ik,kj->ij', rows, transposed)
    estimate *= -2.0
    estimate += training_norms
    estimate += row_norms[:, None]
    if exclude is not None:
        estimate[np.arange(len(rows)), exclude] = np.inf
    # |estimate - d^2| <= (f + 2) u (|a| + |b|)^2 (u = eps / 2, f features): ``error`` is 8 times that; the
    # distances computed from the differences err by (f + 3) u relative, the bound's factor 8 times that
    rounding = (rows.shape[1] + 3) * _EPS
    error = 4 * rounding * (np.sqrt(row_norms) + np.sqrt(farthest)) ** 2
    bound = (np.partition(estimate, k - 1, axis=1)[:, k - 1] + error) * (1 + 4 * rounding) + error
    which, candidate = np.nonzero(estimate <= bound[:, None])
    difference = rows[which] - training[candidate]
    squared = np.einsum('ij,ij->i', difference, difference)
    order = np.lexsort((candidate, squared, which))    # by row, then distance, then index
    counts = np.bincount(which, minlength=len(rows))
    chosen = order[(np.cumsum(counts) - counts)[:, None] + np.arange(k)[None, :]]
    return np.sqrt(squared[chosen]), candidate[chosen]


_EPS = float(np.finfo(float).eps)
_LARGEST = 1e150        # a squared norm below it: no product or sum of ``_nearest`` overflows
_PREPARED = collections.OrderedDict()   # id(training) -> (training, ``_prepared``'s), the last few searched
_PREPARED_KEPT = 4


def _prepared(training):
    """What ``_nearest`` needs of the ``training`` windows each time: (their transpose, contiguous; each one's
    squared norm; the largest), kept for the last ``_PREPARED_KEPT`` arrays searched (the trigger's, one batch
    after another)."""
    entry = _PREPARED.get(id(training))
    if entry is None or entry[0] is not training:
        norms = np.einsum('ij,ij->i', training, training)
        entry = (training, np.ascontiguousarray(training.T), norms, float(np.max(norms)) if len(norms) else 0.0)
        _PREPARED[id(training)] = entry
        while len(_PREPARED) > _PREPARED_KEPT:
            try:
                _PREPARED.popitem(last=False)
            except KeyError:    # emptied by another thread meanwhile
                break
    return entry[1:]


def _nearest_brute(rows, training, k, exclude=None):
    """``_nearest`` by every distance: the differences of each row with every training window, every distance
    sorted (ties: the lower index)."""
    squared = np.einsum('ijk,ijk->ij', *(rows[:, None, :] - training[None, :, :],) * 2)
    if exclude is not None:
        squared[np.arange(len(rows)), exclude] = np.inf
    k = min(k, training.shape[0] - (exclude is not None))
    found = np.argsort(squared, axis=1, kind='stable')[:, :k]
    return np.sqrt(np.take_along_axis(squared, found, axis=1)), found


def from_dict(block, where, features, compact=True):
    """The ``LocalDensity`` of a file's ``local`` block (None: none); ValueError('<where>: ...') unless ``k`` is a
    count from 1 below the windows (at most MAX_WINDOWS), every array has its shape (``features`` columns) and
    finite numbers (``scale`` and ``densities`` positive, ``distances`` non-negative) and ``extreme`` <
    ``typical``. ``compact``: the arrays are ``ENCODING`` strings and ``windows`` says how many training windows
    (``to_dict``); else lists of numbers (the envelope file's version 3)."""
    if block is None:
        return None
    keys = _COMPACT_KEYS if compact else LocalDensity._fields
    if not isinstance(block, dict) or set(block) != set(keys):
        extra = sorted(set(block) - set(keys), key=str) if isinstance(block, dict) else ()
        raise ValueError('%s: must map %s%s%s' % (where, ', '.join(keys), '' if compact else ' to numbers',
                                                  ' (unknown key %s)' % brief(extra[0]) if extra else ''))
    k = block['k']
    if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= MAX_NEIGHBOURS:
        raise ValueError('%s: k: %s must be a count of neighbours from 1 to %d' % (where, brief(k), MAX_NEIGHBOURS))
    if compact:
        if block['encoding'] != ENCODING:
            raise ValueError('%s: encoding: %s, this cc_log reads %r' % (where, brief(block['encoding']), ENCODING))
        rows = block['windows']
        rows = rows if isinstance(rows, int) and not isinstance(rows, bool) else -1
        said = 'windows: must be a count'
    else:
        rows = len(block['training']) if isinstance(block['training'], list) else -1
        said = 'training: must be a list'
    if not k < rows <= MAX_WINDOWS:
        raise ValueError('%s: %s of more than k=%d and at most %d windows' % (where, said, k, MAX_WINDOWS))
    shapes = {'mean': (features,), 'scale': (features,), 'training': (rows, features), 'distances': (rows,),
              'densities': (rows,)}
    read = decode_array if compact else finite_array
    arrays = {key: read(block[key], shapes[key], '%s: %s' % (where, key)) for key in _ARRAYS}
    for key, test, said in (('scale', np.greater, 'positive'), ('densities', np.greater, 'positive'),
                            ('distances', np.greater_equal, 'non-negative')):
        if not np.all(test(arrays[key], 0)):
            raise ValueError('%s: %s: every entry must be %s' % (where, key, said))
    typical, extreme = (_finite(block[key], '%s: %s' % (where, key)) for key in ('typical', 'extreme'))
    if not extreme < typical:
        raise ValueError('%s: extreme %r must be below typical %r' % (where, extreme, typical))
    return LocalDensity(k, *[arrays[key] for key in _ARRAYS], typical, extreme)


def encode_array(array):
    """``array``'s numbers as ``ENCODING``: float64, little-endian, in base64 (ASCII)."""
    return base64.b64encode(np.ascontiguousarray(array, dtype='<f8').tobytes()).decode('ascii')


def decode_array(text, shape, where):
    """The float array of ``shape`` that ``encode_array`` wrote as ``text``, every entry a finite number;
    ValueError naming ``where`` otherwise (the length checked before anything is decoded)."""
    count = int(np.prod(shape))
    size = 4 * -(-8 * count // 3)     # base64 of 8 x count bytes, padded
    if not isinstance(text, str) or len(text) != size:
        raise ValueError('%s: must be %s numbers, %s in %d characters' % (
            where, ' x '.join(str(n) for n in shape), ENCODING, size))
    try:
        data = base64.b64decode(text.encode('ascii'), validate=True)
    except (UnicodeEncodeError, binascii.Error, ValueError):
        raise ValueError('%s: not %s' % (where, ENCODING))
    if len(data) != 8 * count:
        raise ValueError('%s: not %s' % (where, ENCODING))
    array = np.frombuffer(data, dtype='<f8').astype(float).reshape(shape)
    if not np.all(np.isfinite(array)):
        raise ValueError('%s: entry %d is not a finite number' % (where, int(np.flatnonzero(~np.isfinite(array))[0])))
    return array


def finite_array(value, shape, where):
    """``value`` (nested lists) as a float array of ``shape``, every entry a finite number (checked before any
    conversion); ValueError naming ``where`` otherwise."""
    def check(item, depth):
        if not isinstance(item, list) or len(item) != shape[depth]:
            raise ValueError('%s: must be %s numbers' % (where, ' x '.join(str(n) for n in shape)))
        if depth + 1 < len(shape):
            for entry in item:
                check(entry, depth + 1)
            return
        for entry in item:
            if isinstance(entry, bool) or not isinstance(entry, (int, float)) or not math.isfinite(entry):
                raise ValueError('%s: %s is not a finite number' % (where, brief(entry)))
    check(value, 0)
    return np.array(value, dtype=float)


def _finite(value, where):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError('%s: %s must be a finite number' % (where, brief(value)))
    return float(value)
