"""What the classifier sees: odometry messages -> feature rows -> one vector per feature window.

Two feature sets:

- ``motion`` (default): per message, quantities that do not depend on where the robot is or which way it
  faces: body-frame twist (speeds, roll/pitch/yaw rates), speed, accelerations and jerk from twist
  differences over the real time step, the pose-derived body velocity minus the reported twist
  (consistency: localization jumps, wheels spinning while the pose stands still), the direction of "up" in
  the body frame (roll/pitch, never heading), the climb rate and the specific mechanical power
  d(speed^2/2 + g z)/dt (a UAV losing an engine, a robot hitting a wall). A window of rows becomes a
  fixed-length vector of per-channel summary statistics (mean, std, min, max), whatever the number of rows.
- ``raw``: the CC-Log paper's features, the concatenation of position, orientation, linear and angular
  twist of the W messages of a count window (kept for comparison; it depends on where the robot is).

Irregular time is expected: derivatives use the actual time step; a repeated stamp (or one closer than
``min_dt``) keeps the previous derivatives; time going backwards or a gap longer than ``max_dt`` restarts
the derivatives (they read 0 until the next message). A message with a non-finite field never raises: its
row repeats the last good row (zeros before any) and ``rejected`` counts it.

Pure Python plus numpy: no rospy. Messages are read by attribute (``msg.pose.pose.position.x`` ...), so
any object with the nav_msgs/Odometry layout works.
"""
import collections
import math

import numpy as np

from .spans import Span

FEATURE_SETS = ('motion', 'raw')
TOPIC_TYPES = ('nav_msgs/Odometry',)

MOTION_COLUMNS = (
    'vx', 'vy', 'vz',                      # reported linear twist (body frame by the ROS convention)
    'wx', 'wy', 'wz',                      # reported angular twist: roll, pitch, yaw rate
    'speed',                               # |v|
    'ax', 'ay', 'az',                      # d(linear twist)/dt over the real dt
    'jerk',                                # |d(a)/dt|
    'pose_vx_err', 'pose_vy_err', 'pose_vz_err',  # body velocity from pose differences minus twist
    'up_x', 'up_y',                        # world "up" in the body frame (roll / pitch, not heading)
    'climb_rate',                          # world dz/dt from pose differences
    'energy_rate',                         # d(speed^2 / 2 + g z)/dt: specific mechanical power
)
# Tried and left out: angular acceleration and the body rate from orientation differences minus the reported
# rate (heading-rate consistency). On the real data they were noise that hid the anomalies (ALFA publishes
# the angular twist at half the odometry rate): docs/DETECTION.md has the figures.
GRAVITY = 9.81
RAW_COLUMNS = ('px', 'py', 'pz', 'qx', 'qy', 'qz', 'qw', 'vx', 'vy', 'vz', 'wx', 'wy', 'wz')
STATISTICS = ('mean', 'std', 'min', 'max')

DEFAULT_MAX_DT = 1.0    # seconds: a longer gap between messages restarts the derivatives
DEFAULT_MIN_DT = 1e-4   # seconds: a shorter step counts as a repeated stamp
CLIP = 1e6              # every row value is clipped to +-CLIP so window statistics stay finite


def _parse_window(value):
    span = Span.parse(value, 'window')
    if span.count == 0 or span.seconds == 0:
        raise ValueError('window: must hold at least one message')
    return span


class FeatureConfig(collections.namedtuple('FeatureConfig', 'feature_set window topic_type')):
    """What a model was trained on: feature set, feature window (``'500'`` or ``'5s'``), topic type.

    The window is normalised to its canonical text (``'500'``, ``'5s'``); bad values raise
    ``ValueError('<field>: <what is wrong>')``.
    """

    __slots__ = ()

    def __new__(cls, feature_set='motion', window='500', topic_type='nav_msgs/Odometry'):
        if feature_set not in FEATURE_SETS:
            raise ValueError('feature_set: %r is not one of %s' % (feature_set, ', '.join(FEATURE_SETS)))
        span = _parse_window(window)
        if topic_type not in TOPIC_TYPES:
            raise ValueError('topic_type: %r is not supported (supported: %s)' % (topic_type, ', '.join(TOPIC_TYPES)))
        if feature_set == 'raw' and span.is_duration:
            raise ValueError('window: the raw feature set needs a message count, not %s' % (span,))
        return super(FeatureConfig, cls).__new__(cls, feature_set, str(span), topic_type)

    @property
    def span(self):
        """The feature window as a Span."""
        return Span.parse(self.window, 'window')

    def to_dict(self):
        """Plain dict (JSON-ready)."""
        return {'feature_set': self.feature_set, 'window': self.window, 'topic_type': self.topic_type}

    @classmethod
    def from_dict(cls, data):
        """Build from ``to_dict()`` output; raise ValueError for anything else."""
        if not isinstance(data, dict):
            raise ValueError('config: expected an object, got %s' % type(data).__name__)
        missing = [key for key in cls._fields if key not in data]
        if missing:
            raise ValueError('config: missing %s' % ', '.join(missing))
        extra = sorted(set(data) - set(cls._fields))
        if extra:
            raise ValueError('config: unknown field(s) %s' % ', '.join(map(str, extra)))
        for key in cls._fields:
            if not isinstance(data[key], str):
                raise ValueError('config: %s must be a string, got %r' % (key, data[key]))
        return cls(data['feature_set'], data['window'], data['topic_type'])


