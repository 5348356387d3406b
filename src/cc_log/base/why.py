"""Why a window was kept: the features that stood out when a trigger fired, and by how much. Pure.

A ``Fire`` (``triggers.base``) carries ``why``: a tuple of at most MAX_ENTRIES entries, most outstanding first,
each a dict ``{"feature", "value", "limit", "ratio", "unit", "text"}``: the feature's name, its value, the limit
it is measured against (the most seen in training, a rule's level), ``ratio`` value / limit (None when that
says nothing: a limit of 0 or of the other sign), the unit, and a line for people ("yaw rate 4.2 rad/s, 2.3x
the most seen in training"; at most MAX_TEXT characters). A trigger may add other numeric keys (the
classifier's ``sd``: how many training standard deviations the value lies beyond the training range, or from
the training mean for a model without ranges). ``entry`` builds one, ``bounded`` bounds what goes into a
window's metadata (finite numbers or None, short texts), ``check`` is what a reader accepts, and
``classifier_why`` explains a classifier's window vector from its model.
"""
import math
import numbers

import numpy as np

MAX_ENTRIES = 3
MAX_TEXT = 120
MAX_FEATURE = 64
MAX_KEYS = 12  # keys of one entry
_NUMBER_KEYS = ('value', 'limit', 'ratio')
_TEXT_KEYS = ('feature', 'unit', 'text')
_KEYS = ('feature', 'value', 'limit', 'ratio', 'unit', 'text')

#: Words and unit of the channels of the feature sets (``features/``): a vector entry ``max(wz)`` reads
#: "max yaw rate", rad/s. A channel not listed reads as its own name, without a unit.
CHANNELS = {
    'vx': ('forward speed', 'm/s'), 'vy': ('sideways speed', 'm/s'), 'vz': ('vertical speed', 'm/s'),
    'wx': ('roll rate', 'rad/s'), 'wy': ('pitch rate', 'rad/s'), 'wz': ('yaw rate', 'rad/s'),
    'speed': ('speed', 'm/s'), 'ax': ('forward acceleration', 'm/s^2'), 'ay': ('sideways acceleration', 'm/s^2'),
    'az': ('vertical acceleration', 'm/s^2'), 'jerk': ('jerk', 'm/s^3'),
    'pose_vx_err': ('pose-minus-twist forward speed', 'm/s'), 'pose_vy_err': ('pose-minus-twist sideways speed', 'm/s'),
    'pose_vz_err': ('pose-minus-twist vertical speed', 'm/s'), 'up_x': ('roll tilt', '1'), 'up_y': ('pitch tilt', '1'),
    'climb_rate': ('climb rate', 'm/s'), 'energy_rate': ('specific power', 'W/kg'),
    'yaw_acc': ('yaw acceleration', 'rad/s^2'), 'yaw_err': ('heading-minus-yaw-rate turn rate', 'rad/s'),
    'acc_x': ('IMU acceleration x', 'm/s^2'), 'acc_y': ('IMU acceleration y', 'm/s^2'),
    'acc_z': ('IMU acceleration z', 'm/s^2'), 'acc_norm': ('IMU acceleration', 'm/s^2'),
    'gyro_x': ('IMU roll rate', 'rad/s'), 'gyro_y': ('IMU pitch rate', 'rad/s'), 'gyro_z': ('IMU yaw rate', 'rad/s'),
    'gyro_norm': ('IMU turn rate', 'rad/s'), 'gyro_change': ('IMU turn-rate change', 'rad/s^2'),
    'cmd_v': ('commanded speed', 'm/s'), 'cmd_w': ('commanded yaw rate', 'rad/s'), 'v': ('speed', 'm/s'),
    'w': ('yaw rate', 'rad/s'), 'v_err': ('speed minus command', 'm/s'), 'w_err': ('yaw rate minus command', 'rad/s'),
    'lag_v': ('speed short of command', 'm/s'), 'lag_w': ('yaw rate short of command', 'rad/s'),
    'over_v': ('speed beyond command', 'm/s'), 'over_w': ('yaw rate beyond command', 'rad/s'),
    'slip_v': ('wheel speed beyond pose speed', 'm/s'), 'cmd_age': ('command age', 's'),
    'px': ('x', 'm'), 'py': ('y', 'm'), 'pz': ('z', 'm'), 'qx': ('orientation qx', '1'), 'qy': ('orientation qy', '1'),
    'qz': ('orientation qz', '1'), 'qw': ('orientation qw', '1'),
    'displacement': ('displacement', 'm'), 'path_length': ('path length', 'm'), 'progress_ratio': ('progress', '1'),
    'rotation': ('rotation', 'rad'), 'net_rotation': ('net rotation', 'rad'),
    'rotation_in_place': ('rotation in place', 'rad'), 'speed_reversals': ('speed reversals', '1'),
    'yaw_reversals': ('yaw-rate reversals', '1'), 'mean_speed': ('mean speed', 'm/s'), 'max_speed': ('speed', 'm/s'),
    'mean_yaw_rate': ('mean yaw rate', 'rad/s'), 'max_yaw_rate': ('yaw rate', 'rad/s'),
    'turn_beyond_half': ('turn beyond a half turn', '0.01 rad'),
}
_STATISTICS = {'mean': 'mean %s', 'std': '%s spread', 'min': 'min %s', 'max': 'max %s'}


