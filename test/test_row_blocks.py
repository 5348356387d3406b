"""``row_block`` of the odometry feature sets: a block of messages at once gives the very same floats (bit for bit),
``covers`` flags and state as ``row_values(_raw)`` message by message, on every real bag and on crafted blocks
with repeated stamps, gaps, backwards time, non-finite fields, bad quaternions, clipped and overflowing values,
cut messages and changing frame ids, wherever the blocks are cut."""
import math

import numpy as np
import pytest

from cc_log import features
from cc_log.base.raw_message import serialized
from cc_log.base import raw_message
from cc_log.features import FeatureConfig

bagio = pytest.importorskip('cc_log.storage.bag.bagio')  # needs rosbag (a sourced ROS environment)
from nav_msgs.msg import Odometry  # noqa: E402

STATE = ('_prev', '_deriv', '_prev_stamp', '_last_row', '_kind', '_dt', 'segment_start', 'segment_rows', 'restarts',
         'rejected')
BAGS = {  # every real bag with odometry: file -> topic
    'husky_outdoor_2015.bag': '/husky_velocity_controller/odom',
    'alfa_carbonZ_engine_failure.bag': '/mavros/local_position/odom',
    'f1tenth_DS1.bag': '/odom', 'f1tenth_DS2.bag': '/odom', 'f1tenth_DS3.bag': '/odom', 'f1tenth_DS4.bag': '/odom',
    'f1tenth_DS5.bag': '/odom',
    'icelab_normal_plan.bag': '/odom', 'icelab_window_plan.bag': '/odom',
    'socspioneer_trace0.bag': '/odom', 'socspioneer_trace1.bag': '/odom',
    'sequor_E2_normal_safe_escape_straight.bag': '/odom', 'sequor_N2_anomalous_jerky_driving.bag': '/odom',
    'sequor_N3_anomalous_crash_wall.bag': '/odom',
}


def state_of(feature):
    """The state a row depends on, as text that tells every float apart (repr: -0.0, nan)."""
    return {name: repr(getattr(feature, name, None)) for name in STATE}


def bits(rows):
    return np.ascontiguousarray(rows, dtype=float).view(np.int64)


class Counting(object):
    """Counts the messages a set computes one at a time (``row_values(_raw)`` calls)."""

    def __init__(self, feature):
        self.calls = 0
        for name in ('row_values', 'row_values_raw'):
            setattr(feature, name, self.counted(getattr(feature, name)))

    def counted(self, method):
        def call(*args):
            self.calls += 1
            return method(*args)
        return call


def compare(name, items, stamps, raw, cuts, window='20'):
    """Rows of ``items`` message by message against ``row_block`` over the blocks between ``cuts``; returns how
    many messages the block path computed one at a time."""
    config = FeatureConfig(name, window)
    one, block = features.get(name)(config), features.get(name)(config)
    counting = Counting(block)
    row_of = one.row_values_raw if raw else one.row_values
    expected, expected_covered, states = [], [], []
    for item, stamp in zip(items, stamps):
        expected.append(row_of(item, stamp))
        expected_covered.append(one.covers(config.span, stamp))
        states.append(state_of(one))
    bounds = [0] + sorted(cuts) + [len(items)]
    got, got_covered = [], []
    for start, end in zip(bounds[:-1], bounds[1:]):
        rows, covered = block.row_block(items[start:end], stamps[start:end], raw, config.span)
        assert rows.shape == (end - start, len(block.columns)) and covered.shape == (end - start,)
        got.append(rows)
        got_covered.extend(covered.tolist())
        if end > start:
            assert state_of(block) == states[end - 1], (name, start, end)
    assert (bits(np.concatenate(got)) == bits(expected)).all(), name
    assert got_covered == expected_covered
    return counting.calls


def odometry(p, q, v, w, frame='odom', child='base_link'):
    msg = Odometry()
    msg.header.frame_id, msg.child_frame_id = frame, child
    pose, twist = msg.pose.pose, msg.twist.twist
    pose.position.x, pose.position.y, pose.position.z = p
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = q
    twist.linear.x, twist.linear.y, twist.linear.z = v
    twist.angular.x, twist.angular.y, twist.angular.z = w
    return msg


