"""Learning: feature-vector files, training the one-class SVM, evaluating it.

Vector files (written by collect mode, read by ``cclog learn``): one vector per file,
``<directory>/<label>/<stamp>.json`` holding ``{"stamp", "features": [...], "names"?, "config": {...}}``.

``train`` fits scikit-learn's ``OneClassSVM`` (RBF kernel) on standardised vectors and returns an
``AnomalyModel`` holding only arrays. It works with nominal data alone: the nominal vectors (in time order)
are cut into contiguous blocks, some blocks are held out, the model is fitted on the rest, and the
threshold is set below nearly all held-out scores with a margin. Contiguous blocks matter: neighbouring
sliding-window vectors share most of their rows, so a random hold-out would score like the training data
and give a threshold that is far too tight. With anomalous examples, ``nu``, ``gamma`` and the threshold are
chosen so that every anomalous vector is flagged (recall 100%) with the fewest held-out nominal ones.

A day of "nominal" driving may hold anomalies. Before all that, ``train`` scores every nominal vector with a
model fitted on the other blocks of the day (TRIM_FOLDS contiguous blocks), drops at most the ``trim`` share
(``cclog learn``: DEFAULT_TRIM, 1 %; ``train`` alone: 0, none) that scores lowest (the most outlying), of
those beyond Tukey's far-out fence (TRIM_FENCE interquartile ranges below the lower quartile), and goes on with
the rest;
``info['trimmed']`` counts them and ``info['trimmed_spans']`` says where they were (stamps when given). The
model records the range its kept vectors cover (``coverage``, read by ``drift.DriftMonitor``).

scikit-learn is imported inside ``train`` only: scoring never needs it.
"""
import collections
import json
import math
import os
import resource
import time

import numpy as np

from cc_log.base import safe_files, safe_input
from cc_log.features import FeatureConfig, vector_length, vector_names
from cc_log.learning.model import AnomalyModel

DEFAULT_NU = 0.02
DEFAULT_GAMMA_FACTOR = 0.5      # gamma = factor / n_features on standardised vectors
DEFAULT_HOLDOUT = 0.2
DEFAULT_BLOCKS = 10
DEFAULT_QUANTILE = 0.002        # the threshold sits below this quantile of held-out nominal scores ...
DEFAULT_MARGIN = 0.5            # ... by this fraction of (median - quantile) of those scores
DEFAULT_MAX_EXACT = 20000       # above this many training vectors: 'auto' subsamples evenly in time
NYSTROEM_COMPONENTS = 300
NU_GRID = (0.005, 0.02, 0.05, 0.1)
GAMMA_FACTOR_GRID = (0.1, 0.25, 0.5, 1.0, 2.0)
DEFAULT_TRIM = 0.01            # cclog learn's share of the most outlying nominal vectors dropped (train: 0)
MAX_TRIM = 0.5
TRIM_FENCE = 3.0               # ... and only those more than this many interquartile ranges below the lower quartile
TRIM_FOLDS = 4                 # contiguous blocks, each scored by a fit on the others, to find what to trim
MAX_TRIMMED_SPANS = 20         # spans of trimmed vectors listed in info (the rest counted)
STOPPED_SPEED = 0.05           # m/s: a window whose largest |v| is below this counts as stopped (coverage)
COVERAGE_QUANTILES = (0.01, 0.99)
MIN_VECTORS = 10               # fewer nominal vectors cannot be split into training and held-out blocks
MIN_SCALE = 1e-5               # feature units (m/s, m/s^2, rad/s ...): a smaller spread is rounding, not driving
METHODS = ('auto', 'exact', 'nystroem')

Report = collections.namedtuple('Report', 'total tp fp fn tn precision recall')
Report.__doc__ = 'Counts with positive = anomalous; precision and recall are fractions (nan when undefined).'


# -- vector files -------------------------------------------------------------------------------------

