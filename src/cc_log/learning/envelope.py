"""The learned physics envelope: what a robot's nominal driving reached, and how far a window goes beyond it.

``Envelope`` holds the largest value of every ``features.envelope`` column over the windows of nominal driving
(``learn``), with the window and stride they were computed over and the topic. A window's *limit* per feature
is ``factor`` (default 2.0) times the larger of that maximum and the feature's physical floor
(``ENVELOPE_FLOORS``), so a robot that never turned in training does not flag every turn. Its *ratio* is
value / limit, and its score keeps cc_log's direction (lower is more anomalous; docs/DESIGN.md):

    score = -ln(max ratio)      0 at the limit, negative beyond it (flagged), positive inside

(a max ratio below 1e-6 counts as 1e-6, one above 1e300 or too large to compute as 1e300). ``explain`` names the
features beyond their limit, most outstanding first, each against the most seen in training (floored).

The *joint check* (``Envelope.joint``, a ``Joint``; None: off) sees a combination of features that nominal
driving never showed although each stays inside its own limit (two features that always moved together, apart
now). Learned on the training windows: each feature standardised by their mean and standard deviation (as
scikit-learn's StandardScaler, the deviation floored at ``JOINT_RESOLUTION``: a feature that spreads less is
float rounding, not driving, and a live window's rounding must not look new), the robust centre ``location`` and
``precision`` of the standardised windows (scikit-learn's MinCovDet), and of their squared distances
``d2 = (z - location) @ precision @ (z - location)`` the median (``typical``) and the largest (``farthest``).
A window's joint ratio is ``(d2 - typical) / (joint_factor x (farthest - typical))`` and the score takes the
larger of it and the largest feature ratio: ``-ln(max(feature ratios, joint ratio))``. Scoring is numpy only
(the live trigger); only ``learn`` uses scikit-learn.

The *local part* (``Envelope.local``, a ``learning.local_density.LocalDensity``; None: off) sees a window in a
sparse gap between kinds of nominal driving (inside every limit, near the robust centre): its local outlier
factor among the training windows. Its ratio ``(typical - score) / (local_factor x (typical - extreme))`` joins
the others: ``-ln(max(feature ratios, joint ratio, local ratio))``.

The file (``save``/``load``, JSON; version 4 with the ``local`` block's arrays compact, float64 in base64
(``local_density.ENCODING``: parsed in one call each), version 3 with them as lists of numbers, version 2 with the
``joint`` block only, version 1 with neither: the parts a file lacks are off) is read with bounds: known keys only,
every column's maximum a finite non-negative number, the joint and local blocks' arrays of their shapes and finite,
one-line ValueErrors naming the file. Pure: no rospy.
"""
import collections
import json
import math

import numpy as np

from cc_log.base import safe_files, safe_input
from cc_log.base.safe_input import brief
from cc_log.base.why import MAX_TEXT
from cc_log.features.envelope import ENVELOPE_COLUMNS, ENVELOPE_FLOORS, ENVELOPE_UNITS
from cc_log.learning import local_density
from cc_log.learning.local_density import finite_array

KIND = 'cc_log envelope'
VERSION = 4
VERSIONS = (1, 2, 3, 4)     # the versions ``load`` reads (1: no joint block, 2: no local block, 3: its arrays as lists)
DEFAULT_FACTOR = 2.0
DEFAULT_JOINT_FACTOR = 4.0  # the joint check's factor (the detector benchmark's level 4); 0: off
DEFAULT_LOCAL_FACTOR = 6.0  # the local part's factor (the detector benchmark's lof at level 6); 0: off
MIN_JOINT_WINDOWS = 50      # fewer training windows (or fewer than 2 per feature): no joint check
JOINT_RESOLUTION = 1e-6     # the smallest scale of a feature in the joint check (its units: m, m/s, rad, ...)
MIN_RATIO = 1e-6            # a smaller max ratio scores as this one (score <= 13.8)
MAX_RATIO = 1e300           # a larger one (or one too large to compute) as this one (score >= -690.8)
MAX_FILE_BYTES = 16 << 20  # the local part keeps up to 10,000 training windows
MAX_WHY = 3                 # features a Fire names at most
_KEYS = {1: ('kind', 'version', 'topic', 'window', 'stride', 'windows', 'seconds', 'maxima')}   # per version
_KEYS[2] = _KEYS[1] + ('joint',)
_KEYS[3] = _KEYS[2] + ('local',)
_KEYS[4] = _KEYS[3]

