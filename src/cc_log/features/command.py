"""``command``: what the robot is told to do (geometry_msgs/Twist on ``cmd_vel``) against what it does
(nav_msgs/Odometry): not following commands, stuck, slipping, overshooting.

Rows are made on odometry messages with the newest command; a command older than ``COMMAND_TIMEOUT``
counts as zero (base controllers stop the robot then). Per row: the commanded forward speed and yaw rate,
the reported ones, how far the robot falls short of the command (``lag_v``, ``lag_w``: not following,
stuck) and goes beyond it (``over_v``, ``over_w``: overshooting, running away), the reported forward speed
minus the speed the pose actually moved at (``slip_v``: wheels turning on the spot) and the age of the
command. A window becomes the mean, std, min and max of every column.
"""
import struct

from cc_log.features.base import REPEAT, RESTART, register
from cc_log.features.motion import ODOMETRY_MD5, OdometrySet, to_body

COMMAND_COLUMNS = ('cmd_v', 'cmd_w', 'v', 'w', 'v_err', 'w_err', 'lag_v', 'lag_w', 'over_v', 'over_w', 'slip_v',
                   'cmd_age')
COMMAND_TIMEOUT = 0.5  # seconds after which a command no longer holds
MAX_AGE = 10.0         # seconds: cmd_age is capped here (also before the first command)
TWIST_MD5 = '9f195f881246fdfa2798d1d3eebca84a'  # the geometry_msgs/Twist layout observe_raw reads
_DOUBLE = struct.Struct('<d')
_ANGULAR_Z = 5 * 8     # linear x, y, z, angular x, y before it


@register
class CommandFeatures(OdometrySet):
    """Velocity command against odometry (see the module docstring)."""

    name = 'command'
    inputs = OdometrySet.inputs + (('cmd_vel', 'geometry_msgs/Twist'),)
    columns = COMMAND_COLUMNS
    raw_md5sums = frozenset([ODOMETRY_MD5, TWIST_MD5])

    def reset_state(self):
        self._command = None  # (stamp, v, w) of the newest command
        self._prev = None     # position of the reference odometry message
        self._slip = 0.0

    def observe(self, role, msg, stamp):
        if role != 'cmd_vel':
            return
        try:
            v, w = float(msg.linear.x), float(msg.angular.z)
        except (AttributeError, TypeError, ValueError, OverflowError):
            self.rejected += 1
            return
        self._command_at(stamp, v, w)

    def observe_raw(self, role, buff, stamp):
        if role != 'cmd_vel':
            return
        try:
            v, w = _DOUBLE.unpack_from(buff, 0)[0], _DOUBLE.unpack_from(buff, _ANGULAR_Z)[0]
        except struct.error:
            self.rejected += 1
            return
        self._command_at(stamp, v, w)

    def _command_at(self, stamp, v, w):
        try:
            stamp = float(stamp)
        except (TypeError, ValueError, OverflowError):
            self.rejected += 1
            return
        if (v + w + stamp) * 0.0 != 0.0:
            self.rejected += 1
            return
        self._command = (stamp, v, w)

    def make_row(self, stamp, values):
        pose = self.pose_of(values)
        if pose is None:
            return None
        p, q, v, w = pose[0], pose[1], pose[2][0], pose[3][2]
        kind, dt = self._step(stamp)
        if kind == RESTART:
            self._slip = 0.0
            self._prev = p
        elif kind != REPEAT:
            moved = to_body(q, ((p[0] - self._prev[0]) / dt, (p[1] - self._prev[1]) / dt,
                                (p[2] - self._prev[2]) / dt))
            self._slip = v - moved[0]
            self._prev = p
        cmd_v = cmd_w = 0.0
        age = MAX_AGE
        if self._command is not None:
            age = min(MAX_AGE, max(0.0, stamp - self._command[0]))
            if age <= COMMAND_TIMEOUT:
                cmd_v, cmd_w = self._command[1], self._command[2]
        lag_v, lag_w = abs(cmd_v) - abs(v), abs(cmd_w) - abs(w)
        return (cmd_v, cmd_w, v, w, v - cmd_v, w - cmd_w, max(0.0, lag_v), max(0.0, lag_w), max(0.0, -lag_v),
                max(0.0, -lag_w), self._slip, age)
