"""Hypothesis strategies of hostile live input (issue 42), for ``test_fuzz_live.py``: what the intake hands to
``SmartLogger.on_records``, and the triggers a logger runs.

- ``live_streams()``: batches of ``Record(stamp, topic, None, 0, raw, connection)``: nav_msgs/Odometry on the
  driving topic (smooth driving, then hostile values: NaN, infinities, 1e308, a zero quaternion; header stamps
  0, far ahead, backwards, repeated, nanoseconds past a second) and side topics of any name (legal and not),
  payloads up to 1 MB (arbitrary bytes, or valid messages), connection headers with odd types, md5sums and
  definitions (keys missing too), arrival stamps NaN, infinite, zero, negative, far ahead, backwards, repeated;
  bursts (one record repeated many times in a batch), many topics; between batches, manual trigger requests
  with any ``before``/``after``.
- ``trigger_sets()``: the names of the triggers a logger runs besides the manual one (``DRIVING``'s envelope,
  a classifier, ``when`` and ``arrival`` rules, a silence rule); ``make_triggers`` builds them.

Pure data (the triggers are built by ``make_triggers``); every payload is at most ``fs.MAX_INPUT_BYTES``.
"""
import functools
import math
import random

from hypothesis import strategies as st

import fuzz_strategies as fs

DRIVING = '/odom'
MAX_BATCHES = 12
MAX_BATCH = 400

_HOSTILE_FLOATS = [float('nan'), float('inf'), -float('inf'), 1e308, -1e308, 5e-324, 0.0, -0.0, 1e9]
_ARRIVALS_ODD = [float('nan'), float('inf'), -float('inf'), 0.0, -1.0, -1e9, 1e308, 4e9, 1e18]
_TOPICS = ['/camera/image_raw', '/scan', '/imu/data', '/tf', '/diagnostics', DRIVING, DRIVING + '/', '/odom ',
           '', ' ', '/', '//', 'a b', 'relative', '~private', '/a/../b', '/\x00', '/\n', '/\u202e', '/\U0001f600',
           '/' + 'a' * 1000, '/1abc', '/a-b', '/a.b']
_TYPES = ['std_msgs/String', 'sensor_msgs/Image', 'nav_msgs/Odometry', 'diagnostic_msgs/DiagnosticArray', '', 'a',
          'a/b/c', '/', 'x/Y', '../../etc/passwd', 'std_msgs/Strin', 'pkg/Type\n', '*']
_DEFINITIONS = ['', 'string data\n', 'int32 x\nfloat64[] y\n', 'Header header\nuint8[] data\n', 'garbage ;;; (',
                'string __import__("os").system("touch pwned");X=1\n', 'MSG: a/B\nint8 x\n', 'uint8[4294967295] x\n',
                'x' * 5000]


def _odometry_class():
    from nav_msgs.msg import Odometry
    return Odometry


@functools.lru_cache(maxsize=None)
def _real_connection(type_name):
    """The connection header a publisher of the installed ``type_name`` sends."""
    from cc_log.base.raw_message import installed_class
    cls = installed_class(type_name)
    return {'type': cls._type, 'md5sum': cls._md5sum, 'message_definition': cls._full_text,
            'callerid': '/robot', 'latching': '0'}


@st.composite
def connections(draw, type_name=None):
    """A connection header: a real publisher's (of ``type_name`` or another installed type), or with its type,
    md5sum, definition, latching and callerid replaced by odd values, or keys missing."""
    real = _real_connection(type_name or draw(st.sampled_from(['std_msgs/String', 'sensor_msgs/Image'])))
    how = draw(st.integers(0, 5))
    if how <= 1:
        return dict(real)
    connection = dict(real)
    for key in draw(st.lists(st.sampled_from(sorted(real)), min_size=1, max_size=5, unique=True)):
        if draw(st.integers(0, 5)) == 0:
            del connection[key]
        elif key == 'type':
            connection[key] = draw(st.one_of(st.sampled_from(_TYPES), st.text(max_size=30)))
        elif key == 'message_definition':
            connection[key] = draw(st.one_of(st.sampled_from(_DEFINITIONS), st.text(max_size=200)))
        elif key == 'md5sum':
            connection[key] = draw(st.sampled_from(['*', '', '0' * 32, 'z' * 32, 'a' * 1000, real['md5sum']]))
        else:
            connection[key] = draw(st.sampled_from(['0', '1', 'true', '', '\x00', '/x' * 200]))
    return connection