# How a feature is named in a window's "why"
LABELS = {
    'max_speed': 'speed', 'max_yaw_rate': 'yaw rate', 'max_accel': 'acceleration', 'max_yaw_accel':
    'yaw acceleration', 'max_jerk': 'jerk', 'speed_variation': 'speed variation in 1 window',
    'yaw_rate_variation': 'yaw rate variation in 1 window', 'yaw_rate_flips': 'yaw rate sign flips',
    'max_pose_gap': 'pose step off the wheels\' step', 'sum_pose_gap': 'pose off the wheels (summed)',
    'max_heading_gap': 'heading step off the yaw rate', 'sum_heading_gap': 'heading off the yaw rate (summed)',
    'still_fraction': 'time standing still', 'still_yaw_rate': 'yaw rate while standing',
    'max_span_accel': 'acceleration over 0.2 s', 'max_decel': 'deceleration', 'max_speedup': 'speed-up',
    'max_speed_drop': 'speed drop in 0.2 s', 'max_speed_rise': 'speed rise in 0.2 s',
}
# Shorter names where the joint check names three features in one line (a why's text is at most MAX_TEXT)
JOINT_LABELS = dict(LABELS, **{
    'speed_variation': 'speed variation', 'yaw_rate_variation': 'yaw rate variation', 'max_pose_gap': 'pose step gap',
    'sum_pose_gap': 'pose gap', 'max_heading_gap': 'heading step gap', 'sum_heading_gap': 'heading gap',
    'still_fraction': 'standing still', 'still_yaw_rate': 'yaw rate standing', 'max_span_accel': '0.2 s acceleration',
    'max_speed_drop': 'speed drop', 'max_speed_rise': 'speed rise'})


class Joint(collections.namedtuple('Joint', 'mean scale location precision typical farthest')):
    """The joint check of the training windows (see the module docstring): ``mean``, ``scale`` (per feature),
    ``location`` (standardised), ``precision`` (19 x 19) arrays; ``typical``, ``farthest``: the median and the
    largest squared distance of a training window."""

    __slots__ = ()

    def distances(self, matrix):
        """The squared robust distance ``d2`` of each row of ``matrix`` (numpy only)."""
        z = self.deviations(matrix)
        return np.einsum('...i,ij,...j->...', z, self.precision, z)

    def deviations(self, matrix):
        """Each row standardised, minus the location."""
        return (np.asarray(matrix, dtype=float) - self.mean) / self.scale - self.location

    def ratios(self, matrix, factor=DEFAULT_JOINT_FACTOR):
        """The joint ratio of each row: ``(d2 - typical) / (factor x (farthest - typical))`` (> 1: flagged)."""
        return (self.distances(matrix) - self.typical) / (factor * (self.farthest - self.typical))

    def to_dict(self):
        return collections.OrderedDict([
            ('mean', self.mean.tolist()), ('scale', self.scale.tolist()), ('location', self.location.tolist()),
            ('precision', self.precision.tolist()), ('typical', float(self.typical)),
            ('farthest', float(self.farthest))])

    def __eq__(self, other):
        return isinstance(other, Joint) and all(np.array_equal(a, b) for a, b in zip(self, other))

    def __ne__(self, other):
        return not self == other

    __hash__ = None


