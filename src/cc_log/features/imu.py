"""``imu``: shocks and vibration from sensor_msgs/Imu.

Per message: the body-frame linear acceleration and angular velocity with their magnitudes, and how fast
each changes (|d(acceleration)/dt|, the jerk of a shock; |d(angular velocity)/dt|). The orientation is not
used (it holds the heading). A window becomes the mean, std, min and max of every column: the std of the
accelerations is the vibration, the max jerk the hardest shock.
"""
import math
import struct

from cc_log.features.base import REPEAT, RESTART, FeatureSet, after_header, register, xyz

IMU_COLUMNS = ('acc_x', 'acc_y', 'acc_z', 'acc_norm', 'gyro_x', 'gyro_y', 'gyro_z', 'gyro_norm', 'jerk',
               'gyro_change')
IMU_MD5 = '6a62c6daae103f4ff57a132d6f95cec2'  # the sensor_msgs/Imu layout read_raw reads
_VECTOR3 = struct.Struct('<3d')
_GYRO_AFTER_HEADER = 4 * 8 + 9 * 8                # orientation, its covariance
_ACC_AFTER_HEADER = _GYRO_AFTER_HEADER + 3 * 8 + 9 * 8  # angular velocity, its covariance


def _norm(v):
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def _rate(now, before, inv):
    return math.sqrt((now[0] - before[0]) ** 2 + (now[1] - before[1]) ** 2 + (now[2] - before[2]) ** 2) * inv


@register
class ImuFeatures(FeatureSet):
    """Shocks and vibration of sensor_msgs/Imu (see the module docstring)."""

    name = 'imu'
    inputs = (('imu', 'sensor_msgs/Imu'),)
    columns = IMU_COLUMNS

    def reset_state(self):
        self._prev = None    # (acceleration, angular velocity) of the reference message
        self._deriv = (0.0, 0.0)

    raw_md5sums = frozenset([IMU_MD5])

    def read(self, msg):
        return xyz(msg.linear_acceleration) + xyz(msg.angular_velocity)

    def read_raw(self, buff):
        offset = after_header(buff)
        return _VECTOR3.unpack_from(buff, offset + _ACC_AFTER_HEADER) + \
            _VECTOR3.unpack_from(buff, offset + _GYRO_AFTER_HEADER)

    def make_row(self, stamp, values):
        acc, gyro = values[0:3], values[3:6]
        kind, dt = self._step(stamp)
        if kind == RESTART:
            self._deriv = (0.0, 0.0)
            self._prev = (acc, gyro)
        elif kind != REPEAT:
            inv = 1.0 / dt
            self._deriv = (_rate(acc, self._prev[0], inv), _rate(gyro, self._prev[1], inv))
            self._prev = (acc, gyro)
        return acc + (_norm(acc),) + gyro + (_norm(gyro),) + self._deriv
