"""``raw``: the CC-Log paper's features, for comparison.

The concatenation of position, orientation, linear and angular twist of the W messages of a count window
(nav_msgs/Odometry). It depends on where the robot is and which way it faces.
"""

from cc_log.features.base import register
from cc_log.features.motion import OdometrySet

RAW_COLUMNS = ('px', 'py', 'pz', 'qx', 'qy', 'qz', 'qw', 'vx', 'vy', 'vz', 'wx', 'wy', 'wz')


@register
class RawFeatures(OdometrySet):
    """The paper's concatenation of odometry messages (see the module docstring)."""

    name = 'raw'
    columns = RAW_COLUMNS
    ordered = True
    count_window = True

    def make_row(self, stamp, values):
        self._count(stamp)
        return values

    @classmethod
    def _count_of(cls, span):
        if span.is_duration:
            raise ValueError('window: the raw feature set needs a message count, not %s' % (span,))
        return span.count

    @classmethod
    def vector(cls, array, span):
        count = cls._count_of(span)
        if len(array) != count:
            raise ValueError('rows: the raw feature set needs exactly %d rows, got %d' % (count, len(array)))
        return array.reshape(-1).astype(float)

    @classmethod
    def vector_names(cls, span):
        return ['%s[%d]' % (name, i) for i in range(cls._count_of(span)) for name in RAW_COLUMNS]

    @classmethod
    def vector_length(cls, span):
        return cls._count_of(span) * len(RAW_COLUMNS)