class Envelope(collections.namedtuple('Envelope', 'maxima topic window stride windows seconds joint local',
                                      defaults=(None,))):
    """The nominal driving's largest value per envelope feature (``maxima``: a dict over ``ENVELOPE_COLUMNS``),
    learned on ``topic`` over windows of ``window`` s every ``stride`` s (``windows`` of them, ``seconds`` of
    driving); ``joint``: their joint check (a ``Joint``), or None; ``local``: their local part (a
    ``LocalDensity``), or None."""

    __slots__ = ()

    def trained(self):
        """Per column (in ``ENVELOPE_COLUMNS`` order): the training maximum, floored (an array)."""
        return np.array([max(float(self.maxima[name]), ENVELOPE_FLOORS[name]) for name in ENVELOPE_COLUMNS])

    def limits(self, factor=DEFAULT_FACTOR):
        """Per column: the limit beyond which a window is flagged, ``factor`` x ``trained()``."""
        return check_factor(factor) * self.trained()

    def to_dict(self):
        return collections.OrderedDict([
            ('kind', KIND), ('version', VERSION), ('topic', self.topic), ('window', self.window),
            ('stride', self.stride), ('windows', self.windows), ('seconds', self.seconds),
            ('maxima', collections.OrderedDict((name, float(self.maxima[name])) for name in ENVELOPE_COLUMNS)),
            ('joint', self.joint.to_dict() if self.joint is not None else None),
            ('local', self.local.to_dict() if self.local is not None else None)])

    def save(self, path):
        """Write as JSON (atomically)."""
        with safe_files.AtomicFile(path, overwrite=True, text=True) as stream:
            json.dump(self.to_dict(), stream, indent=1)
            stream.write('\n')

    @classmethod
    def from_dict(cls, document, source='envelope'):
        """The envelope of a document ``to_dict`` wrote; ValueError('<source>: ...') otherwise."""
        if not isinstance(document, dict) or document.get('kind') != KIND:
            raise ValueError('%s: not an envelope file (no "kind": "%s")' % (source, KIND))
        version = document.get('version')
        if isinstance(version, bool) or version not in VERSIONS:
            raise ValueError('%s: version %s, this cc_log reads %s' % (
                source, brief(version), ' and '.join(str(v) for v in VERSIONS)))
        unknown = sorted(set(document) - set(_KEYS[version]), key=str)
        if unknown:
            raise ValueError('%s: unknown key %s' % (source, brief(unknown[0])))
        maxima = document.get('maxima')
        if not isinstance(maxima, dict) or set(maxima) != set(ENVELOPE_COLUMNS):
            missing = sorted(set(ENVELOPE_COLUMNS) - set(maxima or ())) if isinstance(maxima, dict) else ()
            raise ValueError('%s: maxima: must map each of the %d envelope features to a number%s' % (
                source, len(ENVELOPE_COLUMNS), ' (missing %s)' % missing[0] if missing else ''))
        for name, value in maxima.items():
            _number(value, '%s: maxima: %s' % (source, name))
        topic = document.get('topic')
        if not isinstance(topic, str) or not topic or len(topic) > 1024:
            raise ValueError('%s: topic: %s is not a topic name' % (source, brief(topic)))
        window = _number(document.get('window'), '%s: window' % source, positive=True, most=600.0)
        stride = _number(document.get('stride'), '%s: stride' % source, positive=True, most=600.0)
        windows = _number(document.get('windows'), '%s: windows' % source)
        seconds = _number(document.get('seconds'), '%s: seconds' % source)
        joint = _read_joint(document.get('joint'), '%s: joint' % source)
        local = local_density.from_dict(document.get('local'), '%s: local' % source, len(ENVELOPE_COLUMNS),
                                        compact=version >= 4)
        return cls({name: float(maxima[name]) for name in ENVELOPE_COLUMNS}, topic, window, stride, int(windows),
                   seconds, joint, local)

    @classmethod
    def load(cls, path):
        """The envelope in the JSON file ``path``; ValueError('<path>: ...') when it cannot be read or is wrong."""
        try:
            with safe_input.open_input(path) as stream:
                text = stream.read(MAX_FILE_BYTES + 1)
        except OSError as error:
            raise ValueError('%s: cannot be read (%s)' % (path, error.strerror or error))
        if len(text) > MAX_FILE_BYTES:
            raise ValueError('%s: larger than %d bytes: not an envelope file' % (path, MAX_FILE_BYTES))
        try:
            document = safe_input.json_loads(text, parse_constant=_refuse_constant, parse_int=safe_input.bounded_int)
        except ValueError as error:
            raise ValueError('%s: not JSON (%s)' % (path, error))
        return cls.from_dict(document, path)


