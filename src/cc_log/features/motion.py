"""``motion`` (the default feature set): how the robot moves, from nav_msgs/Odometry, wherever it is.

Per message, quantities that do not depend on where the robot is or which way it faces: body-frame twist
(speeds, roll/pitch/yaw rates), speed, accelerations and jerk from twist differences over the real time
step, the pose-derived body velocity minus the reported twist (consistency: localization jumps, wheels
spinning while the pose stands still), the direction of "up" in the body frame (roll/pitch, never heading),
the climb rate and the specific mechanical power d(speed^2/2 + g z)/dt (a UAV losing an engine, a robot
hitting a wall). A window of rows becomes a fixed-length vector of per-channel summary statistics (mean,
std, min, max), whatever the number of rows.
"""
import math
import struct

import numpy as np

from cc_log.base.spans import Span
from cc_log.features.base import CLIP, REPEAT, RESTART, STEP, FeatureSet, after_header, after_string, register, xyz

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
ODOMETRY = 'nav_msgs/Odometry'
ODOMETRY_MD5 = 'cd5e73d190d741a2f92e81eda573aca7'  # the layout read_odometry_raw reads
_POSE = struct.Struct('<7d')    # geometry_msgs/Pose: position, orientation
_TWIST = struct.Struct('<6d')   # geometry_msgs/Twist: linear, angular
_TWIST_AFTER_POSE = 7 * 8 + 36 * 8  # the pose, then its covariance
MIN_BLOCK = 16  # messages: a smaller block goes message by message (numpy's fixed cost per block outweighs it)


def read_odometry(msg):
    """position (3), orientation (4), linear (3) and angular (3) twist of a nav_msgs/Odometry: 13 floats."""
    pose = msg.pose.pose
    twist = msg.twist.twist
    orientation = pose.orientation
    return xyz(pose.position) + (float(orientation.x), float(orientation.y), float(orientation.z),
                                 float(orientation.w)) + xyz(twist.linear) + xyz(twist.angular)


def read_odometry_raw(buff):
    """``read_odometry`` of a serialized nav_msgs/Odometry: after the header's and child_frame_id's variable
    strings, the pose and the twist lie at fixed offsets."""
    offset = after_string(buff, after_header(buff))
    return _POSE.unpack_from(buff, offset) + _TWIST.unpack_from(buff, offset + _TWIST_AFTER_POSE)


def unit_quaternion(q):
    """``q`` (x, y, z, w) normalised; None when it has (nearly) no length."""
    n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
    if not (1e-12 < n2 < 1e12):
        return None
    n = math.sqrt(n2)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


class OdometrySet(FeatureSet):
    """A feature set whose first input is nav_msgs/Odometry (``odom``): ``read`` takes all of a message (so a
    message with a broken field is rejected by every such set alike); ``pose_of(values)`` splits it."""

    inputs = (('odom', ODOMETRY),)
    raw_md5sums = frozenset([ODOMETRY_MD5])

    def read(self, msg):
        return read_odometry(msg)

    def read_raw(self, buff):
        return read_odometry_raw(buff)

    def read_block(self, items, raw):
        """``read`` (``read_raw`` when ``raw``) of every item: an (n, 13) float array, a row of NaN where an item
        cannot be read (its row is rejected as by ``row_values``)."""
        if raw:
            return read_odometry_block_raw(items)
        values = np.full((len(items), 13), np.nan)
        for i, msg in enumerate(items):
            try:
                values[i] = self.read(msg)
            except (AttributeError, TypeError, ValueError, OverflowError):
                pass
        return values

    @staticmethod
    def pose_of(values):
        """``(p, q, v, w)`` of ``read``'s values with q normalised, or None when q has (nearly) no length."""
        q = unit_quaternion(values[3:7])
        return None if q is None else (values[0:3], q, values[7:10], values[10:13])