def _label_ok(label):
    return (isinstance(label, str) and label not in ('', '.', '..') and '/' not in label
            and os.sep not in label and '\0' not in label)


def write_vector(directory, label, stamp, vector, config, names=None):
    """Write one feature vector to ``<directory>/<label>/<stamp>.json`` atomically; return the path."""
    if not _label_ok(label):
        raise ValueError('label: %r is not a valid directory name' % (label,))
    stamp = float(stamp)
    if not math.isfinite(stamp):
        raise ValueError('stamp: %r is not finite' % stamp)
    values = np.asarray(vector, dtype=float)
    if values.ndim != 1 or not np.all(np.isfinite(values)):
        raise ValueError('vector: must be a 1-D array of finite numbers')
    document = {'stamp': stamp, 'features': values.tolist(), 'config': config.to_dict()}
    if names is not None:
        if len(names) != len(values):
            raise ValueError('names: %d names for %d features' % (len(names), len(values)))
        document['names'] = list(names)
    folder = safe_files.make_dirs(safe_files.inside(directory, label, 'label', directory=True))
    path = safe_files.inside(folder, '%.6f.json' % stamp, 'stamp')
    with safe_files.AtomicFile(path, overwrite=True, text=True) as stream:
        json.dump(document, stream, allow_nan=False, separators=(',', ':'))
    return path


def load_vectors(directory, with_stamps=False):
    """Read every vector file under ``directory``.

    Returns ``(vectors, config)``: ``vectors`` maps label -> 2-D array (rows in stamp order) and config is
    the FeatureConfig all files share. With ``with_stamps``: ``(vectors, config, stamps)`` with stamps a
    dict label -> 1-D array. Raises ValueError naming the path for a missing or empty directory, an
    unreadable file, or files of different configs or lengths.
    """
    if not os.path.isdir(directory):
        raise ValueError('%s: no such directory of feature vectors' % directory)
    found = {}
    config = None
    config_path = None
    length = None
    for label in sorted(os.listdir(directory)):
        folder = os.path.join(directory, label)
        if not os.path.isdir(folder):
            continue
        entries = []
        for name in os.listdir(folder):
            if not name.endswith('.json') or '.tmp-' in name:
                continue
            path = os.path.join(folder, name)
            try:
                with safe_input.open_input(path) as stream:
                    document = safe_input.json_loads(stream.read(), parse_constant=_refuse)
            except (IOError, OSError, ValueError) as error:
                raise ValueError('%s: not a feature vector file (%s)' % (path, error))
            if not isinstance(document, dict) or 'features' not in document or 'config' not in document:
                raise ValueError('%s: not a feature vector file (needs "features" and "config")' % path)
            try:
                file_config = FeatureConfig.from_dict(document['config'])
            except ValueError as error:
                raise ValueError('%s: %s' % (path, error))
            if config is None:
                config, config_path = file_config, path
            elif file_config != config:
                raise ValueError('%s: config %s differs from %s in %s'
                                 % (path, file_config.to_dict(), config.to_dict(), config_path))
            features = document['features']
            if not isinstance(features, list) or not all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) for x in features):
                raise ValueError('%s: features must be a list of numbers' % path)
            values = np.array(features, dtype=float)
            if not np.all(np.isfinite(values)):
                raise ValueError('%s: features hold non-finite values' % path)
            if length is None:
                length = len(values)
            elif len(values) != length:
                raise ValueError('%s: %d features, other files have %d' % (path, len(values), length))
            stamp = document.get('stamp')
            if isinstance(stamp, bool) or not isinstance(stamp, (int, float)):
                raise ValueError('%s: stamp must be a number' % path)
            entries.append((float(stamp), values))
        if entries:
            entries.sort(key=lambda entry: entry[0])
            found[label] = (np.array([stamp for stamp, _ in entries]), np.array([v for _, v in entries]))
    if not found:
        raise ValueError('%s: no feature vector files (<label>/<stamp>.json) found' % directory)
    if length != vector_length(config):
        raise ValueError('%s: vectors have %d features, the config %s needs %d'
                         % (config_path, length, config.to_dict(), vector_length(config)))
    vectors = {label: pair[1] for label, pair in found.items()}
    if with_stamps:
        return vectors, config, {label: pair[0] for label, pair in found.items()}
    return vectors, config