@st.composite
def payloads(draw):
    """Serialized bytes of a side message: a few arbitrary bytes, or up to 1 MB of random bytes."""
    if draw(st.integers(0, 2)):
        return draw(st.binary(max_size=64))
    size = draw(st.one_of(st.integers(0, 70000), st.sampled_from([65535, 65536, fs.MAX_INPUT_BYTES])))
    return random.Random(draw(st.integers(0, 2 ** 32))).randbytes(min(size, fs.MAX_INPUT_BYTES))


def _set_stamp(msg, secs, nsecs):
    msg.header.stamp.secs, msg.header.stamp.nsecs = secs % 2 ** 32, nsecs % 2 ** 32


def smooth_driving(count, start, step=0.02):
    """``count`` serialized Odometry records of smooth driving (nothing hostile) from ``start``."""
    from cc_log.base.raw_message import serialized
    from cc_log.base.records import Record
    Odometry = _odometry_class()
    records = []
    for i in range(count):
        t = start + step * (i + 1)
        msg = Odometry()
        msg.pose.pose.position.x, msg.twist.twist.linear.x, msg.pose.pose.orientation.w = 0.5 * step * i, 0.5, 1.0
        _set_stamp(msg, int(t), int((t % 1) * 1e9))
        records.append(Record(t, DRIVING, None, 0, serialized(msg), _real_connection('nav_msgs/Odometry')))
    return records


