"""The learned physics envelope: what a robot's nominal driving reached, and how far a window goes beyond it.

``Envelope`` holds the largest value of every ``features.envelope`` column over the windows of nominal driving
(``learn``), with the window and stride they were computed over and the topic. A window's *limit* per feature
is ``factor`` (default 2.0) times the larger of that maximum and the feature's physical floor
(``ENVELOPE_FLOORS``), so a robot that never turned in training does not flag every turn. Its *ratio* is
value / limit, and its score keeps cc_log's direction (lower is more anomalous; docs/DESIGN.md):

    score = -ln(max ratio)      0 at the limit, negative beyond it (flagged), positive inside

(a max ratio below 1e-6 counts as 1e-6). ``explain`` names the features beyond their limit, most outstanding
first, each against the most seen in training (floored). The file (``save``/``load``, JSON) is read with bounds:
known keys only, every column's maximum a finite non-negative number, one-line ValueErrors naming the file.
Pure: no rospy.
"""
import collections
import json
import math

import numpy as np

from cc_log.core import safe_files, safe_input
from cc_log.core.safe_input import brief
from cc_log.features.envelope import ENVELOPE_COLUMNS, ENVELOPE_FLOORS, ENVELOPE_UNITS

KIND = 'cc_log envelope'
VERSION = 1
DEFAULT_FACTOR = 2.0
MIN_RATIO = 1e-6            # a smaller max ratio scores as this one (score <= 13.8)
MAX_FILE_BYTES = 1 << 20
MAX_WHY = 3                 # features a Fire names at most
_KEYS = ('kind', 'version', 'topic', 'window', 'stride', 'windows', 'seconds', 'maxima')

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


class Envelope(collections.namedtuple('Envelope', 'maxima topic window stride windows seconds')):
    """The nominal driving's largest value per envelope feature (``maxima``: a dict over ``ENVELOPE_COLUMNS``),
    learned on ``topic`` over windows of ``window`` s every ``stride`` s (``windows`` of them, ``seconds`` of
    driving)."""

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
            ('maxima', collections.OrderedDict((name, float(self.maxima[name])) for name in ENVELOPE_COLUMNS))])

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
        unknown = sorted(set(document) - set(_KEYS), key=str)
        if unknown:
            raise ValueError('%s: unknown key %s' % (source, brief(unknown[0])))
        if document.get('version') != VERSION:
            raise ValueError('%s: version %s, this cc_log reads %d' % (source, brief(document.get('version')), VERSION))
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
        return cls({name: float(maxima[name]) for name in ENVELOPE_COLUMNS}, topic, window, stride, int(windows),
                   seconds)

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


def learn(matrices, topic, window, stride, seconds):
    """The envelope of nominal driving: ``matrices`` the ``envelope_windows`` matrices of its runs (each (n, 19));
    ValueError when they hold no window."""
    matrices = [np.asarray(m, dtype=float).reshape(-1, len(ENVELOPE_COLUMNS)) for m in matrices]
    rows = sum(len(m) for m in matrices)
    if not rows:
        raise ValueError('%s: no whole window of %g s of odometry to learn from' % (topic, window))
    maxima = np.max(np.concatenate(matrices), axis=0)
    return Envelope({name: float(value) for name, value in zip(ENVELOPE_COLUMNS, maxima)}, topic, float(window),
                    float(stride), rows, float(seconds))


def ratios(matrix, limits):
    """Each value over its limit (rows of ``matrix`` against the ``limits`` array)."""
    return np.asarray(matrix, dtype=float) / limits


def scores(matrix, limits):
    """The score of each row: ``-ln(max ratio)`` (lower is more anomalous; < 0 beyond the envelope)."""
    worst = np.max(ratios(matrix, limits), axis=-1)
    return -np.log(np.maximum(worst, MIN_RATIO))


def explain(row, envelope, factor=DEFAULT_FACTOR, details=None):
    """Why a window (``row``, one ``envelope_windows`` row) is beyond the envelope: a tuple of at most MAX_WHY
    dicts ``{feature, value, limit, ratio, unit, text}`` of the features beyond ``factor`` x their limit, most
    outstanding first. ``limit`` is what the value is measured against, the most seen in training (floored:
    ``Envelope.trained``), ``ratio`` value / limit (the window fired because it exceeds ``factor``); the text
    says how far past it. ``details``: ``{feature: text}`` said instead of the feature's plain value (e.g. the
    pose step against the wheels' step)."""
    trained = envelope.trained()
    row = np.asarray(row, dtype=float)
    beyond = np.flatnonzero(row > check_factor(factor) * trained)
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
    return tuple(why)


def _figure(value):
    return '%.3g' % value if abs(value) < 10 else '%.1f' % value