def columns(feature_set):
    """Names of the per-message row channels of a feature set."""
    if feature_set == 'motion':
        return MOTION_COLUMNS
    if feature_set == 'raw':
        return RAW_COLUMNS
    raise ValueError('feature_set: %r is not one of %s' % (feature_set, ', '.join(FEATURE_SETS)))


def stamp_of(msg, fallback):
    """``msg.header.stamp`` in float seconds when the message has a non-zero one, else ``fallback``."""
    header = getattr(msg, 'header', None)
    stamp = getattr(header, 'stamp', None)
    if stamp is not None:
        secs = getattr(stamp, 'secs', None)
        if secs is not None:
            value = secs + getattr(stamp, 'nsecs', 0) * 1e-9
            if value != 0:
                return float(value)
    if hasattr(fallback, 'to_sec'):
        return fallback.to_sec()
    return float(fallback)


def _clip(value):
    if value > CLIP:
        return CLIP
    if value < -CLIP:
        return -CLIP
    return value


class OdometryFeatures(object):
    """Per-message feature rows for one driving topic (stateful: derivatives need the previous message).

    ``row(msg, stamp)`` returns a new 1-D float array (never NaN or inf); ``columns`` names its entries;
    ``row_values(msg, stamp)`` is the same row as a tuple of plain floats (cheaper per message).
    ``rejected`` counts messages with non-finite fields, ``restarts`` the times the derivatives restarted
    (first message, time going backwards, gaps longer than ``max_dt``).
    """

    def __init__(self, config=None, max_dt=DEFAULT_MAX_DT, min_dt=DEFAULT_MIN_DT):
        self.config = config if config is not None else FeatureConfig()
        if not isinstance(self.config, FeatureConfig):
            raise ValueError('config: expected a FeatureConfig, got %s' % type(self.config).__name__)
        if not (max_dt > min_dt > 0):
            raise ValueError('max_dt: must be larger than min_dt (%r) and positive' % min_dt)
        self.max_dt = float(max_dt)
        self.min_dt = float(min_dt)
        self.columns = columns(self.config.feature_set)
        self._motion = self.config.feature_set == 'motion'
        self.rejected = 0
        self.restarts = 0
        self.reset()

    def reset(self):
        """Forget the previous message (derivatives restart at the next one)."""
        self._prev = None        # (stamp, p, q, v, w, a) of the last accepted message
        self._deriv = None       # last derivative channels (held on a repeated stamp)
        self._last_row = None
        self.segment_start = None  # stamp of the first row since the derivatives last restarted
        self.segment_rows = 0      # rows since then

    def covers(self, span, stamp):
        """True when the rows since the last restart (gap, backwards time) fill ``span`` up to ``stamp``.

        WindowBuffer's feature window is time-based and may hold rows from before a gap or only a few rows
        after one; callers that want only whole windows of continuous data check this as well.
        """
        span = Span.parse(span, 'window')
        if self.segment_start is None:
            return False
        if span.is_duration:
            return stamp - self.segment_start >= span.seconds
        return self.segment_rows >= span.count

    def row(self, msg, stamp):
        """The feature row of ``msg`` received at ``stamp`` (float seconds)."""
        return np.array(self.row_values(msg, stamp), dtype=float)

    def row_values(self, msg, stamp):
        """``row(msg, stamp)`` as a tuple of plain floats (the per-message fast path: no numpy)."""
        try:
            pose = msg.pose.pose
            twist = msg.twist.twist
            position, orientation = pose.position, pose.orientation
            linear, angular = twist.linear, twist.angular
            p = (float(position.x), float(position.y), float(position.z))
            q = (float(orientation.x), float(orientation.y), float(orientation.z), float(orientation.w))
            v = (float(linear.x), float(linear.y), float(linear.z))
            w = (float(angular.x), float(angular.y), float(angular.z))
            stamp = float(stamp)
            # finite iff x - x == 0 (NaN and +-inf give NaN)
            ok = (sum(p) + sum(q) + sum(v) + sum(w) + stamp) * 0.0 == 0.0
            if not ok:
                ok = all(math.isfinite(x) for x in p + q + v + w + (stamp,))
        except (AttributeError, TypeError, ValueError, OverflowError):
            ok = False
        if not ok:
            return self._reject()
        if not self._motion:
            row = _clipped(p + q + v + w)
            self._last_row = row
            self._count(stamp)
            return row
        n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
        if not (1e-12 < n2 < 1e12):
            return self._reject()
        n = math.sqrt(n2)
        q = (q[0] / n, q[1] / n, q[2] / n, q[3] / n)
        return self._motion_row(stamp, p, q, v, w)

    def _reject(self):
        self.rejected += 1
        if self._last_row is None:
            return (0.0,) * len(self.columns)
        return self._last_row

    def _count(self, stamp):
        if self.segment_start is None:
            self.segment_start = stamp
        self.segment_rows += 1

    def _motion_row(self, stamp, p, q, v, w):
        prev = self._prev
        dt = None if prev is None else stamp - prev[0]
        if dt is None or dt < 0 or dt > self.max_dt:
            # First message, time going backwards, or a gap: derivatives restart.
            if prev is not None:
                self.segment_start = None
                self.segment_rows = 0
            self.restarts += 1
            deriv = (0.0,) * 9
            a = None
            self._prev = (stamp, p, q, v, w, a)
        elif dt < self.min_dt:
            # Repeated stamp: keep the previous derivatives and the previous reference message.
            deriv = self._deriv
        else:
            _, p0, q0, v0, w0, a0 = prev
            inv = 1.0 / dt
            a = ((v[0] - v0[0]) * inv, (v[1] - v0[1]) * inv, (v[2] - v0[2]) * inv)
            if a0 is None:
                jerk = 0.0
            else:
                jerk = math.sqrt((a[0] - a0[0]) ** 2 + (a[1] - a0[1]) ** 2 + (a[2] - a0[2]) ** 2) * inv
            # Pose-derived body velocity: world displacement rotated into the body frame by the mean of the
            # two orientations' inverse rotations, compared with the mean reported twist.
            d = ((p[0] - p0[0]) * inv, (p[1] - p0[1]) * inv, (p[2] - p0[2]) * inv)
            b1 = _to_body(q0, d)
            b2 = _to_body(q, d)
            pose_err = (0.5 * (b1[0] + b2[0] - v0[0] - v[0]),
                        0.5 * (b1[1] + b2[1] - v0[1] - v[1]),
                        0.5 * (b1[2] + b2[2] - v0[2] - v[2]))
            climb = d[2]
            speed0 = math.sqrt(v0[0] * v0[0] + v0[1] * v0[1] + v0[2] * v0[2])
            speed1 = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            energy = 0.5 * (speed1 * speed1 - speed0 * speed0) * inv + GRAVITY * climb
            deriv = a + (jerk,) + pose_err + (climb, energy)
            self._prev = (stamp, p, q, v, w, a)
        self._deriv = deriv
        self._count(stamp)
        x, y, z, qw = q
        up_x = 2.0 * (x * z - y * qw)
        up_y = 2.0 * (y * z + x * qw)
        speed = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        row = _clipped(v + w + (speed,) + deriv[:7] + (up_x, up_y) + deriv[7:])
        self._last_row = row
        return row


