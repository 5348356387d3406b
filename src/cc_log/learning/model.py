"""The anomaly model: a one-class SVM as plain arrays, scored with numpy, stored as data-only JSON.

Two kernel models, both trained by ``learning.train`` with scikit-learn and kept here as arrays only:

- ``ocsvm``: scikit-learn's ``OneClassSVM`` with an RBF kernel:
  ``score(x) = sum_i dual_coef[i] * exp(-gamma * |sv_i - z|^2) + intercept`` where ``z`` is ``x``
  standardised with the scaler's mean and scale; equal to ``OneClassSVM.decision_function`` wherever the kernel
  sum is at least ``FLOOR_FRACTION`` of ``-intercept``. Below that the RBF sum has all but reached its floor
  (far from every support vector it underflows to 0, so the plain score of every far vector is the same
  ``intercept``); there the score goes on as ``intercept + r * (1 + ln(sum / r))``, r = FLOOR_FRACTION *
  -intercept, the sum's log computed without underflow: the same value and slope at the joint, and a vector
  further from the support vectors still scores lower, so a threshold can be set among far vectors too.
- ``nystroem-sgd``: the scalable formulation of scikit-learn 1.2: ``Nystroem`` (RBF) then
  ``SGDOneClassSVM``: ``score(x) = coef . (exp(-gamma * |c_j - z|^2)_j @ normalization.T) - offset``.

Scores follow scikit-learn's ``decision_function``: lower is more anomalous; a vector is anomalous when
``score < threshold``. The file is JSON ``{"format": "cc_log-model", "version": 1, ...}``: loading never
executes code (no pickle, no joblib), and anything but a well-formed model raises
``ModelError('<path>: <what is wrong>')``. The optional ``"coverage"`` (``learning.coverage``: the range of
speed, yaw rate and time stopped, or of every feature, its nominal training vectors cover) is absent from
older files, as is the optional ``"ranges"`` (``{"min": [...], "max": [...]}``: each feature's smallest and largest
value over the nominal training vectors, which ``base.why`` compares a window with).
"""
import json
import math

import numpy as np

from cc_log.base import safe_input
from cc_log.base.safe_input import brief
from cc_log.features import WINDOW_RANGES, FeatureConfig, vector_length
from cc_log.base.errors import ModelError

FORMAT = 'cc_log-model'
VERSION = 1
KINDS = ('ocsvm', 'nystroem-sgd')
#: Largest model file read: an ``ocsvm`` model of 20,000 support vectors of 200 features is ~80 MB of JSON.
MAX_MODEL_BYTES = 1 << 30
SCORE_BLOCK = 32  # vectors scored at a time by score_each (bounds its block of distances to the centres)
FLOOR_FRACTION = 1e-3  # ocsvm: below this share of -intercept the kernel sum is continued by its log
#: Plausible ranges of a model (anything outside is refused, naming the key): the feature window in
#: messages (held as rows) or seconds, the RBF kernel's gamma (of standardised features: ~1e-3 to 10).
MAX_WINDOW_COUNT = WINDOW_RANGES[0].high
MAX_WINDOW_SECONDS = WINDOW_RANGES[1].high
MAX_GAMMA = 1e6


