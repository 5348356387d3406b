"""``progress``: is the robot getting anywhere? From nav_msgs/Odometry, over the whole window.

Rows are the planar position, the forward speed, the yaw rate and the time step. A window (rows in order)
becomes: the net displacement, the path length, their ratio (near 1 driving somewhere, near 0 going back and
forth or standing), the total and the net rotation and the rotation while standing, how often the forward
speed and the yaw rate reverse (sign changes beyond a dead band), and the mean and largest |speed| and
|yaw rate|. Only differences of positions are used, so the vector does not depend on where the robot is.

Oscillating without getting anywhere, the observable side of a planning failure, stands out from driving:
on the simulator every oscillation reverses the speed 3 or more times in 3 s, nominal driving at most once
(``test_features.py``). Spinning in place differs from driving, but over a few seconds it looks like a turn
towards a goal; only a window longer than such turns tells them apart by ``rotation_in_place``.
"""
import numpy as np

from .base import RESTART, register
from .motion import OdometrySet

PROGRESS_COLUMNS = ('x', 'y', 'v', 'w', 'dt')
PROGRESS_VECTOR = ('displacement', 'path_length', 'progress_ratio', 'rotation', 'net_rotation', 'rotation_in_place',
                   'speed_reversals', 'yaw_reversals', 'mean_speed', 'max_speed', 'mean_yaw_rate', 'max_yaw_rate')
SPEED_DEAD_BAND = 0.05     # m/s: slower counts as standing (no sign)
YAW_DEAD_BAND = 0.1        # rad/s
RATIO_PATH = 0.1           # m added to the path length in progress_ratio (standing still gives 0, not 0/0)


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

    def make_row(self, stamp, values):
        kind, dt = self._step(stamp)
        return (values[0], values[1], values[7], values[12], 0.0 if kind == RESTART else dt)

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
                         float(speed.mean()), float(speed.max()), float(yaw_rate.mean()), float(yaw_rate.max())])

    @classmethod
    def vector_names(cls, span):
        return list(PROGRESS_VECTOR)