def _clipped(values):
    """``values`` (a tuple of floats) with every entry clipped to +-CLIP (itself when none is out of range)."""
    if max(values) > CLIP or min(values) < -CLIP:
        return tuple(_clip(value) for value in values)
    return values


def _to_body(q, d):
    """Rotate world vector ``d`` into the body frame of unit quaternion ``q`` (x, y, z, w): R(q)^T d."""
    x, y, z, w = q
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r01 = 2.0 * (x * y - z * w)
    r02 = 2.0 * (x * z + y * w)
    r10 = 2.0 * (x * y + z * w)
    r11 = 1.0 - 2.0 * (x * x + z * z)
    r12 = 2.0 * (y * z - x * w)
    r20 = 2.0 * (x * z - y * w)
    r21 = 2.0 * (y * z + x * w)
    r22 = 1.0 - 2.0 * (x * x + y * y)
    return (r00 * d[0] + r10 * d[1] + r20 * d[2],
            r01 * d[0] + r11 * d[1] + r21 * d[2],
            r02 * d[0] + r12 * d[1] + r22 * d[2])


def vector_names(config):
    """Names of the entries of ``window_vector(rows, config)``."""
    if config.feature_set == 'motion':
        return ['%s(%s)' % (stat, name) for stat in STATISTICS for name in MOTION_COLUMNS]
    span = config.span
    if span.is_duration:
        raise ValueError('window: the raw feature set needs a message count, not %s' % (span,))
    return ['%s[%d]' % (name, i) for i in range(span.count) for name in RAW_COLUMNS]