class AnomalyModel(object):
    """A trained anomaly model: feature config, scaler, kernel model arrays and decision threshold.

    ``kernel`` holds the arrays of ``kind``: for ``ocsvm`` ``support_vectors`` (n, d), ``dual_coef`` (n,),
    ``intercept``, ``gamma``; for ``nystroem-sgd`` ``components`` (m, d), ``normalization`` (m, m),
    ``coef`` (m,), ``offset``, ``gamma``. ``info`` is a free dict of JSON values (training figures);
    ``coverage`` None or ``learning.coverage``'s dict; ``ranges`` None or ``{"min": array, "max": array}`` of the
    training vectors (``base.why``).
    """

    def __init__(self, config, mean, scale, kind, kernel, threshold, names=None, info=None, source='<model>',
                 coverage=None, ranges=None):
        if not isinstance(config, FeatureConfig):
            raise ModelError('%s: config: expected a FeatureConfig, got %s' % (source, type(config).__name__))
        self.config = config
        self.mean = np.asarray(mean, dtype=float)
        self.scale = np.asarray(scale, dtype=float)
        self.kind = kind
        self.kernel = {key: (np.asarray(value, dtype=float) if not np.isscalar(value) else float(value))
                       for key, value in kernel.items()}
        self.threshold = float(threshold)
        self.names = list(names) if names is not None else None
        try:  # plain JSON values only (numpy scalars become Python numbers)
            self.info = json.loads(json.dumps(dict(info or {}), allow_nan=False, default=_plain))
        except (TypeError, ValueError) as error:
            raise ModelError('%s: info must hold finite JSON values only (%s)' % (source, error))
        self.coverage = check_coverage(coverage, source)
        self.ranges = None if ranges is None else {key: np.asarray(ranges[key], dtype=float) for key in ('min', 'max')}
        _validate(self, source)
        self._prepare()

    def _prepare(self):
        self._inv_scale = 1.0 / self.scale
        self._gamma = self.kernel['gamma']
        self._joint = None   # the kernel sum below which the score is continued by its log (ocsvm)
        if self.kind == 'ocsvm':
            self._centres = self.kernel['support_vectors']
            self._weights = self.kernel['dual_coef']
            self._bias = self.kernel['intercept']
            if self._bias < 0.0 and len(self._weights) and np.all(self._weights > 0.0):
                self._joint = -FLOOR_FRACTION * self._bias
                self._log_weights = np.log(self._weights)
        else:
            self._centres = self.kernel['components']
            # coef . (k @ N.T) == (N.T @ coef) . k: fold the normalization into one weight vector
            self._weights = self.kernel['normalization'].T.dot(self.kernel['coef'])
            self._bias = -self.kernel['offset']

    @property
    def dimension(self):
        """Length of the feature vectors the model scores."""
        return self.mean.shape[0]

    def score(self, vector):
        """Decision score of one feature vector (lower is more anomalous), computed with numpy."""
        return self.score_each([vector])[0]

    def score_each(self, vectors):
        """``[score(v) for v in vectors]`` (a list of 1-D vectors), computed SCORE_BLOCK at a time with the
        same arithmetic for each, so a batch scores as one vector does (bit for bit where the BLAS kernel rounds a
        dot product alike wherever its row lies in memory; OpenBLAS's Prescott kernel differs in the last bits)."""
        X = np.asarray(vectors, dtype=float)
        if X.ndim != 2 or X.shape[1:] != self.mean.shape:
            shape = X.shape[1:] if X.ndim == 2 else X.shape
            raise ModelError('vector: expected %d values, got shape %s' % (self.dimension, shape))
        out = []
        for start in range(0, len(X), SCORE_BLOCK):
            Z = (X[start:start + SCORE_BLOCK] - self.mean) * self._inv_scale
            diff = self._centres[None, :, :] - Z[:, None, :]
            d2 = np.einsum('kij,kij->ki', diff, diff)
            sums = np.array([self._weights.dot(row) for row in np.exp(-self._gamma * d2)])
            out.extend(float(value) for value in self._continued(sums, d2))
        return out

    def scores(self, vectors):
        """Scores of the rows of a 2-D array."""
        X = np.asarray(vectors, dtype=float)
        if X.ndim != 2 or X.shape[1] != self.dimension:
            raise ModelError('vectors: expected shape (n, %d), got %s' % (self.dimension, X.shape))
        Z = (X - self.mean) * self._inv_scale
        out = np.empty(len(Z))
        for start in range(0, len(Z), 512):
            block = Z[start:start + 512]
            d2 = (np.einsum('ij,ij->i', block, block)[:, None] - 2.0 * block.dot(self._centres.T)
                  + np.einsum('ij,ij->i', self._centres, self._centres)[None, :])
            np.maximum(d2, 0.0, out=d2)
            out[start:start + 512] = self._continued(np.exp(-self._gamma * d2).dot(self._weights), d2)
        return out

    def _continued(self, sums, d2):
        """Scores of rows whose kernel sums are ``sums`` (of their squared distances ``d2`` to the centres):
        ``sum + intercept``, and below the joint (ocsvm) ``intercept + joint * (1 + ln(sum / joint))``."""
        out = sums + self._bias
        if self._joint is None:
            return out
        low = sums < self._joint
        if np.any(low):
            terms = self._log_weights[None, :] - self._gamma * d2[low]
            top = terms.max(axis=1)
            log_sum = top + np.log(np.exp(terms - top[:, None]).sum(axis=1))
            out[low] = self._bias + self._joint * (1.0 + log_sum - math.log(self._joint))
        return out

    def is_anomalous(self, vector):
        """``(score < threshold, score)``."""
        value = self.score(vector)
        return value < self.threshold, value

    def check_config(self, config):
        """Raise ModelError when ``config`` (FeatureConfig or dict) differs from the model's."""
        if isinstance(config, dict):
            config = FeatureConfig.from_dict(config)
        if config != self.config:
            different = ['%s %r (model: %r)' % (field, getattr(config, field), getattr(self.config, field))
                         for field in FeatureConfig._fields if getattr(config, field) != getattr(self.config, field)]
            raise ModelError('config: the model was trained for other features: %s' % '; '.join(different))

    # -- file -----------------------------------------------------------------------------------------

    def to_dict(self):
        """The JSON document of the model."""
        document = {
            'format': FORMAT,
            'version': VERSION,
            'config': self.config.to_dict(),
            'kind': self.kind,
            'scaler': {'mean': self.mean.tolist(), 'scale': self.scale.tolist()},
            'kernel': {key: (value.tolist() if isinstance(value, np.ndarray) else value)
                       for key, value in sorted(self.kernel.items())},
            'threshold': self.threshold,
            'names': self.names,
            'info': self.info,
        }
        if self.coverage is not None:
            document['coverage'] = self.coverage
        if self.ranges is not None:
            document['ranges'] = {key: value.tolist() for key, value in self.ranges.items()}
        return document

    def save(self, path):
        """Write the model atomically (``<path>.tmp-<pid>``, fsync, rename over ``path``: a link there is
        replaced, never written through; see ``safe_files``); return ``path``."""
        from cc_log.base import safe_files
        text = json.dumps(self.to_dict(), allow_nan=False, separators=(',', ':'), default=_plain)
        with safe_files.AtomicFile(path, overwrite=True, text=True) as stream:
            stream.write(text)
        return path

    @classmethod
    def load(cls, path):
        """Read a model file; raise ModelError('<path>: <what is wrong>') for anything but a valid model."""
        try:
            with safe_input.open_input(path) as stream:
                data = stream.read(MAX_MODEL_BYTES + 1)
        except (IOError, OSError) as error:
            raise ModelError('%s: cannot read: %s' % (path, error.strerror or error))
        except ValueError as error:  # a FIFO, a device: never read (a FIFO would block)
            raise ModelError(str(error))
        if len(data) > MAX_MODEL_BYTES:
            raise ModelError('%s: not a cc_log model (larger than %d bytes)' % (path, MAX_MODEL_BYTES))
        if data[:1] == b'\x80':
            raise ModelError('%s: not a cc_log model (a pickle/joblib payload? models are JSON, never pickles)'
                             % path)
        try:
            text = data.decode('utf-8')
        except UnicodeDecodeError:
            raise ModelError('%s: not a cc_log model (not UTF-8 JSON text)' % path)

        def refuse_constant(name):
            raise ValueError('%s is not allowed' % name)

        try:
            document = safe_input.json_loads(text, parse_constant=refuse_constant, parse_int=safe_input.bounded_int)
        except ValueError as error:
            raise ModelError('%s: not a cc_log model (invalid JSON: %s)' % (path, error))
        return cls.from_dict(document, path)

    @classmethod
    def from_dict(cls, document, path='<model>'):
        """Build from ``to_dict()`` output, validating everything; raise ModelError naming ``path``."""
        if not isinstance(document, dict) or document.get('format') != FORMAT:
            raise ModelError('%s: not a cc_log model (no "format": "%s")' % (path, FORMAT))
        if document.get('version') != VERSION or isinstance(document.get('version'), bool):
            raise ModelError('%s: model version %s is not supported (this cc_log reads version %d)'
                             % (path, brief(document.get('version')), VERSION))
        for key in ('config', 'kind', 'scaler', 'kernel', 'threshold'):
            if key not in document:
                raise ModelError('%s: missing "%s"' % (path, key))
        try:
            config = FeatureConfig.from_dict(document['config'])
        except ValueError as error:
            raise ModelError('%s: %s' % (path, error))
        kind = document['kind']
        if kind not in KINDS:
            raise ModelError('%s: kind %s is not one of %s' % (path, brief(kind), ', '.join(KINDS)))
        scaler = document['scaler']
        if not isinstance(scaler, dict):
            raise ModelError('%s: scaler must be an object' % path)
        mean = _array(scaler.get('mean'), 1, path, 'scaler.mean')
        scale = _array(scaler.get('scale'), 1, path, 'scaler.scale')
        kernel_doc = document['kernel']
        if not isinstance(kernel_doc, dict):
            raise ModelError('%s: kernel must be an object' % path)
        shapes = _KERNEL_FIELDS[kind]
        unknown = sorted(set(kernel_doc) - set(shapes))
        if unknown:
            raise ModelError('%s: kernel: unknown field(s) %s for kind %s' % (path, ', '.join(unknown), kind))
        kernel = {}
        for key, ndim in shapes.items():
            if key not in kernel_doc:
                raise ModelError('%s: kernel: missing "%s"' % (path, key))
            if ndim == 0:
                kernel[key] = _number(kernel_doc[key], path, 'kernel.' + key)
            else:
                kernel[key] = _array(kernel_doc[key], ndim, path, 'kernel.' + key)
        threshold = _number(document['threshold'], path, 'threshold')
        names = document.get('names')
        if names is not None and (not isinstance(names, list) or not all(isinstance(n, str) for n in names)):
            raise ModelError('%s: names must be a list of strings' % path)
        info = document.get('info') or {}
        if not isinstance(info, dict):
            raise ModelError('%s: info must be an object' % path)
        ranges = document.get('ranges')
        if ranges is not None:
            if not isinstance(ranges, dict):
                raise ModelError('%s: ranges must be an object {"min": [...], "max": [...]}' % path)
            ranges = {key: _array(ranges.get(key), 1, path, 'ranges.' + key) for key in ('min', 'max')}
        return cls(config, mean, scale, kind, kernel, threshold, names, info, source=path,
                   coverage=document.get('coverage'), ranges=ranges)


