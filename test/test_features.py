"""Features: invariance to where the robot is and which way it faces, irregular time, bad input."""
import math
import time
from types import SimpleNamespace as NS

import numpy as np
import pytest

from cc_log.features import (
    FEATURE_SETS, MOTION_COLUMNS, RAW_COLUMNS, FeatureConfig, FeatureWindow, OdometryFeatures, get, stamp_of,
    vector_length, vector_names, window_vector)
from cc_log.base.spans import Span

rosbag = pytest.importorskip('rosbag')


def odom(p, q, v, w, stamp=None):
    """A nav_msgs/Odometry-shaped object."""
    header = NS(stamp=NS(secs=int(stamp), nsecs=int(round((stamp - int(stamp)) * 1e9)))) if stamp else NS(
        stamp=NS(secs=0, nsecs=0))
    return NS(header=header,
              pose=NS(pose=NS(position=NS(x=p[0], y=p[1], z=p[2]),
                              orientation=NS(x=q[0], y=q[1], z=q[2], w=q[3]))),
              twist=NS(twist=NS(linear=NS(x=v[0], y=v[1], z=v[2]), angular=NS(x=w[0], y=w[1], z=w[2]))))


def trajectory(path, topic, limit=800):
    """(stamp, p, q, v, w) tuples of a real bag's odometry."""
    out = []
    with rosbag.Bag(path) as bag:
        for _, msg, t in bag.read_messages(topics=[topic]):
            pose, twist = msg.pose.pose, msg.twist.twist
            out.append((stamp_of(msg, t.to_sec()),
                        (pose.position.x, pose.position.y, pose.position.z),
                        (pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w),
                        (twist.linear.x, twist.linear.y, twist.linear.z),
                        (twist.angular.x, twist.angular.y, twist.angular.z)))
            if len(out) >= limit:
                break
    return out


def qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def moved(traj, yaw, shift):
    """The same motion elsewhere: positions rotated by ``yaw`` about z and shifted, orientations rotated,
    body-frame twist unchanged."""
    c, s = math.cos(yaw), math.sin(yaw)
    qz = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    out = []
    for stamp, p, q, v, w in traj:
        p2 = (c * p[0] - s * p[1] + shift[0], s * p[0] + c * p[1] + shift[1], p[2] + shift[2])
        out.append((stamp, p2, qmul(qz, q), v, w))
    return out


def rows_of(traj, config):
    features = OdometryFeatures(config)
    return [features.row(odom(p, q, v, w, stamp), stamp) for stamp, p, q, v, w in traj]


@pytest.mark.parametrize('name,topic', [
    ('husky_outdoor_2015.bag', '/husky_velocity_controller/odom'),
    ('alfa_carbonZ_engine_failure.bag', '/mavros/local_position/odom'),
])
def test_motion_features_ignore_position_and_heading(real_bag, name, topic):
    traj = trajectory(real_bag(name), topic)
    config = FeatureConfig('motion', '50')
    original = rows_of(traj, config)
    for yaw, shift in ((2.1, (1000.0, -250.0, 3.0)), (-0.7, (-40.0, 7.5, 0.0)), (math.pi, (0.0, 0.0, 0.0))):
        other = rows_of(moved(traj, yaw, shift), config)
        assert np.allclose(np.array(original), np.array(other), rtol=1e-7, atol=1e-6)
        for end in (50, 300, len(traj)):
            assert np.allclose(window_vector(original[end - 50:end], config),
                               window_vector(other[end - 50:end], config), rtol=1e-7, atol=1e-6)
    # the raw features of the paper do depend on position: the check above could fail
    raw = FeatureConfig('raw', '50')
    assert not np.allclose(np.array(rows_of(traj, raw)), np.array(rows_of(moved(traj, 2.1, (1000.0, 0, 0)), raw)))


