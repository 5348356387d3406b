"""``progress``: is the robot getting anywhere? From nav_msgs/Odometry, over the whole window.

Rows are the planar position, the forward speed, the yaw rate and the time step. A window (rows in order)
becomes: the net displacement, the path length, their ratio (near 1 driving somewhere, near 0 going back and
forth or standing), the total and the net rotation and the rotation while standing, how often the forward
speed and the yaw rate reverse (sign changes beyond a dead band), the mean and largest |speed| and
|yaw rate|, and the turn without progress beyond a half turn (below). Only differences of positions are used,
so the vector does not depend on where the robot is.

Oscillating without getting anywhere, the observable side of a planning failure, stands out from driving:
on the simulator every oscillation reverses the speed 3 or more times in 3 s, nominal driving at most once
(``test_features.py``). Spinning in place differs from driving, but over a few seconds it looks like a turn
towards a goal. What tells them apart: a turn towards a goal needs at most a half turn (pi) in place, a
spin keeps turning. Each row carries ``still_yaw``, the net yaw turned since the robot was last more than
``STILL_RADIUS`` from where it stood (a running sum kept across windows, so its horizon is not bounded by the
window); the vector's ``turn_beyond_half`` is how far the largest |still_yaw| of the window goes beyond
``HALF_TURN`` (pi + ``TURN_MARGIN``), in units of ``TURN_UNIT``. Nominal driving keeps it at 0 (on the
simulator the largest |still_yaw| of 130 nominal minutes is 3.13 rad), so any spin past a half turn lies far
from every training vector whatever the scaling.
"""
import math

import numpy as np

from cc_log.features.base import RESTART, STEP, register
from cc_log.features.motion import OdometrySet

PROGRESS_COLUMNS = ('x', 'y', 'v', 'w', 'dt', 'still_yaw')
PROGRESS_VECTOR = ('displacement', 'path_length', 'progress_ratio', 'rotation', 'net_rotation', 'rotation_in_place',
                   'speed_reversals', 'yaw_reversals', 'mean_speed', 'max_speed', 'mean_yaw_rate', 'max_yaw_rate',
                   'turn_beyond_half')
SPEED_DEAD_BAND = 0.05     # m/s: slower counts as standing (no sign)
YAW_DEAD_BAND = 0.1        # rad/s
RATIO_PATH = 0.1           # m added to the path length in progress_ratio (standing still gives 0, not 0/0)
STILL_RADIUS = 0.2         # m: moving farther than this from where the robot stood restarts still_yaw
TURN_MARGIN = 0.2          # rad beyond pi (controller overshoot, a curve right after a turn)
HALF_TURN = math.pi + TURN_MARGIN
TURN_UNIT = 0.01           # rad: turn_beyond_half counts these


def reversals(values, dead_band):
    """How often the sign of ``values`` changes, ignoring values within +-dead_band."""
    signs = np.sign(values[np.abs(values) > dead_band])
    return float(np.count_nonzero(signs[1:] != signs[:-1])) if len(signs) > 1 else 0.0


@register
class ProgressFeatures(OdometrySet):
    """Progress of the robot over the window (see the module docstring)."""

    name = 'progress'
    columns = PROGRESS_COLUMNS
    ordered = True

    def reset_state(self):
        self._anchor = None      # (x, y) where the robot stood when still_yaw restarted
        self._still_yaw = 0.0

    def make_row(self, stamp, values):
        kind, dt = self._step(stamp)
        dt = 0.0 if kind == RESTART else dt
        x, y, w = values[0], values[1], values[12]
        anchor = self._anchor
        if kind == RESTART or anchor is None or math.hypot(x - anchor[0], y - anchor[1]) > STILL_RADIUS:
            self._anchor, self._still_yaw = (x, y), 0.0
        elif kind == STEP:
            self._still_yaw += w * dt
        return (x, y, values[7], w, dt, self._still_yaw)

    @classmethod
    def vector(cls, array, span):
        steps = np.hypot(np.diff(array[:, 0]), np.diff(array[:, 1]))
        displacement = float(np.hypot(array[-1, 0] - array[0, 0], array[-1, 1] - array[0, 1]))
        path = float(steps.sum())
        v, w, dt = array[:, 2], array[:, 3], array[1:, 4]
        turned = w[1:] * dt
        speed, yaw_rate = np.abs(v), np.abs(w)
        standing = speed[1:] <= SPEED_DEAD_BAND
        return np.array([displacement, path, displacement / (path + RATIO_PATH), float(np.abs(turned).sum()),
                         abs(float(turned.sum())), float(np.abs(turned[standing]).sum()),
                         reversals(v, SPEED_DEAD_BAND), reversals(w, YAW_DEAD_BAND),
                         float(speed.mean()), float(speed.max()), float(yaw_rate.mean()), float(yaw_rate.max()),
                         max(0.0, float(np.abs(array[:, 5]).max()) - HALF_TURN) / TURN_UNIT])

    @classmethod
    def vector_names(cls, span):
        return list(PROGRESS_VECTOR)