def check_coverage(coverage, path='<model>'):
    """``coverage`` (None, or ``{"quantities": [{"name", "unit", "min", "max", ...}], "stopped_share"?, ...}``)
    as plain JSON values; ModelError naming ``path`` and the key when it is anything else."""
    if coverage is None:
        return None
    try:
        coverage = json.loads(json.dumps(coverage, allow_nan=False, default=_plain))
    except (TypeError, ValueError) as error:
        raise ModelError('%s: coverage must hold finite JSON values only (%s)' % (path, error))
    quantities = coverage.get('quantities') if isinstance(coverage, dict) else None
    if not isinstance(quantities, list) or not quantities:
        raise ModelError('%s: coverage: "quantities" must be a non-empty list' % path)
    for index, entry in enumerate(quantities):
        where = 'coverage.quantities[%d]' % index
        if not isinstance(entry, dict) or not isinstance(entry.get('name'), str) \
                or not isinstance(entry.get('unit', ''), str):
            raise ModelError('%s: %s must be an object with a "name" and a "unit"' % (path, where))
        low = _number(entry.get('min'), path, where + '.min')
        if _number(entry.get('max'), path, where + '.max') < low:
            raise ModelError('%s: %s: max is below min' % (path, where))
    share = coverage.get('stopped_share')
    if share is not None and not 0.0 <= _number(share, path, 'coverage.stopped_share') <= 1.0:
        raise ModelError('%s: coverage.stopped_share must be between 0 and 1' % path)
    return coverage