def test_motion_rows_see_jumps_spinning_wheels_climbing_and_braking():
    config = FeatureConfig()
    features = OdometryFeatures(config)
    q = (0.0, 0.0, math.sin(0.3), math.cos(0.3))
    heading = (math.cos(0.6), math.sin(0.6), 0.0)
    rows = []
    for i in range(20):
        p = (heading[0] * 0.1 * i, heading[1] * 0.1 * i, 0.0)
        rows.append(features.row(odom(p, q, (1.0, 0, 0), (0, 0, 0)), 10.0 + 0.1 * i))
    err = [MOTION_COLUMNS.index(c) for c in ('pose_vx_err', 'pose_vy_err', 'pose_vz_err')]
    assert np.abs(np.array(rows)[1:, err]).max() < 1e-9   # consistent pose and twist
    # wheels spinning (twist 1 m/s) while the pose stands still
    spin = features.row(odom(p, q, (1.0, 0, 0), (0, 0, 0)), 12.0)
    assert spin[err[0]] == pytest.approx(-1.0, abs=1e-9)
    # localization jump of 5 m sideways in 0.1 s
    jump = features.row(odom((p[0] - 5 * heading[1], p[1] + 5 * heading[0], 0.0), q, (1.0, 0, 0), (0, 0, 0)), 12.1)
    assert jump[err[1]] == pytest.approx(50.0, rel=1e-6)
    # climbing 0.2 m in 0.1 s at 1 m/s: climb rate 2 m/s, specific power g * 2 (speed unchanged)
    row = features.row(odom((p[0] - 5 * heading[1], p[1] + 5 * heading[0], 0.2), q, (1.0, 0, 0), (0, 0, 0)), 12.2)
    assert row[MOTION_COLUMNS.index('climb_rate')] == pytest.approx(2.0, rel=1e-6)
    assert row[MOTION_COLUMNS.index('energy_rate')] == pytest.approx(9.81 * 2.0, rel=1e-6)
    # braking from 1 m/s to 0 in 0.1 s: -10 m/s^2, specific power -(1/2) / 0.1 = -5 W/kg
    row = features.row(odom((p[0] - 5 * heading[1], p[1] + 5 * heading[0], 0.2), q, (0.0, 0, 0), (0, 0, 0)), 12.3)
    assert row[MOTION_COLUMNS.index('ax')] == pytest.approx(-10.0, rel=1e-6)
    assert row[MOTION_COLUMNS.index('energy_rate')] == pytest.approx(-5.0, rel=1e-6)


def test_irregular_time_gives_finite_rows_without_spikes():
    features = OdometryFeatures(FeatureConfig())
    stamps = [100.0, 100.01, 100.01, 100.01, 100.0200001, 99.5, 99.51, 99.52, 99.52 + 3 * 3600, 99.53 + 3 * 3600,
              99.53 + 3 * 3600 + 1e-7, 99.54 + 3 * 3600, 99.53 + 3 * 3600, 99.56 + 3 * 3600]
    glitch = {2, 3, 10}             # repeated (or 0.1 us later) stamps carrying another speed
    rows = []
    for i, stamp in enumerate(stamps):
        v = 1.0 + (stamp - 99.0) % 3600 + (0.5 if i in glitch else 0.0)   # 1 m/s^2 between gaps
        rows.append(features.row(odom((i * 0.01, 0, 0), (0, 0, 0, 1), (v, 0, 0), (0, 0, 0.1)), stamp))
    rows = np.array(rows)
    assert np.all(np.isfinite(rows))
    ax = rows[:, MOTION_COLUMNS.index('ax')]
    jerk = rows[:, MOTION_COLUMNS.index('jerk')]
    assert np.abs(ax).max() <= 1.0 + 1e-6       # never dv / (tiny dt)
    assert np.abs(jerk).max() <= 200.0
    assert ax[8] == 0.0 and ax[5] == 0.0        # after the 3 h gap and after time went backwards
    assert features.restarts >= 4               # first, backwards, gap, backwards again
    assert features.rejected == 0


ODOMETRY_SETS = [name for name in FEATURE_SETS if get(name).inputs[0][1] == 'nav_msgs/Odometry']


@pytest.mark.parametrize('feature_set', ODOMETRY_SETS)
def test_non_finite_input_gives_finite_row_and_counts(feature_set):
    config = FeatureConfig(feature_set, '10')
    features = OdometryFeatures(config)
    assert np.all(features.row(odom((math.nan, 0, 0), (0, 0, 0, 1), (1, 0, 0), (0, 0, 0)), 1.0) == 0)
    good = features.row(odom((0, 0, 0), (0, 0, 0, 1), (1, 0, 0), (0, 0, 0)), 1.1)
    bad_inputs = [
        odom((0, 0, 0), (0, 0, 0, 1), (math.inf, 0, 0), (0, 0, 0)),
        odom((0, 0, 0), (0, 0, math.nan, 1), (1, 0, 0), (0, 0, 0)),
        odom((0, 0, 0), (0, 0, 0, 1), (1, 0, 0), (0, 0, -math.inf)),
        odom((0, 0, 0), (0, 0, 0, 1), (None, 0, 0), (0, 0, 0)),
        NS(header=None),
    ]
    for msg in bad_inputs:
        row = features.row(msg, 1.2)
        assert np.all(np.isfinite(row)) and np.array_equal(row, good)
    assert np.all(np.isfinite(features.row(odom((0, 0, 0), (0, 0, 0, 1), (1, 0, 0), (0, 0, 0)), math.nan)))
    assert features.rejected == 1 + len(bad_inputs) + 1
    if feature_set == 'motion':
        # a zero quaternion cannot be normalised: rejected too; huge finite values are clipped
        features.row(odom((0, 0, 0), (0, 0, 0, 0), (1, 0, 0), (0, 0, 0)), 1.3)
        assert features.rejected == 1 + len(bad_inputs) + 2
        huge = features.row(odom((1e300, 0, 0), (0, 0, 0, 1), (1e300, 0, 0), (0, 0, 0)), 1.4)
        assert np.all(np.isfinite(huge)) and np.abs(huge).max() <= 1e6
        assert np.all(np.isfinite(window_vector([huge, good, huge], config)))