@st.composite
def driving_records(draw, count, start):
    """``count`` serialized Odometry records of smooth driving from ``start``, some values and stamps hostile."""
    from cc_log.base.raw_message import serialized
    from cc_log.base.records import Record
    Odometry = _odometry_class()
    connection = _real_connection('nav_msgs/Odometry')
    if draw(st.integers(0, 4)) == 0:
        connection = draw(connections('nav_msgs/Odometry'))
    odd = set(draw(st.lists(st.integers(0, max(0, count - 1)), max_size=max(1, count // 4))))
    records, t = [], start
    for i in range(count):
        t += 0.02
        msg = Odometry()
        msg.header.seq = i
        msg.header.frame_id = 'odom'
        x, speed = 0.5 * (t - start), 0.5 + 0.1 * math.sin(t)
        msg.pose.pose.position.x, msg.twist.twist.linear.x = x, speed
        msg.pose.pose.orientation.w = 1.0
        secs, nsecs = int(t), int((t % 1) * 1e9)
        arrival = t
        if i in odd:
            how = draw(st.integers(0, 6))
            if how == 0:
                value = draw(st.sampled_from(_HOSTILE_FLOATS))
                msg.twist.twist.linear.x = msg.pose.pose.position.x = msg.twist.twist.angular.z = value
            elif how == 1:
                msg.pose.pose.orientation.w = 0.0  # the zero quaternion
            elif how == 2:
                secs, nsecs = draw(st.sampled_from([(0, 0), (2 ** 32 - 1, 999999999), (secs - 1000, nsecs),
                                                    (secs, 2 ** 32 - 1), (secs + 86400 * 365, 0)]))
            elif how == 3:
                arrival = draw(st.sampled_from(_ARRIVALS_ODD))
            elif how == 4 and records:
                records.append(records[-1])  # repeated
                continue
            elif how == 5:
                t -= draw(st.sampled_from([0.02, 1.0, 30.0, 1e6]))  # backwards
            else:
                msg.pose.pose.position.x = draw(st.floats(allow_nan=True, allow_infinity=True))
        _set_stamp(msg, secs, nsecs)
        records.append(Record(arrival, DRIVING, None, 0, serialized(msg), connection))
    return records


@st.composite
def side_records(draw, stamps):
    """Records of side topics (any names, payloads, connections) at arrival ``stamps``; bursts repeat one."""
    from cc_log.base.records import Record
    publishers = [(draw(st.one_of(st.sampled_from(_TOPICS), fs.names(), st.text(max_size=20))),
                   draw(connections())) for _ in range(draw(st.integers(1, 6)))]
    if draw(st.integers(0, 5)) == 0:  # many topics
        publishers += [('/many/t%d' % i, publishers[0][1]) for i in range(draw(st.integers(50, 400)))]
    records = []
    for stamp in stamps:
        topic, connection = publishers[draw(st.integers(0, len(publishers) - 1))]
        record = Record(stamp, topic, None, 0, draw(payloads()), connection)
        records.extend([record] * (draw(st.integers(2, 300)) if draw(st.integers(0, 9)) == 0 else 1))
    return records


@st.composite
def live_streams(draw):
    """A list of steps: ``('records', [Record])`` batches (driving and side records in arrival order), and
    ``('manual', before, after)`` requests between them."""
    count = draw(st.integers(1, 600))
    driving = draw(driving_records(count, draw(st.sampled_from([1432235498.0, 0.0, 1e9]))))
    arrivals = [record.stamp for record in driving[::max(1, len(driving) // 30)]]
    side = draw(side_records([stamp + draw(st.sampled_from([0.0, 0.001, -5.0, 100.0])) for stamp in arrivals]))
    merged, i, j = [], 0, 0
    while i < len(driving) or j < len(side):  # interleaved, each in its own order
        if j >= len(side) or (i < len(driving) and draw(st.integers(0, 3))):
            merged.append(driving[i])
            i += 1
        else:
            merged.append(side[j])
            j += 1
    steps, start = [], 0
    while start < len(merged):
        size = draw(st.integers(1, MAX_BATCH))
        steps.append(('records', merged[start:start + size]))
        start += size
        if draw(st.integers(0, 4)) == 0:
            span = st.one_of(st.none(), st.sampled_from(_HOSTILE_FLOATS + [-1.0, 2.0, 1e6]), fs.scalars)
            steps.append(('manual', draw(span), draw(span)))
    return steps[:MAX_BATCHES * 2]


def trigger_sets():
    """The names of the triggers a logger runs (its manual one besides)."""
    return st.lists(st.sampled_from(['envelope', 'classifier', 'when', 'arrival', 'silent']), unique=True,
                    max_size=5)


@functools.lru_cache(maxsize=None)
def _envelope():
    """An envelope learned on synthetic driving (test_envelope's helpers)."""
    import test_envelope
    return test_envelope.learned(test_envelope.nominal_drive(seconds=60.0))


def make_triggers(names):
    """New triggers of these names (``trigger_sets``), on ``DRIVING`` and a side topic."""
    from cc_log.learning.model import AnomalyModel
    from cc_log.triggers import ClassifierTrigger
    from cc_log.triggers.envelope import EnvelopeTrigger
    from cc_log.triggers.rule import RuleTrigger
    made = {
        'envelope': lambda: EnvelopeTrigger('envelope', _envelope(), DRIVING),
        'classifier': lambda: ClassifierTrigger('classifier', AnomalyModel.from_dict(fs.valid_model()), [DRIVING],
                                                classify_every='1'),
        'when': lambda: RuleTrigger('fast', DRIVING, when='twist.twist.linear.x > 2.0', type='nav_msgs/Odometry'),
        'arrival': lambda: RuleTrigger('bump', '/scan', arrival=True),
        'silent': lambda: RuleTrigger('quiet', '/imu/data', silent='1s'),
    }
    return [made[name]() for name in names]