def _plain(value):
    """JSON fallback for numpy values in ``info``."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError('%r is not JSON data' % (value,))


_KERNEL_FIELDS = {
    'ocsvm': {'support_vectors': 2, 'dual_coef': 1, 'intercept': 0, 'gamma': 0},
    'nystroem-sgd': {'components': 2, 'normalization': 2, 'coef': 1, 'offset': 0, 'gamma': 0},
}


def _number(value, path, name):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ModelError('%s: %s must be a finite number, got %s' % (path, name, brief(value)))
    return float(value)


def _array(value, ndim, path, name):
    """A finite float array of ``ndim`` dimensions from nested JSON lists."""
    def bad(what):
        return ModelError('%s: %s %s' % (path, name, what))

    if not isinstance(value, list) or not value:
        raise bad('must be a non-empty list')
    if ndim == 1:
        rows = [value]
    else:
        if not all(isinstance(row, list) for row in value):
            raise bad('must be a list of lists')
        rows = value
        if len(set(len(row) for row in rows)) != 1 or not rows[0]:
            raise bad('rows must all have the same non-zero length')
    for row in rows:
        for item in row:
            if isinstance(item, bool) or not isinstance(item, (int, float)):
                raise bad('must hold numbers only, found %s' % brief(item))
    array = np.array(value, dtype=float)
    if not np.all(np.isfinite(array)):
        raise bad('holds non-finite values')
    return array


def check_window(config):
    """Raise ValueError('window: ...') unless the feature window of ``config`` (a FeatureConfig) is at most
    MAX_WINDOW_COUNT messages or MAX_WINDOW_SECONDS seconds."""
    span = config.span
    if span.is_duration and span.seconds > MAX_WINDOW_SECONDS:
        raise ValueError('window: %s is longer than %gs' % (span, MAX_WINDOW_SECONDS))
    if not span.is_duration and span.count > MAX_WINDOW_COUNT:
        raise ValueError('window: %s is more than %d messages' % (span, MAX_WINDOW_COUNT))


def _validate(model, path):
    """Check shapes and values of a model; raise ModelError naming ``path``."""
    def bad(what):
        return ModelError('%s: %s' % (path, what))

    if model.kind not in KINDS:
        raise bad('kind %s is not one of %s' % (brief(model.kind), ', '.join(KINDS)))
    try:
        check_window(model.config)
    except ValueError as error:
        raise bad('config: %s' % error)
    dimension = vector_length(model.config)
    for name, array in (('scaler.mean', model.mean), ('scaler.scale', model.scale)):
        if array.shape != (dimension,):
            raise bad('%s has shape %s; the features %s/%s need (%d,)'
                      % (name, array.shape, model.config.feature_set, model.config.window, dimension))
        if not np.all(np.isfinite(array)):
            raise bad('%s holds non-finite values' % name)
    with np.errstate(divide='ignore', over='ignore'):
        if not np.all(model.scale > 0) or not np.all(np.isfinite(1.0 / model.scale)):
            raise bad('scaler.scale must be positive, with a finite inverse')
    if not math.isfinite(model.threshold):
        raise bad('threshold must be finite')
    expected = _KERNEL_FIELDS[model.kind]
    if set(model.kernel) != set(expected):
        raise bad('kernel fields %s, expected %s' % (sorted(model.kernel), sorted(expected)))
    for key, ndim in expected.items():
        value = model.kernel[key]
        if ndim == 0:
            if not isinstance(value, float) or not math.isfinite(value):
                raise bad('kernel.%s must be a finite number' % key)
        elif not isinstance(value, np.ndarray) or value.ndim != ndim or not np.all(np.isfinite(value)):
            raise bad('kernel.%s must be a finite %d-D array' % (key, ndim))
    if not 0 < model.kernel['gamma'] <= MAX_GAMMA:
        raise bad('kernel.gamma: %g is not in (0, %g]' % (model.kernel['gamma'], MAX_GAMMA))
    if model.kind == 'ocsvm':
        sv, coef = model.kernel['support_vectors'], model.kernel['dual_coef']
        if sv.shape[1] != dimension:
            raise bad('kernel.support_vectors has %d columns, the features need %d' % (sv.shape[1], dimension))
        if coef.shape != (sv.shape[0],):
            raise bad('kernel.dual_coef has shape %s, expected (%d,)' % (coef.shape, sv.shape[0]))
    else:
        comp, norm, coef = model.kernel['components'], model.kernel['normalization'], model.kernel['coef']
        m = comp.shape[0]
        if comp.shape[1] != dimension:
            raise bad('kernel.components has %d columns, the features need %d' % (comp.shape[1], dimension))
        if norm.shape != (m, m):
            raise bad('kernel.normalization has shape %s, expected (%d, %d)' % (norm.shape, m, m))
        if coef.shape != (m,):
            raise bad('kernel.coef has shape %s, expected (%d,)' % (coef.shape, m))
    if model.names is not None and len(model.names) != dimension:
        raise bad('names has %d entries, expected %d' % (len(model.names), dimension))
    if model.ranges is not None:
        low, high = model.ranges['min'], model.ranges['max']
        if low.shape != (dimension,) or high.shape != (dimension,):
            raise bad('ranges: min and max need %d values each' % dimension)
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(low <= high)):
            raise bad('ranges: min and max must be finite, min at most max')