def crafted(count=160, seed=3):
    """Odometry messages of a wobbly drive at 100 Hz (stamps, messages) with every irregularity the sets handle."""
    rng = np.random.default_rng(seed)
    stamps, msgs = [], []
    t, x, y, yaw = 100.0, 0.0, 0.0, 0.0
    for i in range(count):
        t += 0.01 + rng.normal(0, 0.002)
        speed, rate = 1.0 + rng.normal(0, 0.3), rng.normal(0, 0.5)
        yaw += rate * 0.01
        x, y = x + speed * math.cos(yaw) * 0.01, y + speed * math.sin(yaw) * 0.01
        roll, pitch = rng.normal(0, 0.05), rng.normal(0, 0.05)
        q = (math.sin(roll / 2), math.sin(pitch / 2), math.sin(yaw / 2), math.cos(yaw / 2))
        scale = 1.0 + rng.normal(0, 0.01)  # not quite unit length, as real quaternions
        stamps.append(t)
        msgs.append(odometry((x, y, rng.normal(0, 0.01)), tuple(c * scale for c in q),
                             (speed, rng.normal(0, 0.05), rng.normal(0, 0.02)), (0.0, 0.0, rate)))
    stamps[20:24] = [stamps[19]] * 4                 # repeated stamps (dt = 0)
    stamps[30] = stamps[29] + 5e-5                   # closer than min_dt
    stamps[40] = stamps[39] + 3.0                    # a gap: derivatives restart
    stamps[41:] = [s + 3.0 for s in stamps[41:]]
    stamps[50] = stamps[49] - 0.5                    # time going backwards
    msgs[60].twist.twist.linear.y = float('nan')     # non-finite fields
    msgs[61].pose.pose.position.x = float('inf')
    msgs[62].pose.pose.orientation = type(msgs[62].pose.pose.orientation)()  # zero quaternion
    msgs[70].pose.pose.orientation.w = 1e7            # a quaternion far too long
    msgs[80].twist.twist.linear.x = 5e6              # clipped values (speed, accelerations)
    msgs[90].pose.pose.position.y = 1e9              # a pose jump: clipped pose error, climb, energy
    msgs[100].twist.twist.linear.x = 1e200           # rows overflowing to inf (clipped) and nan (energy)
    msgs[101].twist.twist.linear.x = -1e200
    stamps[110] = float('nan')                       # a stamp that is no number
    msgs[120].header.frame_id = 'map'                # other frame id lengths: another layout
    msgs[121].header.frame_id, msgs[121].child_frame_id = 'odom_x', 'base_lin'  # same total length
    return stamps, msgs


@pytest.fixture(scope='module')
def crafted_raw():
    stamps, msgs = crafted()
    buffs = [serialized(msg) for msg in msgs]
    buffs[130] = buffs[130][:len(buffs[130]) // 2]   # a message cut off
    return stamps, buffs, msgs


@pytest.mark.parametrize('name', ['motion', 'dynamics', 'progress', 'command', 'raw'])
def test_crafted_blocks_cut_anywhere_give_the_rows_and_state_message_by_message(crafted_raw, name):
    stamps, buffs, msgs = crafted_raw
    every = range(0, len(buffs) + 1) if name == 'motion' else range(0, len(buffs) + 1, 7)
    for cut in every:
        compare(name, buffs, stamps, True, [cut])
    for seed in range(5):
        cuts = np.random.default_rng(seed).choice(len(buffs), size=8, replace=False).tolist()
        compare(name, buffs, stamps, True, cuts)
        compare(name, msgs, stamps, False, cuts, window='30' if features.get(name).count_window else '0.3s')


def test_a_whole_crafted_block_goes_mostly_at_once_and_counts_what_it_rejects(crafted_raw):
    stamps, buffs, _ = crafted_raw
    one_at_a_time = compare('motion', buffs, stamps, True, [])
    assert one_at_a_time < 60  # the irregular messages and the message before each run
    motion = features.get('motion')(FeatureConfig('motion', '20'))
    motion.row_block(buffs, stamps, True, '20')
    assert motion.rejected == 6 and motion.restarts == 3  # nan, inf, 2 bad quaternions, nan stamp, cut


def test_uniform_frame_ids_are_read_at_once_with_the_same_floats_as_one_by_one(crafted_raw):
    from cc_log.features.motion import read_odometry_block_raw, read_odometry_raw
    _, buffs, _ = crafted_raw
    for part in (buffs[:100], buffs[115:140], [b'\0' * 10, buffs[0]], []):
        values = read_odometry_block_raw(part)
        for row, buff in zip(values, part):
            try:
                expected = read_odometry_raw(buff)
            except Exception:
                assert np.isnan(row).all()
            else:
                assert bits(row).tolist() == bits(expected).tolist()


@pytest.mark.parametrize('bag', sorted(BAGS))
def test_real_bags_in_blocks_give_the_rows_message_by_message(real_bag, bag):
    records = list(bagio.read_raw(real_bag(bag), [BAGS[bag]]))
    buffs = [record.raw for record in records]
    stamps = [raw_message.stamp(record.raw, record.connection, record.stamp) for record in records]
    for window in ('20', '2s'):
        one_at_a_time = compare('motion', buffs, stamps, True, list(range(256, len(buffs), 256)), window)
    compare('motion', buffs, stamps, True, np.random.default_rng(7).choice(len(buffs), 30, False).tolist())
    if bag == 'husky_outdoor_2015.bag':
        assert one_at_a_time < len(buffs) // 10   # the block path really computes at once
        msgs = [raw_message.decoded(record).msg for record in records[:1000]]
        compare('motion', msgs, stamps[:1000], False, [100, 356, 612])