def words(name):
    """``(words, unit)`` of a window-vector entry: ``'max(wz)'`` -> ``('max yaw rate', 'rad/s')``, ``'vx[3]'``
    -> ``('forward speed [3]', 'm/s')``, ``'max_yaw_rate'`` -> ``('yaw rate', 'rad/s')``; else ``(name, '')``."""
    name = str(name)[:MAX_FEATURE]
    if name.endswith(')') and '(' in name:
        stat, channel = name[:-1].split('(', 1)
        if stat in _STATISTICS and channel in CHANNELS:
            label, unit = CHANNELS[channel]
            return _STATISTICS[stat] % label, unit
    if name.endswith(']') and '[' in name:
        channel, index = name[:-1].split('[', 1)
        if channel in CHANNELS:
            return '%s [%s]' % (CHANNELS[channel][0], index), CHANNELS[channel][1]
    return CHANNELS.get(name, (name, ''))


def number_text(value):
    """A value for people: 3 significant digits (``4.2``, ``0.0123``, ``1.2e+03``)."""
    return '%.3g' % value


def entry(feature, value, limit, unit='', text=None, label=None, **more):
    """One ``why`` entry (see the module docstring); ``text`` defaults to "<label> <value> <unit>, <ratio>x
    the most seen in training" (``label``: the feature in words, default its name); ``more``: other numeric
    keys."""
    value, limit = float(value), float(limit)
    ratio = value / limit if limit != 0 and (value >= 0) == (limit > 0) else None
    if text is None:
        unit_text = ' %s' % unit if unit and unit != '1' else ''
        text = '%s %s%s, %s' % (label or feature, number_text(value), unit_text,
                                '%sx the most seen in training' % number_text(ratio) if ratio is not None
                                else 'beyond the %s%s seen in training' % (number_text(limit), unit_text))
    result = {'feature': str(feature), 'value': value, 'limit': limit, 'ratio': ratio, 'unit': str(unit),
              'text': str(text)}
    result.update(more)
    return bounded([result])[0]


def _finite(value):
    if isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(float(value)):
        return float(value)
    return None


def bounded(why):
    """``why`` as it goes into a window's metadata: at most MAX_ENTRIES dicts of at most MAX_KEYS keys (those of
    the module docstring first), texts cut to MAX_TEXT (the others to MAX_FEATURE) characters, numbers finite floats
    or None; anything else left out."""
    result = []
    for item in list(why or ())[:MAX_ENTRIES]:
        if not isinstance(item, dict):
            continue
        clean = {}
        keys = [key for key in _KEYS if key in item] + [key for key in item if key not in _KEYS]
        for key in keys[:MAX_KEYS - 1]:
            value, key = item[key], str(key)[:MAX_FEATURE]
            if key in _TEXT_KEYS or (isinstance(value, str) and key not in _NUMBER_KEYS):
                clean[key] = str(value)[:MAX_TEXT if key == 'text' else MAX_FEATURE]
            else:
                clean[key] = _finite(value)
        clean.setdefault('text', clean.get('feature', ''))
        result.append(clean)
    return result