def _read_joint(block, where):
    """The ``Joint`` of a file's ``joint`` block (None: none); ValueError('<where>: ...') unless every array has
    its shape and finite numbers (``scale`` positive) and ``typical`` < ``farthest``."""
    if block is None:
        return None
    if not isinstance(block, dict) or set(block) != set(Joint._fields):
        extra = sorted(set(block) - set(Joint._fields), key=str) if isinstance(block, dict) else ()
        raise ValueError('%s: must map %s to numbers%s' % (
            where, ', '.join(Joint._fields), ' (unknown key %s)' % brief(extra[0]) if extra else ''))
    size = len(ENVELOPE_COLUMNS)
    arrays = [finite_array(block[key], (size,) * (2 if key == 'precision' else 1), '%s: %s' % (where, key))
              for key in Joint._fields[:4]]
    if not np.all(arrays[1] > 0):
        raise ValueError('%s: scale: every entry must be positive' % where)
    typical = _number(block['typical'], '%s: typical' % where)
    farthest = _number(block['farthest'], '%s: farthest' % where)
    if not typical < farthest:
        raise ValueError('%s: typical %r must be below farthest %r' % (where, typical, farthest))
    return Joint(*(arrays + [typical, farthest]))


def _refuse_constant(name):
    raise ValueError('%s is not a number JSON allows' % name)


def _number(value, name, positive=False, most=None):
    """``value`` as a float: finite and >= 0 (> 0 when ``positive``; <= ``most``); ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0 or \
            (positive and value == 0) or (most is not None and value > most):
        kind = 'positive' if positive else 'non-negative'
        most_text = ' up to %g' % most if most else ''
        raise ValueError('%s: %s must be a finite %s number%s' % (name, brief(value), kind, most_text))
    return float(value)


def check_factor(factor, name='factor'):
    """The limit factor: a finite number above 1 (ValueError naming ``name``)."""
    try:
        value = float(factor)
    except (TypeError, ValueError):
        value = float('nan')
    if isinstance(factor, bool) or not (1.0 <= value < 1e6):
        raise ValueError('%s: %s must be a number from 1 up (2 flags twice the most seen in training)'
                         % (name, brief(factor)))
    return value


def check_joint_factor(factor, name='joint_factor'):
    """The joint check's factor: 0 (off) or a finite number from 1 up (ValueError naming ``name``)."""
    return _part_factor(factor, name, '%g flags a window %gx farther from typical driving than any training '
                        'window' % (DEFAULT_JOINT_FACTOR, DEFAULT_JOINT_FACTOR))


def check_local_factor(factor, name='local_factor'):
    """The local part's factor: 0 (off) or a finite number from 1 up (ValueError naming ``name``)."""
    return _part_factor(factor, name, '%g flags a window whose local outlier factor goes %gx past typical beyond '
                        'any training window' % (DEFAULT_LOCAL_FACTOR, DEFAULT_LOCAL_FACTOR))


def _part_factor(factor, name, example):
    """A part's factor: 0 (off) or a finite number from 1 up; ValueError naming ``name``, saying ``example``."""
    try:
        value = float(factor)
    except (TypeError, ValueError):
        value = float('nan')
    if isinstance(factor, bool) or not (value == 0.0 or 1.0 <= value < 1e6):
        raise ValueError('%s: %s must be 0 (off) or a number from 1 up (%s)' % (name, brief(factor), example))
    return value


def learn(matrices, topic, window, stride, seconds, joint=True, local=True):
    """The envelope of nominal driving: ``matrices`` the ``envelope_windows`` matrices of its runs (each (n, 19));
    with ``joint``, its joint check too (None when ``joint_shortfall`` says the windows cannot set one); with
    ``local``, its local part (``local_density.learn``: None when the windows are too few). ValueError when they
    hold no window."""
    matrices = [np.asarray(m, dtype=float).reshape(-1, len(ENVELOPE_COLUMNS)) for m in matrices]
    rows = sum(len(m) for m in matrices)
    if not rows:
        raise ValueError('%s: no whole window of %g s of odometry to learn from' % (topic, window))
    matrix = np.concatenate(matrices)
    maxima = np.max(matrix, axis=0)
    return Envelope({name: float(value) for name, value in zip(ENVELOPE_COLUMNS, maxima)}, topic, float(window),
                    float(stride), rows, float(seconds), learn_joint(matrix) if joint else None,
                    local_density.learn(matrix) if local else None)


def joint_shortfall(windows):
    """Why ``windows`` training windows cannot set a joint check ('' when they are enough)."""
    needed = max(MIN_JOINT_WINDOWS, 2 * len(ENVELOPE_COLUMNS))
    return '' if windows >= needed else '%d training windows, fewer than %d' % (windows, needed)