@register
class MotionFeatures(OdometrySet):
    """Body-frame motion of nav_msgs/Odometry (see the module docstring)."""

    name = 'motion'
    columns = MOTION_COLUMNS

    def reset_state(self):
        self._prev = None        # (p, q, v, w, a) of the last accepted message
        self._deriv = None       # last derivative channels (held on a repeated stamp)

    def make_row(self, stamp, values):
        pose = self.pose_of(values)
        if pose is None:
            return None
        p, q, v, w = pose
        kind, dt = self._step(stamp)
        self._kind, self._dt = kind, dt   # the step of this message (sets built on motion read it)
        prev = self._prev
        if kind == RESTART:
            # First message, time going backwards, or a gap: derivatives restart.
            deriv = (0.0,) * 9
            self._prev = (p, q, v, w, None)
        elif kind == REPEAT:
            # Repeated stamp: keep the previous derivatives and the previous reference message.
            deriv = self._deriv
        else:
            p0, q0, v0, w0, a0 = prev
            deriv = step_channels(p0, q0, v0, a0, p, q, v, 1.0 / dt, math.sqrt)
            self._prev = (p, q, v, w, deriv[:3])
        self._deriv = deriv
        return motion_row(v, w, q, deriv, math.sqrt)

    def row_block(self, items, stamps, raw, span):
        """``FeatureSet.row_block`` with numpy: the messages of a block that are plain steps from the message
        before (both accepted, min_dt <= dt <= max_dt) are computed at once by the code ``make_row`` runs, the
        others (restarts, repeated stamps, rejected messages, rows that would not be finite) message by
        message, so rows, ``covers`` and the state afterwards are exactly those of ``row_values(_raw)``."""
        cls = type(self)
        if cls.make_row is not MotionFeatures.make_row or cls.read is not OdometrySet.read or \
                cls.read_raw is not OdometrySet.read_raw or len(items) < MIN_BLOCK:
            return FeatureSet.row_block(self, items, stamps, raw, span)
        try:
            times = np.array(stamps, dtype=float)
        except (TypeError, ValueError, OverflowError):
            return FeatureSet.row_block(self, items, stamps, raw, span)
        n = len(items)
        with np.errstate(all='ignore'):   # non-finite values are only flagged here; their rows go one by one
            cols = np.ascontiguousarray(self.read_block(items, raw).T)   # (13, n): one row per read value
            n2 = cols[3] * cols[3] + cols[4] * cols[4] + cols[5] * cols[5] + cols[6] * cols[6]
            ok = np.isfinite(cols).all(axis=0) & np.isfinite(times) & (n2 > 1e-12) & (n2 < 1e12)
            dt = times[1:] - times[:-1]
            step = ok[1:] & ok[:-1] & (dt >= self.min_dt) & (dt <= self.max_dt)
            slow = np.flatnonzero(~step) + 1    # the messages that are no plain step from the one before
            span = Span.parse(span, 'window')
            row_of = self.row_values_raw if raw else self.row_values
            rows = np.empty((n, len(self.columns)))
            covered = np.empty(n, dtype=bool)
            i = 0
            while i < n:
                rows[i] = row_of(items[i], stamps[i])
                covered[i] = self.covers(span, stamps[i])
                end = i + 1
                if ok[i] and self._kind != REPEAT:   # message i is the reference of the next step
                    later = np.searchsorted(slow, end)
                    end = int(slow[later]) if later < len(slow) else n
                    if end > i + 1:
                        end = self._steps(cols, n2, times, i, end, rows, covered, span)
                i = end
        return rows, covered

    def _steps(self, cols, n2, times, ref, end, rows, covered, span):
        """Rows ``ref + 1 .. end - 1`` of a run of plain steps (each from the message before, ``ref`` the
        reference in the state) into ``rows`` and ``covered``, the state after the last; stops before a row that
        would not be finite (message by message decides it). Returns the index after the last row made."""
        start = ref + 1
        quat = cols[3:7, ref:end] / np.sqrt(n2[ref:end])
        inv = 1.0 / (times[start:end] - times[ref:end - 1])
        cur, prev = cols[:, start:end], cols[:, ref:end - 1]
        p, v, w = tuple(cur[0:3]), tuple(cur[7:10]), tuple(cur[10:13])
        q, q0 = tuple(quat[:, 1:]), tuple(quat[:, :-1])
        # jerk needs the acceleration of the step before: the state's for the first, then the block's own
        accel = self._prev[4]
        a0 = np.empty((3, end - start))
        a0[:, 0] = (0.0, 0.0, 0.0) if accel is None else accel
        a0[:, 1:] = ((cur[7:10, :-1] - prev[7:10, :-1]) * inv[:-1])
        deriv = step_channels(tuple(prev[0:3]), q0, tuple(prev[7:10]), tuple(a0), p, q, v, inv, np.sqrt)
        if accel is None:
            deriv[3][0] = 0.0
        block = np.array(motion_row(v, w, q, deriv, np.sqrt)).T
        finite = np.isfinite(block).all(axis=1)
        if not finite.all():
            end = start + int(np.argmin(finite))
            if end == start:
                return start
            block, deriv = block[:end - start], tuple(column[:end - start] for column in deriv)
        self.out_of_range += int((np.abs(block) > CLIP).any(axis=1).sum())
        np.minimum(np.maximum(block, -CLIP), CLIP, out=rows[start:end])
        last = end - 1 - start
        self._prev = (tuple(cur[0:3, last].tolist()), tuple(quat[:, last + 1].tolist()),
                      tuple(cur[7:10, last].tolist()), tuple(cur[10:13, last].tolist()),
                      tuple(float(column[last]) for column in deriv[:3]))
        self._deriv = tuple(float(column[last]) for column in deriv)
        self._last_row = tuple(rows[end - 1].tolist())
        self._kind, self._dt = STEP, float(times[end - 1] - times[end - 2])
        self._prev_stamp = float(times[end - 1])
        before = self.segment_rows
        self.segment_rows += end - start
        if span.is_duration:
            covered[start:end] = times[start:end] - self.segment_start >= span.seconds
        else:
            covered[start:end] = before + np.arange(1, end - start + 1) >= span.count
        return end


