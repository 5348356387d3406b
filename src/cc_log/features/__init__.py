"""What the classifiers see: messages -> feature rows -> one vector per feature window.

Feature sets (one module each, registered by name in ``base``):

- ``motion`` (default): body-frame motion of nav_msgs/Odometry, wherever the robot is;
- ``raw``: the CC-Log paper's concatenation of odometry messages (for comparison);
- ``imu``: shocks and vibration from sensor_msgs/Imu;
- ``command``: geometry_msgs/Twist commands against odometry (not following, stuck, slipping, overshooting);
- ``progress``: net displacement against path length and reversals over the window (odometry).

``FeatureConfig(feature_set, window)`` names a set and its window (stored in model and vector files);
``FeatureStream`` is the one step from messages to window vectors that every mode uses, ``FeatureWindow``
its ring array. How to add a set: docs/DESIGN.md.

Irregular time is expected: derivatives use the actual time step; a repeated stamp (or one closer than
``min_dt``) keeps the previous derivatives; time going backwards or a gap longer than ``max_dt`` restarts
the derivatives (they read 0 until the next message). A message with a non-finite field never raises: its
row repeats the last good row (zeros before any) and ``rejected`` counts it.

Pure Python plus numpy: no rospy.
"""
# Each module registers its feature set; the order is the registry's (motion, the default, first).
from cc_log.features import motion  # noqa: F401
from cc_log.features import raw  # noqa: F401
from cc_log.features import imu  # noqa: F401
from cc_log.features import command  # noqa: F401
from cc_log.features import progress  # noqa: F401
from cc_log.features import dynamics  # noqa: F401
from cc_log.features.base import (
    CLIP, DEFAULT_MAX_DT, DEFAULT_MIN_DT, DEFAULT_WINDOW, STATISTICS, WINDOW_RANGES, FeatureConfig, FeatureSet, get,
    names, register, stamp_of)
from cc_log.features.motion import MOTION_COLUMNS
from cc_log.features.raw import RAW_COLUMNS
from cc_log.features.window import (
    FeatureStream, FeatureWindow, columns, vector_length, vector_names, window_vector)

FEATURE_SETS = names()


def OdometryFeatures(config=None, **kwargs):
    """The row maker of ``config`` (default: ``FeatureConfig()``, motion) for a stream of messages."""
    config = config if config is not None else FeatureConfig()
    if not isinstance(config, FeatureConfig):
        raise ValueError('config: expected a FeatureConfig, got %s' % type(config).__name__)
    return config.feature(config, **kwargs)


__all__ = ['FEATURE_SETS', 'MOTION_COLUMNS', 'RAW_COLUMNS', 'STATISTICS', 'CLIP', 'DEFAULT_MAX_DT', 'DEFAULT_MIN_DT',
           'DEFAULT_WINDOW', 'WINDOW_RANGES',
           'FeatureConfig', 'FeatureSet', 'FeatureStream', 'FeatureWindow', 'OdometryFeatures',
           'columns', 'get', 'names', 'register', 'stamp_of', 'vector_length', 'vector_names', 'window_vector']