def learn_joint(matrix):
    """The ``Joint`` of the training windows ``matrix`` (n, 19); None when there are too few
    (``joint_shortfall``) or they do not spread (every window as far from the centre as the typical one)."""
    import warnings
    from sklearn.covariance import MinCovDet
    matrix = np.asarray(matrix, dtype=float)
    if joint_shortfall(len(matrix)) or not np.all(np.isfinite(matrix)):
        return None
    mean, scale = matrix.mean(axis=0), np.maximum(matrix.std(axis=0), JOINT_RESOLUTION)
    standardised = (matrix - mean) / scale
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')   # "not full rank": a feature constant in most windows
            robust = MinCovDet(random_state=0).fit(standardised)
    except (ValueError, np.linalg.LinAlgError):
        return None
    joint = Joint(mean, scale, np.asarray(robust.location_, dtype=float), np.asarray(robust.precision_, dtype=float),
                  0.0, 0.0)
    if not (np.all(np.isfinite(joint.location)) and np.all(np.isfinite(joint.precision))):
        return None
    distances = joint.distances(matrix)
    typical, farthest = float(np.median(distances)), float(np.max(distances))
    if not (np.isfinite(farthest) and typical < farthest):
        return None
    return joint._replace(typical=max(typical, 0.0), farthest=farthest)


def ratios(matrix, limits):
    """Each value over its limit (rows of ``matrix`` against the ``limits`` array)."""
    return np.asarray(matrix, dtype=float) / limits


def scores(matrix, limits, joint=None, joint_factor=DEFAULT_JOINT_FACTOR, local=None,
           local_factor=DEFAULT_LOCAL_FACTOR):
    """The score of each row: ``-ln(max(largest ratio, joint ratio, local ratio))`` (lower is more anomalous; < 0
    beyond the envelope). ``joint``: the ``Joint``, ``local``: the ``LocalDensity`` (None or factor 0: off)."""
    return score_of(np.maximum(*part_ratios(matrix, limits, joint, joint_factor, local, local_factor)))


def part_ratios(matrix, limits, joint=None, joint_factor=DEFAULT_JOINT_FACTOR, local=None,
                local_factor=DEFAULT_LOCAL_FACTOR):
    """Of each row, ``(largest feature ratio, the larger of the joint and the local ratio)`` (the second 0 when
    both are off): the parts ``scores`` takes the larger of."""
    worst = np.max(ratios(matrix, limits), axis=-1)
    other = np.zeros(len(worst))
    if joint is not None and joint_factor:
        other = np.maximum(other, joint.ratios(matrix, joint_factor))
    if local is not None and local_factor and len(worst):
        other = np.maximum(other, local.ratios(matrix, local_factor))
    return worst, other


def score_of(worst):
    """The score of a largest ratio (``-ln``, clipped to [MIN_RATIO, MAX_RATIO]; NaN, a value too large to
    square, as far out as can be said)."""
    worst = np.where(np.isnan(worst), np.inf, worst)
    return -np.log(np.clip(worst, MIN_RATIO, MAX_RATIO))


def explain(row, envelope, factor=DEFAULT_FACTOR, details=None, joint_factor=DEFAULT_JOINT_FACTOR,
            local_factor=DEFAULT_LOCAL_FACTOR):
    """Why a window (``row``, one ``envelope_windows`` row) is beyond the envelope: a tuple of at most MAX_WHY
    dicts ``{feature, value, limit, ratio, unit, text}`` of the features beyond ``factor`` x their limit, most
    outstanding first. ``limit`` is what the value is measured against, the most seen in training (floored:
    ``Envelope.trained``), ``ratio`` value / limit (the window fired because it exceeds ``factor``); the text
    says how far past it. ``details``: ``{feature: text}`` said instead of the feature's plain value (e.g. the
    pose step against the wheels' step). A window beyond the joint check (``joint_factor``; 0: off) adds the
    entry of feature ``joint`` (``joint_why``); the entries are ordered by how far past their factor they are. A
    window beyond the local part (``local_factor``; 0: off) adds the entry of feature ``local`` (``local_why``)
    last: its ratio grows with any distance, the named features say more where there are some."""
    trained = envelope.trained()
    row = np.asarray(row, dtype=float)
    factor = check_factor(factor)
    beyond = np.flatnonzero(row > factor * trained)
    order = beyond[np.argsort(-(row[beyond] / trained[beyond]), kind='stable')][:MAX_WHY]
    why = []
    for index in order:
        name = ENVELOPE_COLUMNS[index]
        value, unit, limit = float(row[index]), ENVELOPE_UNITS[name], float(trained[index])
        shown = '' if unit == '1' else ' ' + unit
        said = (details or {}).get(name) or '%s %s%s' % (LABELS[name], _figure(value), shown)
        if float(envelope.maxima[name]) >= limit:
            times = '%.1fx the most seen in training' % (value / limit)
        else:
            times = '%.1fx the floor %s%s (training never reached it)' % (value / limit, _figure(limit), shown)
        why.append({'feature': name, 'value': value, 'limit': limit, 'ratio': value / limit, 'unit': unit,
                    'text': '%s, %s' % (said, times)})
    joint = joint_why(row, envelope.joint, check_joint_factor(joint_factor)) if joint_factor else None
    if joint is not None:
        past = [entry['ratio'] / factor for entry in why]
        why.insert(int(np.searchsorted(-np.array(past), -joint['ratio'] / joint_factor, side='right')), joint)
    local = local_why(row, envelope.local, check_local_factor(local_factor)) if local_factor else None
    return tuple((why + [local] if local is not None else why)[:MAX_WHY])