@pytest.mark.parametrize('value', [1e200, 1e155, -1e300])
def test_values_beyond_any_physical_range_give_clipped_finite_rows_counted_out_of_range(value):
    """linear.x = 1e200 for 5 s: its square overflows (inf - inf in the energy is NaN); every row is finite, at
    the clip, and counted, message by message and in a block alike, and a window holding one is out of range."""
    from cc_log.features.base import CLIP, out_of_range
    config = FeatureConfig('motion', '10')
    stamps = [100.0 + k / 50.0 for k in range(300)]
    msgs = [odom((0.5 * t, 0, 0), (0, 0, 0, 1), (value if 102.0 <= t < 107.0 else 0.5, 0, 0), (0, 0, 0), t)
            for t in stamps]
    one, block = get('motion')(config), get('motion')(config)
    rows = np.array([one.row_values(msg, t) for msg, t in zip(msgs, stamps)])
    blocked, _ = block.row_block(msgs, stamps, False, config.window)
    assert np.array_equal(rows, blocked) and np.all(np.isfinite(rows)) and np.abs(rows).max() == CLIP
    beyond = np.array([102.0 <= t < 107.0 + 0.03 for t in stamps])  # the derivatives see the end two rows later
    assert [bool(np.abs(row).max() >= CLIP) for row in rows] == list(beyond)
    assert one.out_of_range == block.out_of_range == beyond.sum() and one.rejected == block.rejected == 0
    assert out_of_range(rows[95:105]) and not out_of_range(rows[:100]) and not out_of_range(rows[:0])
    assert np.all(np.isfinite(window_vector(rows[95:105], config)))


def test_window_vector_lengths_and_names():
    motion = FeatureConfig('motion', '5s')
    rng = np.random.default_rng(1)
    for n in (1, 2, 37, 500):
        vector = window_vector(list(rng.normal(size=(n, len(MOTION_COLUMNS)))), motion)
        assert vector.shape == (vector_length(motion),) == (len(vector_names(motion)),)
    rows = [np.array([1.0] * len(MOTION_COLUMNS)), np.array([3.0] * len(MOTION_COLUMNS))]
    vector = window_vector(rows, motion)
    names = vector_names(motion)
    assert vector[names.index('mean(vx)')] == 2.0 and vector[names.index('std(vx)')] == 1.0
    assert vector[names.index('min(vx)')] == 1.0 and vector[names.index('max(vx)')] == 3.0
    raw = FeatureConfig('raw', '3')
    rows = [np.arange(13.0) + 100 * i for i in range(3)]
    assert np.array_equal(window_vector(rows, raw), np.concatenate(rows))
    assert vector_names(raw)[:2] == ['px[0]', 'py[0]'] and len(vector_names(raw)) == 39
    with pytest.raises(ValueError):
        window_vector(rows[:2], raw)
    with pytest.raises(ValueError):
        window_vector([], motion)
    with pytest.raises(ValueError, match='window'):
        window_vector(rows, FeatureConfig('raw', '3')._replace(window='5s'))


