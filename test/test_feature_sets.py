"""The feature-set registry and the sets beyond odometry motion: imu, command, progress, dynamics (no roscore)."""
import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from cc_log import features, sim
from cc_log.learning import learning
from cc_log.features import FEATURE_SETS, FeatureConfig, FeatureStream, vector_length, vector_names, window_vector


def vec3(x=0.0, y=0.0, z=0.0):
    return NS(x=x, y=y, z=z)


def odom(x, y, yaw, v, w):
    """A planar nav_msgs/Odometry-shaped object (no header: the stamp is given)."""
    orientation = NS(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    return NS(pose=NS(pose=NS(position=vec3(x, y), orientation=orientation)),
              twist=NS(twist=NS(linear=vec3(v), angular=vec3(z=w))))


def twist(v, w):
    return NS(linear=vec3(v), angular=vec3(z=w))


def imu(acc, gyro):
    return NS(linear_acceleration=vec3(*acc), angular_velocity=vec3(*gyro))


def test_registry_names_every_set_and_refuses_unknown_ones():
    assert FEATURE_SETS == ('motion', 'raw', 'imu', 'command', 'progress', 'dynamics')
    for name in FEATURE_SETS:
        feature = features.get(name)
        assert feature.name == name and feature.inputs and feature.columns
        config = FeatureConfig(name, '10')
        assert config.topic_type == feature.inputs[0][1]
        assert len(vector_names(config)) == vector_length(config)
    assert features.get('command').inputs == (('odom', 'nav_msgs/Odometry'), ('cmd_vel', 'geometry_msgs/Twist'))
    with pytest.raises(ValueError,
                       match="^feature_set: 'pixels' is not one of motion, raw, imu, command, progress, dynamics$"):
        FeatureConfig('pixels', '10')
    with pytest.raises(ValueError, match='^topic_type: '):
        FeatureConfig('imu', '1s', 'nav_msgs/Odometry')
    with pytest.raises(ValueError, match='^window: the raw feature set needs a message count'):
        FeatureConfig('raw', '1s')


def test_old_model_configs_still_load():
    """Model and vector files written before the registry hold exactly these three fields."""
    for document in ({'feature_set': 'motion', 'window': '2s', 'topic_type': 'nav_msgs/Odometry'},
                     {'feature_set': 'raw', 'window': '250', 'topic_type': 'nav_msgs/Odometry'}):
        config = FeatureConfig.from_dict(document)
        assert config.to_dict() == document


@pytest.mark.parametrize('name', FEATURE_SETS)
def test_every_set_gives_finite_vectors_of_its_length_from_a_stream(name):
    config = FeatureConfig(name, '20')
    stream = FeatureStream(config, every=5)
    first, others = config.feature.inputs[0], config.feature.inputs[1:]
    vectors = []
    for i in range(200):
        stamp = 10.0 + 0.01 * i
        for role, _ in others:
            stream.observe(role, twist(0.5, 0.1), stamp)
        msg = imu((0.1 * math.sin(i), 0.0, 9.8), (0.0, 0.0, 0.1)) if first[1] == 'sensor_msgs/Imu' else \
            odom(0.005 * i, 0.0, 0.001 * i, 0.5, 0.1)
        vector = stream.add(msg, stamp)
        if vector is not None:
            vectors.append(vector)
    assert len(vectors) == len(range(19, 200, 5))  # the first at the 20th message, then every 5th
    assert all(v.shape == (vector_length(config),) and np.all(np.isfinite(v)) for v in vectors)


def test_imu_sees_shocks_and_vibration():
    config = FeatureConfig('imu', '1s')
    names = vector_names(config)
    rng = np.random.default_rng(0)

    def window(extra):
        stream, vector = FeatureStream(config), None
        for i in range(101):
            acc = rng.normal(0.0, 0.05, 3) + (0.0, 0.0, 9.81) + extra(i * 0.01)
            vector = stream.add(imu(acc, rng.normal(0.0, 0.005, 3)), i * 0.01)
        return vector

    quiet = window(lambda t: 0.0)
    shock = window(lambda t: (-25.0 if 0.5 <= t < 0.53 else 0.0, 0.0, 0.0))
    shaking = window(lambda t: (0.0, 0.0, 2.0 * math.sin(2 * math.pi * 23.0 * t)))
    assert shock[names.index('max(jerk)')] > 10 * quiet[names.index('max(jerk)')]
    assert shock[names.index('max(acc_norm)')] > 20.0 > quiet[names.index('max(acc_norm)')]
    assert shaking[names.index('std(acc_z)')] > 1.0 > 0.1 > quiet[names.index('std(acc_z)')]


def test_imu_separates_collisions_and_surges_from_driving_on_simulator_data():
    """Simulated BWIBot with its IMU: every collision and sudden acceleration has a 1 s window whose hardest
    jerk and acceleration spread are beyond every nominal window's."""
    config = sim.SimConfig(minutes=4, anomalies=4, anomaly_types=('collision', 'sudden_acceleration'), seed=2,
                           imu=True)
    simulator = sim.Simulator(config)
    feature = FeatureConfig('imu', '1s')
    stream = FeatureStream(feature, every=10)
    out = [(stamp, stream.add(msg, stamp)) for topic, stamp, msg in simulator.messages() if topic == sim.IMU_TOPIC]
    out = [(stamp, vector) for stamp, vector in out if vector is not None]
    truth = simulator.truth
    assert len(truth) == 4
    names = vector_names(feature)
    for name in ('max(jerk)', 'std(acc_x)'):
        index = names.index(name)
        nominal = max(v[index] for s, v in out if not any(e['start'] - 0.1 <= s <= e['end'] + 1.1 for e in truth))
        for entry in truth:
            assert max(v[index] for s, v in out if entry['start'] <= s <= entry['end'] + 1.0) > 1.5 * nominal, name


def command_run(stuck=None, seconds=60.0, seed=0):
    """(stamp, odometry, command) at 50 Hz: the robot follows varying commands with noise; between the
    ``stuck`` (start, end) seconds the commands go on but the robot does not move."""
    rng = np.random.default_rng(seed)
    x = y = yaw = v = w = 0.0
    out = []
    for i in range(int(seconds * 50)):
        t = i * 0.02
        cmd_v = 0.6 + 0.3 * math.sin(t / 3.0)
        cmd_w = 0.4 * math.sin(t / 2.0)
        blocked = stuck is not None and stuck[0] <= t < stuck[1]
        v = 0.0 if blocked else v + 0.2 * (cmd_v - v)
        w = 0.0 if blocked else w + 0.2 * (cmd_w - w)
        yaw += w * 0.02
        x += v * 0.02 * math.cos(yaw)
        y += v * 0.02 * math.sin(yaw)
        out.append((100.0 + t, odom(x, y, yaw, v + rng.normal(0, 0.01), w + rng.normal(0, 0.01)),
                    twist(cmd_v, cmd_w)))
    return out


def command_vectors(run, config, every=5):
    stream = FeatureStream(config, every=every)
    out = []
    for stamp, msg, command in run:
        stream.observe('cmd_vel', command, stamp - 0.005)
        vector = stream.add(msg, stamp)
        if vector is not None:
            out.append((stamp - 100.0, vector))
    return out


def test_command_flags_a_stuck_robot():
    """A model trained on a robot following its commands calls the windows where it is commanded to move and
    does not anomalous, and the windows of another nominal run not."""
    config = FeatureConfig('command', '1s')
    train = np.array([v for _, v in command_vectors(command_run(seed=1), config)])
    model, _ = learning.train(train, config=config)
    nominal = np.array([v for _, v in command_vectors(command_run(seconds=30.0, seed=2), config)])
    stuck = command_vectors(command_run(stuck=(20.0, 25.0), seconds=30.0, seed=3), config)
    inside = np.array([v for t, v in stuck if 21.0 <= t < 25.0])
    assert model.scores(inside).max() < model.threshold
    assert (model.scores(nominal) < model.threshold).mean() < 0.02
    names = vector_names(config)
    moving = nominal[10:]  # after the start from standing
    assert inside[:, names.index('min(lag_v)')].min() > 0.2 > moving[:, names.index('max(lag_v)')].max()


def test_command_sees_slipping_and_stale_commands():
    config = FeatureConfig('command', '10')
    names = vector_names(config)
    stream = FeatureStream(config)
    stream.observe('cmd_vel', twist(0.5, 0.0), 0.0)
    for i in range(11):  # the wheels report 0.5 m/s, the pose does not move (10 steps after the first)
        vector = stream.add(odom(0.0, 0.0, 0.0, 0.5, 0.0), 0.01 * (i + 1))
    assert vector[names.index('min(slip_v)')] == pytest.approx(0.5)
    assert vector[names.index('max(lag_v)')] == pytest.approx(0.0)
    vector = [stream.add(odom(0.0, 0.0, 0.0, 0.0, 0.0), 2.0 + 0.01 * i) for i in range(10)][-1]
    assert vector[names.index('max(cmd_v)')] == 0.0  # no command for 2 s: it no longer holds
    assert vector[names.index('min(cmd_age)')] == pytest.approx(2.0)


def test_progress_separates_oscillation_from_driving_on_simulator_data():
    """Simulated planning failures: every oscillation reverses the speed 3 or more times in a 3 s window,
    nominal driving (turns towards goals, stops, corners) at most once; a spin in place turns without
    getting anywhere."""
    config = sim.SimConfig(minutes=6, anomalies=6, anomaly_types=('planning_failure',), seed=3)
    simulator = sim.Simulator(config)
    feature = FeatureConfig('progress', '3s')
    stream = FeatureStream(feature, every=10)
    out = [(stamp, stream.add(msg, stamp)) for topic, stamp, msg in simulator.messages() if topic == sim.ODOM_TOPIC]
    out = [(stamp, vector) for stamp, vector in out if vector is not None]
    names = vector_names(feature)
    reversals, rotation, displacement = (names.index(name) for name in
                                         ('speed_reversals', 'rotation_in_place', 'displacement'))
    nominal = np.array([v for s, v in out if not any(e['start'] - 0.1 <= s <= e['end'] + 3.0
                                                     for e in simulator.truth)])
    assert len(nominal) > 1000 and nominal[:, reversals].max() <= 1
    kinds = []
    for entry in simulator.truth:
        inside = np.array([v for s, v in out if entry['start'] + 3.0 <= s <= entry['end']])
        if inside[:, reversals].max() >= 3:
            kinds.append('oscillate')
        else:
            kinds.append('spin')
            assert inside[:, rotation].max() > 2.0 and inside[:, displacement].min() < 0.05
    assert sorted(set(kinds)) == ['oscillate', 'spin']


def test_progress_vector_does_not_depend_on_where_the_robot_is():
    config = FeatureConfig('progress', '50')
    rows = [np.array([0.1 * i, 0.02 * i * i, 0.5, 0.2 * (-1) ** (i // 10), 0.02, 0.0]) for i in range(50)]
    shifted = [row + np.array([1000.0, -300.0, 0.0, 0.0, 0.0, 0.0]) for row in rows]
    assert np.allclose(window_vector(rows, config), window_vector(shifted, config))
    assert window_vector(rows, config)[vector_names(config).index('yaw_reversals')] == 4


def turn_beyond_half(steps, window='1s', rate=20.0):
    """The largest ``turn_beyond_half`` of a progress stream over planar moves ``steps`` [(v, w, seconds)]."""
    config = FeatureConfig('progress', window)
    stream, x, y, yaw, t, out = FeatureStream(config, every=1), 0.0, 0.0, 0.0, 0.0, [0.0]
    index = vector_names(config).index('turn_beyond_half')
    for v, w, seconds in steps:
        for _ in range(int(round(seconds * rate))):
            t, yaw = t + 1.0 / rate, yaw + w / rate
            x, y = x + v * math.cos(yaw) / rate, y + v * math.sin(yaw) / rate
            vector = stream.add(odom(x, y, yaw, v, w), t)
            if vector is not None:
                out.append(vector[index])
    return max(out)


def test_progress_tells_a_spin_from_a_half_turn_over_a_longer_horizon_than_the_window():
    """A half turn in place towards a goal (pi, at the simulator's 1 rad/s) and then driving stays at 0, even
    twice in a row with driving between; a spin of 1.5 turns at 0.7 rad/s does not, although a 1 s window never
    holds more than 0.7 rad of it (the row's still_yaw runs across windows); driving in circles is progress."""
    drive = (0.5, 0.0, 2.0)
    assert turn_beyond_half([drive, (0.0, 1.0, math.pi), drive, (0.0, -1.0, math.pi), drive]) == 0.0
    assert turn_beyond_half([(0.5, 0.5, 30.0)]) == 0.0
    spin = turn_beyond_half([drive, (0.0, 0.7, 3 * math.pi / 0.7), drive])
    assert spin == pytest.approx((3 * math.pi - math.pi - 0.2) / 0.01, rel=0.02)


def test_progress_flags_no_nominal_turn_and_every_spin_past_a_half_turn_on_the_simulator():
    """Simulated planning failures: spins in place go beyond a half turn within them; in the nominal driving
    around them (turns towards goals, dwells, corners) no window does. After a spin the value stays up until the
    robot has turned back towards its goal and driven off (STILL_RADIUS), then for the feature window: a tail of
    up to about 12 s after a 6 rad spin."""
    config = sim.SimConfig(minutes=6, anomalies=6, anomaly_types=('planning_failure',), seed=3)
    simulator = sim.Simulator(config)
    feature = FeatureConfig('progress', '5s')
    stream = FeatureStream(feature, every=10)
    index = vector_names(feature).index('turn_beyond_half')
    out = [(stamp, stream.add(msg, stamp)) for topic, stamp, msg in simulator.messages() if topic == sim.ODOM_TOPIC]
    out = [(stamp, vector[index]) for stamp, vector in out if vector is not None]
    nominal = [value for s, value in out if not any(e['start'] <= s <= e['end'] + 12.0 for e in simulator.truth)]
    assert len(nominal) > 1000 and max(nominal) == 0.0
    beyond = [max(value for s, value in out if e['start'] <= s <= e['end']) for e in simulator.truth]
    assert sum(value > 0 for value in beyond) >= 2, beyond


def test_command_catches_collisions_and_slipping_wheels_on_the_simulator_with_its_cmd_vel():
    """The simulated BWIBot publishes its planner's cmd_vel: a command model trained on two nominal runs (two
    wheel calibrations) flags nearly every window inside every collision and wheel slip of another run, and few
    windows of a third robot's nominal run."""
    config = FeatureConfig('command', '1s')

    def vectors(run, every):
        stream, out = FeatureStream(config, every=every), []
        for topic, stamp, msg in sim.Simulator(run).messages():
            if topic == sim.CMD_TOPIC:
                stream.observe('cmd_vel', msg, stamp)
            elif topic == sim.ODOM_TOPIC:
                vector = stream.add(msg, stamp)
                if vector is not None:
                    out.append((stamp, vector))
        return out
    train = np.array([v for seed in (11, 13) for _, v in
                      vectors(sim.SimConfig(minutes=4, anomalies=0, seed=seed, commands=True), 10)])
    model, _ = learning.train(train, config=config)
    nominal = np.array([v for _, v in vectors(sim.SimConfig(minutes=3, anomalies=0, seed=12, commands=True), 10)])
    assert (model.scores(nominal) < model.threshold).mean() < 0.03  # measured 0.013
    run = sim.SimConfig(minutes=4, anomalies=4, anomaly_types=('collision', 'wheels_slipping'), seed=5, commands=True)
    out = vectors(run, 5)
    truth = sim.Simulator(run)
    list(truth.messages())  # the same run again, for its ground truth
    assert sorted(e['type'] for e in truth.truth) == ['collision', 'collision', 'wheels_slipping', 'wheels_slipping']
    for entry in truth.truth:
        inside = np.array([v for s, v in out if entry['start'] <= s <= entry['end']])
        assert (model.scores(inside) < model.threshold).mean() > 0.9, entry['type']  # measured 0.97 at least


def dynamics_rows(turn=0.0, shift=(0.0, 0.0), speed=1.0, jump_at=None):
    """Rows of the dynamics set for a robot driving a circle of yaw rate 0.2 at ``speed``, the whole
    trajectory turned by ``turn`` and shifted by ``shift``; at message ``jump_at`` the pose jumps 1 m and
    0.3 rad and stays there."""
    feature = features.get('dynamics')(FeatureConfig('dynamics', '20'))
    x = y = 0.0
    yaw = turn
    rows = []
    for i in range(100):
        dx, dy, dyaw = (0.0, 0.0, 0.0) if jump_at is None or i < jump_at else (1.0, 0.0, 0.3)
        rows.append(feature.row(odom(x + shift[0] + dx, y + shift[1] + dy, yaw + dyaw, speed, 0.2), 10.0 + 0.1 * i))
        x, y, yaw = x + 0.1 * speed * math.cos(yaw), y + 0.1 * speed * math.sin(yaw), yaw + 0.02
    return np.array(rows)


def test_dynamics_does_not_see_where_the_robot_is_or_how_fast_it_drives_but_sees_a_pose_jump():
    names = features.get('dynamics').columns
    steady = dynamics_rows()
    assert np.allclose(steady, dynamics_rows(turn=2.0, shift=(1000.0, -300.0)), atol=1e-6)
    # steady driving at another speed: the same (near-zero) rows, where motion's speed channels would differ
    assert np.abs(steady[2:]).max() < 0.02 and np.abs(dynamics_rows(speed=3.0)[2:]).max() < 0.06
    jumped = dynamics_rows(jump_at=50)
    assert np.hypot(jumped[50, names.index('pose_vx_err')], jumped[50, names.index('pose_vy_err')]) > 5.0
    assert jumped[50, names.index('yaw_err')] > 2.5
    # after the jump the heading rate agrees again; the 0.3 rad heading offset stays as sideways pose motion
    assert np.abs(jumped[52:, names.index('yaw_err')]).max() < 1e-6
    assert jumped[52:, names.index('pose_vy_err')] == pytest.approx(-math.sin(0.3), abs=0.02)