def joint_why(row, joint, joint_factor=DEFAULT_JOINT_FACTOR):
    """The why entry of a window beyond the joint check (None when it is not, or there is no ``joint``):
    ``{feature: 'joint', value: d2, limit: farthest, ratio, unit: '1', text}``, ``ratio`` = (d2 - typical) /
    (farthest - typical), the text naming the MAX_WHY features that contribute most to d2 (``z_i (P z)_i``; a
    shorter sentence where that one would pass MAX_TEXT characters)."""
    if joint is None:
        return None
    row = np.asarray(row, dtype=float)
    if not joint.ratios(row, joint_factor) > 1:   # the rule ``scores`` flags by
        return None
    with np.errstate(over='ignore', invalid='ignore'):  # a value beyond any physical range: inf, said as such
        value = float(joint.distances(row))
        ratio = (value - joint.typical) / (joint.farthest - joint.typical)
        z = joint.deviations(row)
        parts = z * (joint.precision @ z)
    named = [JOINT_LABELS[ENVELOPE_COLUMNS[i]] for i in np.argsort(-parts, kind='stable')[:MAX_WHY]]
    said = ', '.join(named[:-1]) + ' and ' + named[-1] if len(named) > 1 else named[0]
    text = '%s together %.1fx farther from typical driving than any training window' % (said, ratio)
    if len(text) > MAX_TEXT:
        text = '%s together %.1fx past any training window' % (said, ratio)
    return {'feature': 'joint', 'value': value, 'limit': float(joint.farthest), 'ratio': ratio, 'unit': '1',
            'text': text}


def _figure(value):
    return '%.3g' % value if abs(value) < 10 or abs(value) >= 1e6 else '%.1f' % value


def local_why(row, local, local_factor=DEFAULT_LOCAL_FACTOR):
    """The why entry of a window beyond the local part (None when it is not, or there is no ``local``):
    ``{feature: 'local', value: its local outlier factor, limit: training's largest, ratio, unit: '1', text}``,
    ``ratio`` = (typical - score) / (typical - extreme), the text naming the MAX_WHY features farthest from the
    nearest training windows (``LocalDensity.deviations``)."""
    if local is None:
        return None
    row = np.asarray(row, dtype=float)
    score = float(local.scores(row[None])[0])
    ratio = (local.typical - score) / (local.typical - local.extreme)
    if not (local.typical - score) / (local_factor * (local.typical - local.extreme)) > 1:   # as ``scores``
        return None
    named = [JOINT_LABELS[ENVELOPE_COLUMNS[i]] for i in local.deviations(row, MAX_WHY)]
    for count in range(len(named), -1, -1):   # as many of the features as the text's length allows
        said = ', '.join(named[:count - 1]) + ' and ' + named[count - 1] if count > 1 else ''.join(named[:count])
        text = 'unusual for its neighbourhood%s: local outlier factor %s, %sx beyond training\'s spread' % (
            ' (%s)' % said if said else '', _figure(-score), _figure(ratio))
        if len(text) <= MAX_TEXT:
            break
    return {'feature': 'local', 'value': -score, 'limit': -float(local.extreme), 'ratio': ratio, 'unit': '1',
            'text': text}