def _refuse(name):
    raise ValueError('%s is not allowed' % name)


# -- training -----------------------------------------------------------------------------------------

def peak_rss_mb():
    """Peak resident memory of this process (MB): VmHWM (ru_maxrss of a spawned process may include its parent's:
    Linux carries the high-water mark across exec)."""
    try:
        with open('/proc/self/status') as stream:
            for line in stream:
                if line.startswith('VmHWM:'):
                    return int(line.split()[1]) / 1024.0
    except (IOError, OSError, ValueError, IndexError):
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def split_blocks(n, holdout=DEFAULT_HOLDOUT, blocks=DEFAULT_BLOCKS):
    """Indices (train, held) cutting ``n`` time-ordered vectors into contiguous blocks, ~holdout held out.

    The held-out blocks are spread over the data (not only its end), so the threshold sees every phase.
    """
    blocks = max(2, min(blocks, n // 2))
    edges = np.linspace(0, n, blocks + 1).astype(int)
    n_held = max(1, int(round(holdout * blocks)))
    # spread the held-out blocks evenly, inside the data (the first and last blocks train)
    chosen = sorted(set(min(blocks - 1, int((k + 0.5) * blocks / n_held)) for k in range(n_held)))
    held = np.concatenate([np.arange(edges[b], edges[b + 1]) for b in chosen])
    mask = np.ones(n, dtype=bool)
    mask[held] = False
    return np.flatnonzero(mask), held


class _Fitted(object):
    """A fitted scaler + kernel model (arrays only) with its numpy scorer."""

    def __init__(self, config, mean, scale, kind, kernel, names):
        self.model = AnomalyModel(config, mean, scale, kind, kernel, 0.0, names)

    def scores(self, X):
        return self.model.scores(X)


def feature_scale(std):
    """The scale that standardises features of standard deviations ``std``: 1.0 for a constant column (as
    scikit-learn's StandardScaler), at least MIN_SCALE for the others. A column that varied by float rounding
    alone (odometry whose pose is integrated from its own twist: a sideways pose error of 1e-15 m/s) would
    otherwise make a rounding difference tens of thousands of standard deviations: anomalous wherever the robot
    drives a little differently, e.g. from coordinates further from the origin."""
    std = np.array(std, dtype=float)
    std[std < 10 * np.finfo(float).eps] = 1.0
    return np.maximum(std, MIN_SCALE)


def _fit(X, config, nu, gamma, method, names, seed):
    from sklearn.preprocessing import StandardScaler
    scaler = StandardScaler().fit(X)
    mean = scaler.mean_
    scaler.scale_ = scale = feature_scale(scaler.scale_)
    Z = (X - mean) / scale
    if method == 'nystroem':
        from sklearn.kernel_approximation import Nystroem
        from sklearn.linear_model import SGDOneClassSVM
        components = min(NYSTROEM_COMPONENTS, len(Z))
        nystroem = Nystroem(kernel='rbf', gamma=gamma, n_components=components, random_state=seed).fit(Z)
        features = nystroem.transform(Z)
        sgd = SGDOneClassSVM(nu=nu, random_state=seed, max_iter=50, tol=1e-4).fit(features)
        kernel = {'components': nystroem.components_, 'normalization': nystroem.normalization_,
                  'coef': sgd.coef_.ravel(), 'offset': float(np.ravel(sgd.offset_)[0]), 'gamma': gamma}
        return _Fitted(config, mean, scale, 'nystroem-sgd', kernel, names), (nystroem, sgd, scaler)
    from sklearn.svm import OneClassSVM
    svm = OneClassSVM(kernel='rbf', nu=nu, gamma=gamma, cache_size=200).fit(Z)
    kernel = {'support_vectors': svm.support_vectors_, 'dual_coef': svm.dual_coef_.ravel(),
              'intercept': float(svm.intercept_[0]), 'gamma': gamma}
    return _Fitted(config, mean, scale, 'ocsvm', kernel, names), (svm, scaler)


def nominal_threshold(scores, quantile=DEFAULT_QUANTILE, margin=DEFAULT_MARGIN):
    """Threshold below nearly all ``scores`` of held-out nominal vectors: q - margin * (median - q)."""
    scores = np.asarray(scores, dtype=float)
    low = float(np.quantile(scores, quantile))
    median = float(np.median(scores))
    return low - margin * max(median - low, 1e-12)


def train(nominal, anomalous=None, config=None, nu=None, gamma=None, method='auto',
          holdout=DEFAULT_HOLDOUT, blocks=DEFAULT_BLOCKS, quantile=DEFAULT_QUANTILE, margin=DEFAULT_MARGIN,
          max_exact=DEFAULT_MAX_EXACT, names=None, seed=0, trim=0.0, stamps=None):
    """Train a one-class SVM; return ``(AnomalyModel, info)``.

    ``nominal`` (and ``anomalous``) are 2-D arrays of window vectors in time order. ``config`` is the
    FeatureConfig they were computed with (default: FeatureConfig()). ``nu`` and ``gamma`` (RBF on
    standardised vectors) default to DEFAULT_NU and DEFAULT_GAMMA_FACTOR / n_features, or are chosen on a
    grid when anomalous vectors are given and they are None. ``method``: 'exact' (OneClassSVM on all
    training vectors), 'nystroem' (Nystroem + SGDOneClassSVM), 'auto' (exact; above ``max_exact`` training
    vectors, on an even subsample in time). ``trim``: the largest share of nominal vectors dropped before
    everything else, the lowest scoring by fits over the other blocks and beyond TRIM_FENCE (default 0: none;
    ``cclog learn`` passes DEFAULT_TRIM);
    ``stamps`` (one per nominal vector) name where they were in ``info['trimmed_spans']``. ``info`` holds the
    figures of the run (sizes, parameters, trimming, threshold calibration, training seconds, peak memory); the
    model's ``coverage`` the range of the kept nominal vectors (``coverage``).
    """
    started = time.time()
    config = config if config is not None else FeatureConfig()
    if method not in METHODS:
        raise ValueError('method: %r is not one of %s' % (method, ', '.join(METHODS)))
    X = np.asarray(nominal, dtype=float)
    if X.ndim != 2:
        raise ValueError('nominal: need a 2-D array of vectors, got shape %s' % (X.shape,))
    if len(X) < MIN_VECTORS:
        raise ValueError('nominal: %d vectors, need at least %d: collect with a smaller stride (--stride 1 gives '
                         'one per message), a shorter feature window, or from more nominal driving'
                         % (len(X), MIN_VECTORS))
    dimension = vector_length(config)
    if X.shape[1] != dimension:
        raise ValueError('nominal: vectors have %d features, the config %s needs %d'
                         % (X.shape[1], config.to_dict(), dimension))
    if not np.all(np.isfinite(X)):
        raise ValueError('nominal: holds non-finite values')
    A = None
    if anomalous is not None and len(anomalous):
        A = np.asarray(anomalous, dtype=float)
        if A.ndim != 2 or A.shape[1] != dimension or not np.all(np.isfinite(A)):
            raise ValueError('anomalous: need a finite 2-D array of %d columns' % dimension)
    if names is None:
        names = vector_names(config)
    if isinstance(trim, bool) or not isinstance(trim, (int, float)) or not 0 <= trim < MAX_TRIM:
        raise ValueError('trim: %r must be a share from 0 to below %g' % (trim, MAX_TRIM))
    if stamps is not None:
        stamps = np.asarray(stamps, dtype=float)
        if stamps.shape != (len(X),):
            raise ValueError('stamps: %d stamps for %d nominal vectors' % (stamps.size, len(X)))
    fit_method = 'nystroem' if method == 'nystroem' else 'exact'
    kept, trimmed = _trim(X, stamps, trim, config, nu, gamma, fit_method, max_exact, names, seed)
    X = X[kept]
    train_index, held_index = split_blocks(len(X), holdout, blocks)
    X_train, X_held = X[train_index], X[held_index]
    subsampled = False
    if method == 'auto' and len(X_train) > max_exact:
        X_train = X_train[np.linspace(0, len(X_train) - 1, max_exact).astype(int)]
        subsampled = True
    info = {'method': fit_method, 'requested_method': method, 'vectors_nominal': len(kept) + trimmed['trimmed'],
            'vectors_train': len(X_train), 'vectors_held_out': len(X_held), 'subsampled': subsampled,
            'vectors_anomalous': 0 if A is None else len(A), 'features': dimension,
            'config': config.to_dict()}
    info.update(trimmed)

    candidates = []
    if A is not None and (nu is None or gamma is None):
        nus = NU_GRID if nu is None else (nu,)
        gammas = [f / dimension for f in GAMMA_FACTOR_GRID] if gamma is None else (gamma,)
        for candidate_nu in nus:
            for candidate_gamma in gammas:
                fitted, _ = _fit(X_train, config, candidate_nu, candidate_gamma, fit_method, names, seed)
                held_scores = fitted.scores(X_held)
                anomalous_scores = fitted.scores(A)
                threshold = _recall_threshold(held_scores, anomalous_scores)
                fp = int(np.sum(held_scores < threshold))
                precision = len(A) / float(len(A) + fp)
                spread = max(float(np.median(held_scores) - np.min(anomalous_scores)), 1e-12)
                candidates.append({'nu': candidate_nu, 'gamma': candidate_gamma, 'false_positives': fp,
                                   'precision': precision, 'threshold': threshold,
                                   'margin': (np.min(held_scores) - np.max(anomalous_scores)) / spread,
                                   'fitted': fitted})
        best = max(candidates, key=lambda c: (c['precision'], c['margin']))
        fitted, nu, gamma, threshold = best['fitted'], best['nu'], best['gamma'], best['threshold']
        info['grid'] = [{key: value for key, value in c.items() if key != 'fitted'} for c in candidates]
        info['threshold_rule'] = 'midway between the highest anomalous score and the next held-out nominal score'
        held_scores = fitted.scores(X_held)
    else:
        nu = DEFAULT_NU if nu is None else float(nu)
        gamma = DEFAULT_GAMMA_FACTOR / dimension if gamma is None else float(gamma)
        reductions = 0
        while True:
            fitted, _ = _fit(X_train, config, nu, gamma, fit_method, names, seed)
            held_scores = fitted.scores(X_held)
            floor = _score_floor(fitted.model)
            low = float(np.quantile(held_scores, quantile))
            # Held-out nominal vectors beyond the reach of every support vector (their score is the floor):
            # the kernel is too narrow for this data; widen it (smaller gamma) and refit.
            if floor is None or low - floor > 0.01 * (float(np.median(held_scores)) - floor) or reductions >= 4:
                break
            gamma *= 0.5
            reductions += 1
        threshold = nominal_threshold(held_scores, quantile, margin)
        info['threshold_rule'] = ('held-out nominal: q%g - %g * (median - q%g)' % (quantile, margin, quantile))
        info['gamma_reductions'] = reductions
        if floor is not None and threshold <= floor + 0.1 * (low - floor):
            # at or below the floor a threshold flags only what lies beyond the reach of every support vector
            threshold = floor + 0.1 * (low - floor)
            info['threshold_rule'] += ', raised above the kernel floor'
        if A is not None:
            threshold = max(threshold, _recall_threshold(held_scores, fitted.scores(A)))
    model = fitted.model
    model.threshold = float(threshold)
    info.update({
        'nu': nu, 'gamma': gamma, 'threshold': float(threshold),
        'support_vectors': int(model.kernel['support_vectors'].shape[0]) if model.kind == 'ocsvm'
        else int(model.kernel['components'].shape[0]),
        'held_out_score_min': float(np.min(held_scores)), 'held_out_score_median': float(np.median(held_scores)),
        'held_out_flagged': int(np.sum(held_scores < threshold)),
        'train_seconds': time.time() - started, 'peak_rss_mb': peak_rss_mb(),
    })
    model.info = {key: value for key, value in info.items() if key != 'grid'}
    model.coverage = coverage(X, config)
    model.ranges = {'min': np.min(X, axis=0), 'max': np.max(X, axis=0)}
    return model, info


def _trim(X, stamps, trim, config, nu, gamma, fit_method, max_exact, names, seed):
    """``(kept indices, info entries)``: score each of TRIM_FOLDS contiguous blocks of ``X`` with a model fitted on
    the others (an even subsample above ``max_exact`` for the exact SVM; a model scoring its own training
    vectors would see a run of anomalous windows as a mode of its own), drop at most the ``trim`` share scoring
    lowest, of those beyond the far-out fence; the entries count them and list their spans."""
    count = int(round(trim * len(X)))
    entries = {'trim': float(trim), 'trimmed': 0, 'trimmed_spans': [], 'trimmed_by': 'stamp' if stamps is not None
               else 'index'}
    if count < 1 or len(X) - count < MIN_VECTORS:
        return np.arange(len(X)), entries
    first_nu = DEFAULT_NU if nu is None else float(nu)
    first_gamma = DEFAULT_GAMMA_FACTOR / X.shape[1] if gamma is None else float(gamma)
    scores = np.empty(len(X))
    edges = np.linspace(0, len(X), TRIM_FOLDS + 1).astype(int)
    for start, end in zip(edges[:-1], edges[1:]):
        sample = np.concatenate((X[:start], X[end:]))
        if fit_method == 'exact' and len(sample) > max_exact:
            sample = sample[np.linspace(0, len(sample) - 1, max_exact).astype(int)]
        fitted, _ = _fit(sample, config, first_nu, first_gamma, fit_method, names, seed)
        scores[start:end] = fitted.scores(X[start:end])
    # at most ``count``, and only those "far out" below the bulk of these scores (Tukey's outer fence, TRIM_FENCE
    # interquartile ranges below the lower quartile): a clean day loses little, anomalies far below the rest go
    low, high = np.quantile(scores, (0.25, 0.75))
    cut = low - TRIM_FENCE * (high - low)
    lowest = np.argsort(scores, kind='stable')[:count]
    dropped = np.sort(lowest[scores[lowest] < cut])
    count = len(dropped)
    entries['trim_cut'] = float(cut)
    if not count:
        return np.arange(len(X)), entries
    mask = np.ones(len(X), dtype=bool)
    mask[dropped] = False
    spans = []  # [first, last, vectors] of runs of consecutive dropped vectors
    for index in dropped:
        if spans and index == spans[-1][1] + 1:
            spans[-1][1] = index
            spans[-1][2] += 1
        else:
            spans.append([index, index, 1])
    if len(spans) > MAX_TRIMMED_SPANS:
        spans = sorted(sorted(spans, key=lambda span: -span[2])[:MAX_TRIMMED_SPANS])
    where = stamps if stamps is not None else np.arange(len(X))
    entries.update(trimmed=count, trimmed_spans=[[float(where[a]) if stamps is not None else int(a),
                                                  float(where[b]) if stamps is not None else int(b), int(n)]
                                                 for a, b, n in spans],
                   trimmed_spans_listed=len(spans), trimmed_spans_total=_runs(dropped))
    return np.flatnonzero(mask), entries


def _runs(indices):
    """How many runs of consecutive numbers sorted ``indices`` hold."""
    return int(len(indices) and 1 + np.sum(np.diff(indices) > 1))


# -- coverage: the range of interpretable quantities the training vectors cover ------------------------------

def _absmax(columns):
    return lambda X: np.max(np.abs(X[:, columns]), axis=1)


def _raw_speed(vx, vy, vz):
    return lambda X: np.max(np.sqrt(X[:, vx] ** 2 + X[:, vy] ** 2 + X[:, vz] ** 2), axis=1)


def coverage_quantities(config):
    """``[(name, unit, function of a 2-D array of vectors -> 1-D values, upper_only)]`` of ``config``'s vectors:
    for the odometry sets (motion, command, progress, raw) the largest speed ``|v|`` and yaw rate ``|w|`` of each
    window (upper bounds only; a window is stopped when its ``|v|`` is below STOPPED_SPEED); for the others
    every feature of the vector (both bounds)."""
    names = vector_names(config)
    column = {name: index for index, name in enumerate(names)}

    def columns(*wanted):
        return [column[name] for name in wanted]

    speed = yaw = None
    if 'max(speed)' in column and 'max(wz)' in column:
        speed, yaw = _absmax(columns('max(speed)')), _absmax(columns('min(wz)', 'max(wz)'))
    elif 'max(v)' in column and 'max(w)' in column:
        speed, yaw = _absmax(columns('min(v)', 'max(v)')), _absmax(columns('min(w)', 'max(w)'))
    elif 'max_speed' in column and 'max_yaw_rate' in column:
        speed, yaw = _absmax(columns('max_speed')), _absmax(columns('max_yaw_rate'))
    elif 'vx[0]' in column and 'wz[0]' in column:
        rows = sorted(int(name[3:-1]) for name in column if name.startswith('vx['))
        speed = _raw_speed(*[[column['%s[%d]' % (axis, i)] for i in rows] for axis in ('vx', 'vy', 'vz')])
        yaw = _absmax([column['wz[%d]' % i] for i in rows])
    if speed is not None:
        return [('|v|', 'm/s', speed, True), ('|w|', 'rad/s', yaw, True)]
    return [(name, '', (lambda index: lambda X: X[:, index])(index), False) for index, name in enumerate(names)]


def coverage(vectors, config):
    """The training range of ``coverage_quantities`` over ``vectors`` (2-D): ``{"quantities": [{"name", "unit",
    "min", "max", "q01", "q99"}], "vectors": n}``, with ``"stopped_share"`` (the share of stopped windows) and
    ``"stopped_speed"`` for the odometry sets. Stored in the model file; ``drift.DriftMonitor`` compares live
    vectors with it."""
    X = np.asarray(vectors, dtype=float)
    quantities = coverage_quantities(config)
    result = {'quantities': [], 'vectors': int(len(X))}
    for name, unit, function, _ in quantities:
        values = function(X)
        low, high = np.quantile(values, COVERAGE_QUANTILES)
        result['quantities'].append({'name': name, 'unit': unit, 'min': float(np.min(values)),
                                     'max': float(np.max(values)), 'q01': float(low), 'q99': float(high)})
    if quantities[0][0] == '|v|':
        result['stopped_share'] = float(np.mean(quantities[0][2](X) < STOPPED_SPEED))
        result['stopped_speed'] = STOPPED_SPEED
    return result


def _score_floor(model):
    """The score the plain kernel sum tends to far from every support vector (the model's score goes on below it,
    ever more slowly: ``model.FLOOR_FRACTION``), or None when the kernel has no such floor."""
    if model.kind == 'ocsvm':
        return model.kernel['intercept'] + float(np.sum(np.minimum(model.kernel['dual_coef'], 0.0)))
    return None


def _recall_threshold(nominal_scores, anomalous_scores):
    """Threshold flagging every anomalous score: midway to the next nominal score above the highest one."""
    top = float(np.max(anomalous_scores))
    above = nominal_scores[nominal_scores > top]
    if len(above) == 0:
        return top + max(1e-9, 1e-6 * abs(top))
    return 0.5 * (top + float(np.min(above)))


# -- evaluation -----------------------------------------------------------------------------------------

def evaluate(model, nominal, anomalous):
    """Count decisions of ``model`` on nominal and anomalous vectors (positive = anomalous)."""
    fp = tn = tp = fn = 0
    if nominal is not None and len(nominal):
        flagged = model.scores(np.asarray(nominal, dtype=float)) < model.threshold
        fp, tn = int(flagged.sum()), int((~flagged).sum())
    if anomalous is not None and len(anomalous):
        flagged = model.scores(np.asarray(anomalous, dtype=float)) < model.threshold
        tp, fn = int(flagged.sum()), int((~flagged).sum())
    precision = tp / float(tp + fp) if tp + fp else float('nan')
    recall = tp / float(tp + fn) if tp + fn else float('nan')
    return Report(tp + fp + fn + tn, tp, fp, fn, tn, precision, recall)


def format_report(report, info=None):
    """The paper's table: Total, TP, FP, FN, TN, Precision, Recall, training time, peak memory."""
    def percent(value):
        return 'n/a' if value != value else '%.1f%%' % (100.0 * value)

    lines = ['%-16s %s' % ('Total', report.total), '%-16s %s' % ('TP', report.tp),
             '%-16s %s' % ('FP', report.fp), '%-16s %s' % ('FN', report.fn), '%-16s %s' % ('TN', report.tn),
             '%-16s %s' % ('Precision', percent(report.precision)),
             '%-16s %s' % ('Recall', percent(report.recall))]
    if info:
        if 'train_seconds' in info:
            lines.append('%-16s %.2f s' % ('Training time', info['train_seconds']))
        if 'peak_rss_mb' in info:
            lines.append('%-16s %.0f MB (process peak RSS)' % ('Peak memory', info['peak_rss_mb']))
        if 'method' in info:
            lines.append('%-16s %s, nu=%g, gamma=%.4g, %s vectors (%s held out), threshold %.4g' % (
                'Model', info['method'], info.get('nu', float('nan')), info.get('gamma', float('nan')),
                info.get('vectors_train', '?'), info.get('vectors_held_out', '?'), info.get('threshold', 0.0)))
        if 'trimmed' in info:
            lines.append(trim_text(info))
    return '\n'.join(lines)


def trim_text(info):
    """The line on what training left out: ``Trimmed  12 of 5000 nominal vectors (trim 1%), 3 spans:
    1700000012.0-1700000014.5 s (11), ...`` or that trimming was off."""
    if not info.get('trim'):
        return '%-16s none (trim 0: every nominal vector trained)' % 'Trimmed'
    spans = info.get('trimmed_spans') or []
    stamped = info.get('trimmed_by') == 'stamp'
    shown = ', '.join(('%.1f-%.1f s' if stamped else 'vectors %d-%d') % (a, b) + ' (%d)' % n
                      for a, b, n in spans[:5])
    more = info.get('trimmed_spans_total', len(spans)) - min(5, len(spans))
    return '%-16s %d of %d nominal vectors, the most outlying (trim %g%%): %d span(s)%s%s' % (
        'Trimmed', info['trimmed'], info.get('vectors_nominal', 0), 100.0 * info['trim'],
        info.get('trimmed_spans_total', len(spans)), (': ' + shown) if shown else '',
        ' and %d more' % more if more > 0 else '')
