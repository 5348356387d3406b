"""The simulator's ROS messages: topics, frames, stamps, and odometry and IMU serialized by hand.

The simulator (``world``) yields an odometry or IMU reading as an item, a cheap tuple
``(ODOM_ITEM or IMU_ITEM, genpy.Time stamp, seq, values)``; every other message is a ROS message already.
``message(item)`` builds the ROS message, ``serialized(item)`` writes the same bytes genpy would without
building it (what ``bags.simulate_to_bag`` stores).
"""
import io
import math
import struct

import genpy
from actionlib_msgs.msg import GoalID, GoalStatus, GoalStatusArray
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Imu

ODOM_TOPIC = '/odom'
IMU_TOPIC = '/imu/data'
CMD_TOPIC = '/cmd_vel'
STATUS_TOPIC = '/move_base/status'
TRUTH_TOPIC = '/sim/anomaly'
ACTIVE, SUCCEEDED, ABORTED = 1, 3, 4  # actionlib_msgs/GoalStatus values used
ODOM_FRAME = 'odom'
BASE_FRAME = 'base_link'
IMU_FRAME = 'imu_link'
ODOM_ITEM, IMU_ITEM = 'odom', 'imu'   # the kinds of items


def ros_time(seconds):
    """genpy.Time at whole nanoseconds, and the float it stands for (so stamps compare exactly)."""
    nanos = int(round(seconds * 1e9))
    stamp = genpy.Time(nanos // 1000000000, nanos % 1000000000)
    return stamp, stamp.to_sec()


def yaw_of(q):
    """The yaw (rad) of a quaternion."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _diagonal(*variances):
    """A row-major covariance matrix (tuple) with ``variances`` on its diagonal."""
    n = len(variances)
    return tuple(variances[i // n] if i // n == i % n else 0.0 for i in range(n * n))


_POSE_COVARIANCE = _diagonal(1e-3, 1e-3, 1e6, 1e6, 1e6, 0.03)   # x, y, z, roll, pitch, yaw
_TWIST_COVARIANCE = _diagonal(1e-3, 1e-3, 1e6, 1e6, 1e6, 0.03)
_IMU_ORIENTATION_COVARIANCE = _diagonal(2.5e-3, 2.5e-3, 1e-2)
_IMU_GYRO_COVARIANCE = _diagonal(2.5e-5, 2.5e-5, 2.5e-5)
_IMU_ACCEL_COVARIANCE = _diagonal(2.5e-3, 2.5e-3, 2.5e-3)
_POSE_COVARIANCE_BYTES = struct.pack('<36d', *_POSE_COVARIANCE)
_TWIST_COVARIANCE_BYTES = struct.pack('<36d', *_TWIST_COVARIANCE)
_IMU_ORIENTATION_COVARIANCE_BYTES = struct.pack('<9d', *_IMU_ORIENTATION_COVARIANCE)
_IMU_GYRO_COVARIANCE_BYTES = struct.pack('<9d', *_IMU_GYRO_COVARIANCE)
_IMU_ACCEL_COVARIANCE_BYTES = struct.pack('<9d', *_IMU_ACCEL_COVARIANCE)


def twist(v, w):
    """A geometry_msgs/Twist driving at ``v`` m/s and turning at ``w`` rad/s."""
    msg = Twist()
    msg.linear.x = v
    msg.angular.z = w
    return msg


def _odometry(stamp, seq, x, y, yaw, v, w):
    msg = Odometry()
    msg.header.seq = seq
    msg.header.stamp = stamp
    msg.header.frame_id = ODOM_FRAME
    msg.child_frame_id = BASE_FRAME
    msg.pose.pose.position.x = x
    msg.pose.pose.position.y = y
    msg.pose.pose.orientation.z = math.sin(yaw / 2.0)
    msg.pose.pose.orientation.w = math.cos(yaw / 2.0)
    msg.pose.covariance = _POSE_COVARIANCE
    msg.twist.twist.linear.x = v
    msg.twist.twist.angular.z = w
    msg.twist.covariance = _TWIST_COVARIANCE
    return msg


_HEADER = struct.Struct('<3I')
_ODOM_POSE = struct.Struct('<7d')
_ODOM_TWIST = struct.Struct('<6d')
_IMU_ORIENTATION = struct.Struct('<4d')
_VECTOR = struct.Struct('<3d')


def _string_bytes(text):
    data = text.encode('utf-8')
    return struct.pack('<I', len(data)) + data


_ODOM_FRAMES = _string_bytes(ODOM_FRAME) + _string_bytes(BASE_FRAME)
_IMU_FRAME_BYTES = _string_bytes(IMU_FRAME)


def message(item):
    """The ROS message of a simulator item."""
    if not isinstance(item, tuple):
        return item
    kind, stamp, seq, values = item
    if kind == ODOM_ITEM:
        return _odometry(stamp, seq, *values)
    qz, qw, gx, gy, gz, ax, ay, az = values
    msg = Imu()
    msg.header.seq = seq
    msg.header.stamp = stamp
    msg.header.frame_id = IMU_FRAME
    msg.orientation.z, msg.orientation.w = qz, qw
    msg.orientation_covariance = _IMU_ORIENTATION_COVARIANCE
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = gx, gy, gz
    msg.angular_velocity_covariance = _IMU_GYRO_COVARIANCE
    msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = ax, ay, az
    msg.linear_acceleration_covariance = _IMU_ACCEL_COVARIANCE
    return msg


def serialized(item):
    """The serialized bytes of a simulator item: the same bytes genpy writes for ``message(item)``."""
    if not isinstance(item, tuple):
        buffer = io.BytesIO()
        item.serialize(buffer)
        return buffer.getvalue()
    kind, stamp, seq, values = item
    header = _HEADER.pack(seq & 0xffffffff, stamp.secs, stamp.nsecs)
    if kind == ODOM_ITEM:
        x, y, yaw, v, w = values
        return b''.join((header, _ODOM_FRAMES,
                         _ODOM_POSE.pack(x, y, 0.0, 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)),
                         _POSE_COVARIANCE_BYTES, _ODOM_TWIST.pack(v, 0.0, 0.0, 0.0, 0.0, w),
                         _TWIST_COVARIANCE_BYTES))
    qz, qw, gx, gy, gz, ax, ay, az = values
    return b''.join((header, _IMU_FRAME_BYTES, _IMU_ORIENTATION.pack(0.0, 0.0, qz, qw),
                     _IMU_ORIENTATION_COVARIANCE_BYTES, _VECTOR.pack(gx, gy, gz), _IMU_GYRO_COVARIANCE_BYTES,
                     _VECTOR.pack(ax, ay, az), _IMU_ACCEL_COVARIANCE_BYTES))


def goal_status(stamp, goal, status):
    """The move_base-like status (actionlib_msgs/GoalStatusArray) of goal number ``goal``."""
    array = GoalStatusArray()
    array.header.stamp = stamp
    array.status_list = [GoalStatus(goal_id=GoalID(id='goal_%d' % goal), status=status)]
    return array