def check(why):
    """Whether ``why`` (read from a file) is what ``bounded`` writes: a list of at most MAX_ENTRIES objects of
    strings (``text`` at most MAX_TEXT characters, others at most MAX_FEATURE) and finite numbers or null, at most
    MAX_KEYS keys each."""
    if not isinstance(why, list) or len(why) > MAX_ENTRIES:
        return False
    for item in why:
        if not isinstance(item, dict) or not isinstance(item.get('text'), str) or len(item) > MAX_KEYS:
            return False
        for key, value in item.items():
            if len(key) > MAX_FEATURE:
                return False
            if isinstance(value, str) and key not in _NUMBER_KEYS:
                if len(value) > (MAX_TEXT if key == 'text' else MAX_FEATURE):
                    return False
            elif value is not None and _finite(value) is None:
                return False
    return True


def said(triggers):
    """The indices of the ``triggers`` (``records.Trigger``s of a window) whose why its metadata says: of each
    trigger name, the first firing that says why and the most anomalous one (the lowest score); the others would
    mostly repeat them, and a window of hundreds of firings keeps its metadata small."""
    first, lowest = {}, {}
    for index, trigger in enumerate(triggers):
        if not getattr(trigger, 'why', None):
            continue
        name = getattr(trigger, 'name', None) or trigger.reason
        first.setdefault(name, index)
        score = _finite(trigger.score)
        if score is not None and (name not in lowest or score < lowest[name][0]):
            lowest[name] = (score, index)
    return set(first.values()) | set(index for _, index in lowest.values())


def texts(why):
    """The ``text`` of each entry of a ``why`` (from a Fire or a file), joined by ``'; '`` ('' when none)."""
    return '; '.join(str(item.get('text', '')) for item in why or () if isinstance(item, dict))


def classifier_why(model, vector, names=None):
    """The ``why`` of a classifier's window ``vector`` (1-D) under ``model`` (an ``AnomalyModel``): the entries
    furthest outside the range the training vectors covered (``model.ranges``), measured in training standard
    deviations (``model.scale``) and compared with the most seen in training (``limit``: the training max above
    it, the min below it); for a model without ranges, or a vector inside them all, the entries furthest from the
    training mean in standard deviations (``limit``: the mean, ``ratio`` None). ``names``: of the vector's
    entries (default the model's)."""
    vector = np.asarray(vector, dtype=float)
    names = names or getattr(model, 'names', None) or ['feature %d' % index for index in range(len(vector))]
    scale = np.asarray(model.scale, dtype=float)
    ranges = getattr(model, 'ranges', None)
    outside = None
    if ranges is not None:
        low, high = np.asarray(ranges['min'], dtype=float), np.asarray(ranges['max'], dtype=float)
        above, below = (vector - high) / scale, (low - vector) / scale
        outside = np.maximum(above, below)
    if outside is not None and np.nanmax(outside) > 0:
        order = [index for index in np.argsort(-outside) if outside[index] > 0][:MAX_ENTRIES]
        result = []
        for index in order:
            label, unit = words(names[index])
            limit = high[index] if above[index] >= below[index] else low[index]
            result.append(entry(names[index], vector[index], limit, unit, label=label, sd=float(outside[index])))
        return tuple(result)
    z = (vector - np.asarray(model.mean, dtype=float)) / scale
    result = []
    for index in np.argsort(-np.abs(z))[:MAX_ENTRIES]:
        if not np.isfinite(z[index]):
            continue
        label, unit = words(names[index])
        unit_text = ' %s' % unit if unit and unit != '1' else ''
        side = 'above' if z[index] > 0 else 'below'
        text = '%s %s%s, %s sd %s the training mean' % (
            label, number_text(vector[index]), unit_text, number_text(abs(z[index])), side)
        said = entry(names[index], vector[index], model.mean[index], unit, text, sd=float(z[index]))
        said['ratio'] = None  # a ratio to the mean says nothing
        result.append(said)
    return tuple(result)