def test_feature_window_ring_matches_window_vector():
    rng = np.random.default_rng(2)
    rows = list(rng.normal(size=(730, len(MOTION_COLUMNS))))
    stamps = 10.0 + 0.0137 * np.arange(730) + rng.uniform(0, 0.005, 730)
    for window in ('100', '1.5s'):
        config = FeatureConfig('motion', window)
        ring = FeatureWindow(config, capacity=4)
        held = []
        for stamp, row in zip(stamps, rows):
            ring.add(stamp, row)
            held.append((stamp, row))
            if config.span.is_duration:
                held = [(s, r) for s, r in held if s >= stamp - config.span.seconds]
            else:
                held = held[-config.span.count:]
            assert len(ring) == len(held)
            assert np.allclose(ring.vector(), window_vector([r for _, r in held], config), rtol=1e-9, atol=1e-12)
        assert ring.full
    raw = FeatureConfig('raw', '4')
    ring = FeatureWindow(raw)
    for i in range(6):
        ring.add(float(i), np.full(len(RAW_COLUMNS), float(i)))
    assert np.array_equal(ring.vector()[::len(RAW_COLUMNS)], [2.0, 3.0, 4.0, 5.0])


def test_feature_window_by_count_and_duration():
    width = len(MOTION_COLUMNS)
    window = FeatureWindow(FeatureConfig('motion', '3'))
    for i in range(5):
        window.add(float(i), np.full(width, float(i)))
        assert window.full == (i >= 2)
    assert list(window.rows()[:, 0]) == [2, 3, 4]
    window = FeatureWindow(FeatureConfig('motion', '1s'))
    for i in range(5):
        window.add(i * 0.4, np.full(width, float(i)))
    assert list(window.rows()[:, 0]) == [2, 3, 4]  # 0.8 .. 1.6 s
    assert window.full


def test_duration_feature_window_refills_after_a_gap():
    width = len(MOTION_COLUMNS)
    window = FeatureWindow(FeatureConfig('motion', '1s'))
    for stamp in (0.0, 0.5, 1.0, 3600.0, 3600.5):
        window.add(stamp, np.full(width, stamp))
    assert list(window.rows()[:, 0]) == [3600.0, 3600.5]
    assert not window.full
    window.add(3601.0, np.full(width, 3601.0))
    assert window.full


def test_feature_config_round_trip_and_validation():
    config = FeatureConfig('motion', '5000ms', 'nav_msgs/Odometry')
    assert config.window == '5s' and config.span == Span.duration(5.0)
    assert FeatureConfig.from_dict(config.to_dict()) == config
    assert FeatureConfig() == FeatureConfig('motion', '2s', 'nav_msgs/Odometry')  # a duration: any rate
    for bad in ({'feature_set': 'motion'}, {'feature_set': 'fancy', 'window': '5s', 'topic_type': 'nav_msgs/Odometry'},
                {'feature_set': 'motion', 'window': 'soon', 'topic_type': 'nav_msgs/Odometry'},
                {'feature_set': 'motion', 'window': '0', 'topic_type': 'nav_msgs/Odometry'},
                {'feature_set': 'motion', 'window': 5, 'topic_type': 'nav_msgs/Odometry'},
                {'feature_set': 'motion', 'window': '5s', 'topic_type': 'sensor_msgs/Imu'},
                {'feature_set': 'raw', 'window': '5s', 'topic_type': 'nav_msgs/Odometry'},
                {'feature_set': 'motion', 'window': '5s', 'topic_type': 'nav_msgs/Odometry', 'x': '1'}, []):
        with pytest.raises(ValueError):
            FeatureConfig.from_dict(bad)


def test_stamp_of():
    assert stamp_of(odom((0, 0, 0), (0, 0, 0, 1), (0, 0, 0), (0, 0, 0), 12.5), 99.0) == pytest.approx(12.5)
    assert stamp_of(odom((0, 0, 0), (0, 0, 0, 1), (0, 0, 0), (0, 0, 0)), 99.0) == 99.0
    assert stamp_of(NS(data=1), 7) == 7.0
    assert stamp_of(NS(data=1), NS(to_sec=lambda: 3.5)) == 3.5


def test_cost_per_message(real_bag):
    """row + FeatureWindow.add + vector at 500 rows: well under the 300 us a 3% budget at 100 Hz allows."""
    traj = trajectory(real_bag('husky_outdoor_2015.bag'), '/husky_velocity_controller/odom', 1500)
    msgs = [(odom(p, q, v, w, stamp), stamp) for stamp, p, q, v, w in traj]
    config = FeatureConfig('motion', '500')
    features, ring = OdometryFeatures(config), FeatureWindow(config)
    started = time.perf_counter()
    for msg, stamp in msgs:
        ring.add(stamp, features.row(msg, stamp))
        ring.vector()
    per_message = (time.perf_counter() - started) / len(msgs)
    assert per_message < 600e-6   # generous for a loaded CI machine; measured ~120 us (docs/DETECTION.md)