def vector_length(config):
    """Length of the vectors of ``config``."""
    if config.feature_set == 'motion':
        return len(STATISTICS) * len(MOTION_COLUMNS)
    span = config.span
    if span.is_duration:
        raise ValueError('window: the raw feature set needs a message count, not %s' % (span,))
    return span.count * len(RAW_COLUMNS)


def window_vector(rows, config):
    """One fixed-length float vector from a feature window (list of rows, oldest first).

    ``motion``: mean, std, min and max of every channel (any number of rows >= 1). ``raw``: the rows
    concatenated; the window must be a message count and hold exactly that many rows.
    """
    if len(rows) == 0:
        raise ValueError('rows: the feature window is empty')
    if config.feature_set == 'motion':
        try:
            array = np.concatenate(rows).astype(float, copy=False).reshape(len(rows), -1)
        except ValueError:
            array = None
        if array is None or array.shape[1] != len(MOTION_COLUMNS):
            raise ValueError('rows: expected rows of %d motion channels' % len(MOTION_COLUMNS))
        return _motion_statistics(array)
    span = config.span
    if span.is_duration:
        raise ValueError('window: the raw feature set needs a message count, not %s' % (span,))
    if len(rows) != span.count:
        raise ValueError('rows: the raw feature set needs exactly %d rows, got %d' % (span.count, len(rows)))
    vector = np.concatenate(rows).astype(float)
    if vector.shape[0] != span.count * len(RAW_COLUMNS):
        raise ValueError('rows: expected rows of %d raw channels' % len(RAW_COLUMNS))
    return vector


def _motion_statistics(array):
    """mean, std, min, max of every column of a 2-D array, concatenated."""
    mean = array.mean(axis=0)
    centred = array - mean
    std = np.sqrt(np.einsum('ij,ij->j', centred, centred) / array.shape[0])
    return np.concatenate((mean, std, array.min(axis=0), array.max(axis=0)))


class FeatureWindow(object):
    """The feature window as a preallocated ring array: the fast path for the live node.

    ``add(stamp, row)`` then ``vector()`` gives the same vector as ``window_vector(rows, config)`` on the
    same rows (to rounding) without building an array from a list at every message. Rows are kept like
    WindowBuffer keeps them: the last ``count`` rows, or the rows no older than ``seconds`` before the
    newest. ``full`` follows WindowBuffer.feature_window_full (time since the first row after ``clear``).
    """

    def __init__(self, config, capacity=64):
        self.config = config
        self.span = config.span
        self._width = len(columns(config.feature_set))
        size = self.span.count if not self.span.is_duration else max(1, int(capacity))
        self._data = np.zeros((size, self._width))
        self._stamps = np.zeros(size)
        self.clear()

    def clear(self):
        """Drop every row."""
        self._start = 0   # index of the oldest row in the ring
        self._n = 0
        self._since = None

    def __len__(self):
        return self._n

    @property
    def full(self):
        """True once the window spans ``count`` rows or ``seconds`` since the first row after clear()."""
        if self._n == 0:
            return False
        if self.span.is_duration:
            return self._stamps[(self._start + self._n - 1) % len(self._stamps)] - self._since >= self.span.seconds
        return self._n >= self.span.count

    def add(self, stamp, row):
        """Append a row (newest) and drop the rows that left the window."""
        size = len(self._stamps)
        if self._since is None:
            self._since = stamp
        if self.span.is_duration:
            limit = stamp - self.span.seconds
            while self._n and self._stamps[self._start] < limit:
                self._start = (self._start + 1) % size
                self._n -= 1
            if self._n == size:
                self._grow()
                size = len(self._stamps)
        elif self._n == size:
            self._start = (self._start + 1) % size
            self._n -= 1
        index = (self._start + self._n) % size
        self._data[index] = row
        self._stamps[index] = stamp
        self._n += 1

    def _grow(self):
        order = (self._start + np.arange(self._n)) % len(self._stamps)
        data = np.zeros((2 * len(self._stamps), self._width))
        stamps = np.zeros(2 * len(self._stamps))
        data[:self._n] = self._data[order]
        stamps[:self._n] = self._stamps[order]
        self._data, self._stamps, self._start = data, stamps, 0

    def rows(self):
        """The rows, oldest first, as a 2-D array (a copy)."""
        order = (self._start + np.arange(self._n)) % len(self._stamps)
        return self._data[order]

    def vector(self):
        """The window vector of the rows held (ValueError when empty, or for raw when not full)."""
        if self._n == 0:
            raise ValueError('rows: the feature window is empty')
        if self.config.feature_set == 'motion':
            size = len(self._stamps)
            if self._start + self._n <= size:
                array = self._data[self._start:self._start + self._n]
            else:
                # statistics do not depend on row order: the ring's rows are the first n, wrapped or not
                array = self._data if self._n == size else self.rows()
            return _motion_statistics(array)
        return window_vector(list(self.rows()), self.config)
