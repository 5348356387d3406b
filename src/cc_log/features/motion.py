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

from .base import REPEAT, RESTART, FeatureSet, after_header, after_string, register, xyz

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
            inv = 1.0 / dt
            a = ((v[0] - v0[0]) * inv, (v[1] - v0[1]) * inv, (v[2] - v0[2]) * inv)
            if a0 is None:
                jerk = 0.0
            else:
                jerk = math.sqrt((a[0] - a0[0]) ** 2 + (a[1] - a0[1]) ** 2 + (a[2] - a0[2]) ** 2) * inv
            # Pose-derived body velocity: world displacement rotated into the body frame by the mean of the
            # two orientations' inverse rotations, compared with the mean reported twist.
            d = ((p[0] - p0[0]) * inv, (p[1] - p0[1]) * inv, (p[2] - p0[2]) * inv)
            b1 = to_body(q0, d)
            b2 = to_body(q, d)
            pose_err = (0.5 * (b1[0] + b2[0] - v0[0] - v[0]),
                        0.5 * (b1[1] + b2[1] - v0[1] - v[1]),
                        0.5 * (b1[2] + b2[2] - v0[2] - v[2]))
            climb = d[2]
            speed0 = math.sqrt(v0[0] * v0[0] + v0[1] * v0[1] + v0[2] * v0[2])
            speed1 = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            energy = 0.5 * (speed1 * speed1 - speed0 * speed0) * inv + GRAVITY * climb
            deriv = a + (jerk,) + pose_err + (climb, energy)
            self._prev = (p, q, v, w, a)
        self._deriv = deriv
        x, y, z, qw = q
        up_x = 2.0 * (x * z - y * qw)
        up_y = 2.0 * (y * z + x * qw)
        speed = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        return v + w + (speed,) + deriv[:7] + (up_x, up_y) + deriv[7:]


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