def to_body(q, d):
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


def step_channels(p0, q0, v0, a0, p, q, v, inv, sqrt):
    """The derivative channels (ax ay az jerk pose_v*_err climb energy) of a step from the reference message
    (position ``p0``, unit quaternion ``q0``, twist ``v0``, acceleration ``a0``: None right after a restart)
    to ``(p, q, v)``, ``1 / inv`` seconds later.

    The same code serves one message (floats, ``math.sqrt``) and a block (tuples of numpy columns,
    ``np.sqrt``): the same IEEE operations in the same order, so the very same floats.
    """
    a = ((v[0] - v0[0]) * inv, (v[1] - v0[1]) * inv, (v[2] - v0[2]) * inv)
    if a0 is None:
        jerk = 0.0
    else:
        e0, e1, e2 = a[0] - a0[0], a[1] - a0[1], a[2] - a0[2]
        jerk = sqrt(e0 * e0 + e1 * e1 + e2 * e2) * inv
    # Pose-derived body velocity: world displacement rotated into the body frame by the mean of the
    # two orientations' inverse rotations, compared with the mean reported twist.
    d = ((p[0] - p0[0]) * inv, (p[1] - p0[1]) * inv, (p[2] - p0[2]) * inv)
    b1 = to_body(q0, d)
    b2 = to_body(q, d)
    pose_err = (0.5 * (b1[0] + b2[0] - v0[0] - v[0]),
                0.5 * (b1[1] + b2[1] - v0[1] - v[1]),
                0.5 * (b1[2] + b2[2] - v0[2] - v[2]))
    climb = d[2]
    speed0 = sqrt(v0[0] * v0[0] + v0[1] * v0[1] + v0[2] * v0[2])
    speed1 = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    energy = 0.5 * (speed1 * speed1 - speed0 * speed0) * inv + GRAVITY * climb
    return a + (jerk,) + pose_err + (climb, energy)


def motion_row(v, w, q, deriv, sqrt):
    """The motion row (before clipping) of twist ``v``, ``w``, unit quaternion ``q`` and the derivative
    channels ``deriv``: floats or numpy columns alike, as ``step_channels``."""
    x, y, z, qw = q
    up_x = 2.0 * (x * z - y * qw)
    up_y = 2.0 * (y * z + x * qw)
    speed = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return v + w + (speed,) + deriv[:7] + (up_x, up_y) + deriv[7:]


def read_odometry_block_raw(buffs):
    """``read_odometry_raw`` of every buffer of ``buffs``: an (n, 13) float array, a row of NaN where a buffer is
    too short. When every buffer has the same length and the same frame_id and child_frame_id lengths (the
    pose at the same offset), one strided view of the joined bytes reads them all."""
    values = np.full((len(buffs), 13), np.nan)
    if not buffs:
        return values
    first = buffs[0]
    size = len(first)
    try:
        child = after_header(first)
        offset = after_string(first, child)
    except struct.error:
        offset = size
    if offset + _TWIST_AFTER_POSE + _TWIST.size <= size and len(set(map(len, buffs))) == 1:
        joined = b''.join(buffs)
        table = np.frombuffer(joined, np.uint8).reshape(len(buffs), size)
        lengths = np.concatenate((table[:, 12:16], table[:, child:child + 4]), axis=1)
        if (lengths == lengths[0]).all():
            values[:, :7] = np.ndarray((len(buffs), 7), '<f8', joined, offset, (size, 8))
            values[:, 7:] = np.ndarray((len(buffs), 6), '<f8', joined, offset + _TWIST_AFTER_POSE, (size, 8))
            return values
    for i, buff in enumerate(buffs):
        try:
            values[i] = read_odometry_raw(buff)
        except struct.error:
            pass
    return values
