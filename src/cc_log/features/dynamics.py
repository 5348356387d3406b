"""``dynamics``: how the robot's motion changes and whether pose and twist agree, never how fast it drives.

Every channel of ``motion`` that is a level of the trajectory (speeds, yaw rate, tilt, climb rate, power) makes
a new lap, another speed or another turn look new to a model trained on a short part of a run. The channels
here are zero or small in steady driving at any speed and heading, and large when the motion is physically
abrupt or inconsistent, which is what the simulator's anomaly types are:

- ``ax ay az``, ``jerk``: twist differences over the real dt (collision, sudden acceleration);
- ``yaw_acc``: d(yaw rate)/dt (excessive twisting, planning failures starting a spin or reversing);
- ``pose_vx_err pose_vy_err pose_vz_err``: body velocity from pose differences minus the reported twist
  (localization jumps, wheels slipping);
- ``yaw_err``: the heading rate from orientation differences minus the reported yaw rate (a jump of the
  pose's heading).

A window becomes the mean, std, min and max of every channel, as for ``motion``.
"""
import math

from cc_log.features.base import REPEAT, RESTART, register
from cc_log.features.motion import MotionFeatures

DYNAMICS_COLUMNS = ('ax', 'ay', 'az', 'jerk', 'yaw_acc', 'pose_vx_err', 'pose_vy_err', 'pose_vz_err', 'yaw_err')
_FROM_MOTION = (7, 8, 9, 10, 11, 12, 13)   # ax ay az jerk pose_v*_err in motion's row


def _yaw(q):
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


@register
class DynamicsFeatures(MotionFeatures):
    """Changes of motion and pose-twist consistency of nav_msgs/Odometry (see the module docstring)."""

    name = 'dynamics'
    columns = DYNAMICS_COLUMNS

    def reset_state(self):
        MotionFeatures.reset_state(self)
        self._ref = None          # (yaw, yaw rate) of the reference message
        self._own = (0.0, 0.0)    # last (yaw_acc, yaw_err), held on a repeated stamp

    def make_row(self, stamp, values):
        row = MotionFeatures.make_row(self, stamp, values)
        if row is None:
            return None
        yaw, rate = _yaw(self.pose_of(values)[1]), values[12]
        if self._kind == RESTART:
            self._own = (0.0, 0.0)
            self._ref = (yaw, rate)
        elif self._kind != REPEAT:
            yaw0, rate0 = self._ref
            inv = 1.0 / self._dt
            turned = math.atan2(math.sin(yaw - yaw0), math.cos(yaw - yaw0))
            self._own = ((rate - rate0) * inv, turned * inv - 0.5 * (rate + rate0))
            self._ref = (yaw, rate)
        return tuple(row[i] for i in _FROM_MOTION[:4]) + self._own[:1] + \
            tuple(row[i] for i in _FROM_MOTION[4:]) + self._own[1:]
