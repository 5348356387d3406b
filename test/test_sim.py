"""The simulated BWIBot (cc_log.sim): determinism, nominal limits, anomaly signatures, bags, injection."""
import hashlib
import json
import math
import os
import subprocess
import sys
import time

import pytest

from cc_log import sim
from cc_log.base.raw_message import serialized
from cc_log.base.records import Record
from cc_log.sim import kinematics, messages

HUSKY_ODOM = '/husky_velocity_controller/odom'
LIMITS = sim.BWIBOT_LIMITS


# ---------------------------------------------------------------------------------------------------------
# helpers


class Track(object):
    """Odometry as columns: t, x, y, yaw (unwrapped), v, w."""

    def __init__(self, msgs_with_stamps):
        self.t, self.x, self.y, self.yaw, self.v, self.w = [], [], [], [], [], []
        for stamp, msg in msgs_with_stamps:
            self.t.append(stamp)
            self.x.append(msg.pose.pose.position.x)
            self.y.append(msg.pose.pose.position.y)
            yaw = messages.yaw_of(msg.pose.pose.orientation)
            if self.yaw:
                yaw = self.yaw[-1] + kinematics.wrap(yaw - self.yaw[-1])
            self.yaw.append(yaw)
            self.v.append(msg.twist.twist.linear.x)
            self.w.append(msg.twist.twist.angular.z)
        steps = sorted(b - a for a, b in zip(self.t, self.t[1:]))
        self.rate = 1.0 / steps[len(steps) // 2]

    def __len__(self):
        return len(self.t)

    def indices(self, start, end):
        return [i for i in range(len(self.t)) if start <= self.t[i] <= end]

    def moved(self, i):
        """Distance the pose moved from message i-1 to i."""
        return math.hypot(self.x[i] - self.x[i - 1], self.y[i] - self.y[i - 1])

    def derivative(self, values, span):
        """[(index, d values / dt over `span` seconds of moving averages of `span` seconds)]."""
        n = max(1, int(round(span * self.rate)))
        prefix = [0.0]
        for value in values:
            prefix.append(prefix[-1] + value)
        mean = [(prefix[i + n] - prefix[i]) / n for i in range(len(values) - n + 1)]
        return [(i + n, (mean[i + n] - mean[i]) / (self.t[i + n] - self.t[i])) for i in range(len(mean) - n)]


def inside(stamp, truth, pad=0.0):
    return any(entry['start'] - pad <= stamp <= entry['end'] + pad for entry in truth)


def sim_track(config):
    """Run a simulator; return (track, truth, all items, true positions)."""
    simulator = sim.Simulator(config)
    items, positions = [], []
    while not simulator.done:
        items.extend(simulator.step())
        positions.append((simulator.x, simulator.y))
    track = Track((stamp, msg) for topic, stamp, msg in items if topic == sim.ODOM_TOPIC)
    return track, simulator.truth, items, positions


def longest(track, indices, ok):
    """Longest stretch (seconds) of consecutive messages among `indices` for which ok(i) holds."""
    best, begin = 0.0, None
    for i in indices:
        if ok(i):
            begin = i if begin is None else begin
            best = max(best, track.t[i] - track.t[begin])
        else:
            begin = None
    return best


def check_signature(track, entry, limits=LIMITS):
    """Assert that the anomaly `entry` shows its signature in `track` between its start and end."""
    kind = entry['type']
    idx = track.indices(entry['start'], entry['end'])
    assert len(idx) >= 3, entry
    k = max(1, int(round(0.05 * track.rate)))                 # raw derivative over ~50 ms (1 sample at 10 Hz)
    accel = [(track.v[i + k] - track.v[i]) / (track.t[i + k] - track.t[i]) for i in idx[:-k]]
    yaw_accel = [(track.w[i + k] - track.w[i]) / (track.t[i + k] - track.t[i]) for i in idx[:-k]]
    window = track.rate * 4.0
    if kind == 'collision':
        assert track.v[idx[0]] > 0.3, 'collision while not driving'
        assert min(accel) < -5.0 * limits.max_decel, 'no deceleration spike: %.2f' % min(accel)
        assert longest(track, idx, lambda i: abs(track.v[i]) < 0.05 and track.moved(i) < 0.002) >= 1.9
    elif kind == 'planning_failure':
        # somewhere in the window, 4 s of going nowhere while turning (spinning or oscillating)
        found = False
        for a in idx:
            b = a + int(window)
            if b > idx[-1]:
                break
            net = math.hypot(track.x[b] - track.x[a], track.y[b] - track.y[a])
            turned = sum(abs(track.w[i]) / track.rate for i in range(a, b))
            if net < 1.0 and turned > 1.5:
                found = True
                break
        assert found, 'no 4 s of turning without progress'
    elif kind == 'sudden_acceleration':
        assert max(track.v[i] for i in idx) > 1.25 * limits.max_speed
        assert max(accel) > 3.0 * limits.max_accel, 'no acceleration spike: %.2f' % max(accel)
    elif kind == 'excessive_twisting':
        assert max(abs(track.w[i]) for i in idx) > 1.4 * limits.max_yaw_rate
        assert max(abs(a) for a in yaw_accel) > 2.5 * limits.max_yaw_accel
        # the yaw rate swings to and fro (beyond +-0.5 rad/s around its value at the start) several times
        sides = [1 if track.w[i] - track.w[idx[0]] > 0.5 else -1 for i in idx
                 if abs(track.w[i] - track.w[idx[0]]) > 0.5]
        swings = sum(1 for a, b in zip(sides, sides[1:]) if a != b)
        assert swings >= 6, 'the yaw rate does not oscillate (%d swings)' % swings
    elif kind == 'localization_jump':
        jumps = [track.moved(i) - abs(track.v[i]) * (track.t[i] - track.t[i - 1]) for i in idx[1:]]
        assert max(jumps) > 0.4, 'no pose jump: %.3f m' % max(jumps)
        assert max(abs(a) for a in accel) < 3.0 * limits.max_decel + 1.0, 'the twist is not smooth'
    elif kind == 'wheels_slipping':
        assert longest(track, idx[1:], lambda i: track.moved(i) < 1e-9 and abs(track.v[i]) > 0.2) >= 1.9, \
            'no stretch of wheels turning with the pose frozen'
    else:
        raise AssertionError(kind)


def check_nominal(track, truth, limits=LIMITS, pad=0.3):
    """Outside the anomalies: limits hold, the pose follows the twist."""
    out = [i for i in range(1, len(track)) if not inside(track.t[i], truth, pad)]
    assert len(out) > 0.5 * len(track)
    assert max(abs(track.v[i]) for i in out) <= limits.max_speed * 1.05 + 0.02
    assert max(abs(track.w[i]) for i in out) <= limits.max_yaw_rate * 1.05 + 0.04
    accel = [a for i, a in track.derivative(track.v, 0.1) if not inside(track.t[i], truth, pad + 0.2)]
    assert -limits.max_decel - 0.15 <= min(accel) and max(accel) <= limits.max_accel + 0.15
    yaw_accel = [a for i, a in track.derivative(track.w, 0.1) if not inside(track.t[i], truth, pad + 0.2)]
    assert max(abs(a) for a in yaw_accel) <= limits.max_yaw_accel + 0.35
    for i in out:
        dt = track.t[i] - track.t[i - 1]
        assert abs(track.moved(i) - abs(track.v[i]) * (1.0 / track.rate)) < 0.005 + 0.3 * abs(track.v[i]) * dt, i
        assert abs(track.yaw[i] - track.yaw[i - 1]) < 0.02 + 1.5 * abs(track.w[i]) / track.rate


# ---------------------------------------------------------------------------------------------------------
# fixtures

@pytest.fixture(scope='module', params=[0, 3])
def ten_minutes(request):
    """A default 10-minute run with IMU and the six anomalies."""
    config = sim.SimConfig(seed=request.param, imu=True)
    return (config,) + sim_track(config)


@pytest.fixture(scope='module')
def husky_records():
    import rosbag
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..', 'shared', 'data',
                        'real', 'husky_outdoor_2015.bag')
    if not os.path.exists(path):
        pytest.fail('real data missing: %s (tests read ../shared/data/real/)' % path)
    records = []
    with rosbag.Bag(path) as bag:
        for topic, msg, t in bag.read_messages():
            header = getattr(msg, 'header', None)
            stamp = header.stamp.to_sec() if header is not None and header.stamp.to_sec() else t.to_sec()
            records.append(Record(stamp, topic, msg))
    records.sort(key=lambda record: record.stamp)
    return records


def test_real_bag_fixture_agrees(real_bag, husky_records):
    assert os.path.samefile(real_bag('husky_outdoor_2015.bag'), os.path.join(
        os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..', 'shared', 'data', 'real',
        'husky_outdoor_2015.bag'))
    assert sum(1 for r in husky_records if r.topic == HUSKY_ODOM) == 3952


# ---------------------------------------------------------------------------------------------------------
# the module

def test_core_imports_neither_rospy_nor_rosbag():
    code = 'import sys, cc_log.sim; sys.exit(1 if {"rospy", "rosbag"} & set(sys.modules) else 0)'
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    assert subprocess.call([sys.executable, '-c', code], env=env) == 0


def test_public_names():
    assert sim.ANOMALY_TYPES == ('planning_failure', 'collision', 'sudden_acceleration', 'excessive_twisting',
                                 'localization_jump', 'wheels_slipping')
    config = sim.SimConfig()
    assert (config.rate, config.seed, config.minutes, config.anomalies, config.anomaly_types, config.imu) == \
        (100.0, 0, 10.0, 6, sim.ANOMALY_TYPES, False)


@pytest.mark.parametrize('kwargs, field', [
    (dict(rate=0), 'rate'), (dict(rate='fast'), 'rate'), (dict(seed=1.5), 'seed'), (dict(minutes=-1), 'minutes'),
    (dict(anomalies=-1), 'anomalies'), (dict(anomaly_types='collision,meteor'), 'anomaly_types'),
    (dict(anomaly_types=[]), 'anomaly_types'), (dict(minutes=1.0, anomalies=3), 'anomalies'),
    (dict(jitter=0.01), 'jitter'),
])
def test_bad_configuration_names_the_field(kwargs, field):
    with pytest.raises(ValueError) as error:
        sim.Simulator(sim.SimConfig(**kwargs))
    assert str(error.value).startswith(field + ': ')


def test_anomaly_types_parse():
    assert sim.parse_anomaly_types('collision, wheels_slipping') == ('collision', 'wheels_slipping')
    assert sim.parse_anomaly_types('all') == sim.ANOMALY_TYPES
    assert sim.SimConfig(anomaly_types='collision').validate().anomaly_types == ('collision',)


# ---------------------------------------------------------------------------------------------------------
# determinism

def _all_bytes(config):
    digest = hashlib.sha256()
    simulator = sim.Simulator(config)
    for topic, stamp, msg in simulator.messages():
        digest.update(topic.encode() + repr(stamp).encode() + serialized(msg))
    return digest.hexdigest(), simulator.truth


def test_same_seed_same_bytes_other_seed_differs():
    config = dict(minutes=2.0, anomalies=3, imu=True)
    first, truth_first = _all_bytes(sim.SimConfig(seed=7, **config))
    again, truth_again = _all_bytes(sim.SimConfig(seed=7, **config))
    other, truth_other = _all_bytes(sim.SimConfig(seed=8, **config))
    assert first == again and truth_first == truth_again
    assert len(truth_first) == 3
    assert other != first and truth_other != truth_first


def test_bag_bytes_are_genpy_bytes():
    """simulate_to_bag serializes without genpy message objects: the bytes must be genpy's."""
    simulator = sim.Simulator(sim.SimConfig(minutes=0.5, anomalies=1, warmup=2.0, gap=2.0, imu=True,
                                            anomaly_types='localization_jump'))
    topics = set()
    while not simulator.done:
        for topic, stamp, item in simulator.advance():
            assert messages.serialized(item) == serialized(messages.message(item)), topic
            topics.add(topic)
    assert topics == {sim.ODOM_TOPIC, sim.IMU_TOPIC, sim.TRUTH_TOPIC}


def test_imu_does_not_change_odometry():
    plain = sim_track(sim.SimConfig(minutes=1.0, anomalies=1, seed=2))[0]
    with_imu = sim_track(sim.SimConfig(minutes=1.0, anomalies=1, seed=2, imu=True))[0]
    assert (plain.t, plain.x, plain.v) == (with_imu.t, with_imu.x, with_imu.v)


# ---------------------------------------------------------------------------------------------------------
# the simulated robot

def test_stream_rate_stamps_and_frames(ten_minutes):
    config, track, truth, items, positions = ten_minutes
    assert len(track) == 60000
    steps = [b - a for a, b in zip(track.t, track.t[1:])]
    assert min(steps) > 0.005 and max(steps) < 0.015                  # jitter, never out of order
    assert abs((len(track) - 1) / (track.t[-1] - track.t[0]) - 100.0) < 0.01
    assert 0.0002 < _std(steps) < 0.002                               # jitter is there, and small
    assert track.t[0] == pytest.approx(config.start_time, abs=0.003)
    stamps = [stamp for topic, stamp, msg in items]
    assert stamps == sorted(stamps)
    odom = [msg for topic, stamp, msg in items if topic == sim.ODOM_TOPIC]
    assert all(m.header.frame_id == 'odom' and m.child_frame_id == 'base_link' for m in odom[:100])
    assert odom[5].header.stamp.to_sec() == track.t[5]
    assert odom[0].pose.covariance[0] > 0 and odom[0].pose.covariance[35] > 0
    assert odom[0].twist.covariance[0] > 0 and odom[0].twist.covariance[35] > 0


def _std(values):
    mean = sum(values) / len(values)
    return math.sqrt(sum((v - mean) ** 2 for v in values) / len(values))


def test_nominal_driving_within_limits(ten_minutes):
    config, track, truth, items, positions = ten_minutes
    check_nominal(track, truth)


def test_tours_the_floor(ten_minutes):
    """Corridors, rooms behind doors, the atrium; turning in place; slow drift of the odometry."""
    config, track, truth, items, positions = ten_minutes
    xs = [p[0] for p in positions]
    ys = [p[1] for p in positions]
    visited = set()
    floor = sim.FloorPlan.bwi_floor()
    for name in floor.destinations:
        nx, ny = floor.nodes[name]
        if any(math.hypot(x - nx, y - ny) < 0.3 for x, y in positions[::10]):
            visited.add(name)
    assert len(visited) >= 4, visited
    assert max(xs) - min(xs) > 20.0 and max(ys) - min(ys) > 10.0
    distance = sum(track.moved(i) for i in range(1, len(track)))
    assert 150.0 < distance < 600.0
    spins = [i for i in range(len(track)) if abs(track.v[i]) < 0.03 and abs(track.w[i]) > 0.5
             and not inside(track.t[i], truth, 0.5)]
    assert len(spins) > 100, 'never turns in place'
    cruising = sum(1 for v in track.v if v > 0.9) / float(len(track))
    assert cruising > 0.05


def test_truth_spacing_and_events(ten_minutes):
    config, track, truth, items, positions = ten_minutes
    assert sorted(entry['type'] for entry in truth) == sorted(sim.ANOMALY_TYPES)
    assert truth[0]['start'] - config.start_time >= config.warmup
    for before, after in zip(truth, truth[1:]):
        assert after['start'] - before['end'] >= config.gap
    for entry in truth:
        assert 1.0 < entry['end'] - entry['start'] <= sim.MAX_ANOMALY_SECONDS + 0.1
    assert truth[-1]['end'] < track.t[-1]
    events = [(stamp, json.loads(msg.data)) for topic, stamp, msg in items if topic == sim.TRUTH_TOPIC]
    assert len(events) == 2 * len(truth)
    for entry, (start_stamp, start), (end_stamp, end) in zip(truth, events[::2], events[1::2]):
        assert start == {'event': 'start', 'type': entry['type'], 'start': entry['start'], 'end': None}
        assert end == {'event': 'end', 'type': entry['type'], 'start': entry['start'], 'end': entry['end']}
        assert (start_stamp, end_stamp) == (entry['start'], entry['end'])
        assert entry['start'] in track.t and entry['end'] in track.t


@pytest.mark.parametrize('kind', sim.ANOMALY_TYPES)
def test_anomaly_signature_in_window(ten_minutes, kind):
    config, track, truth, items, positions = ten_minutes
    entry = next(e for e in truth if e['type'] == kind)
    check_signature(track, entry)


def test_imu(ten_minutes):
    config, track, truth, items, positions = ten_minutes
    imu = [(stamp, msg) for topic, stamp, msg in items if topic == sim.IMU_TOPIC]
    assert len(imu) == len(track)
    assert all(m.header.frame_id == sim.IMU_FRAME for stamp, m in imu[:10])
    assert sum(m.linear_acceleration.z for s, m in imu) / len(imu) == pytest.approx(9.80665, abs=0.01)
    nominal = [(s, m) for s, m in imu if not inside(s, truth, 0.5)]
    assert max(abs(m.linear_acceleration.x) for s, m in nominal) < 1.5
    gyro = [m.angular_velocity.z for s, m in imu]
    error = [abs(g - w) for g, w, s in zip(gyro, track.w, track.t) if not inside(s, truth, 0.5)]
    assert sum(error) / len(error) < 0.03
    collision = next(e for e in truth if e['type'] == 'collision')
    assert min(m.linear_acceleration.x for s, m in imu if collision['start'] <= s <= collision['end']) < -8.0


def test_soft_collision_stops_within_the_nominal_deceleration_while_the_imu_rings_and_the_command_drives():
    """A soft collision (named only, never in 'all' nor injected): the odometry's hardest deceleration stays
    below the run's nominal one, while the IMU's forward acceleration spikes beyond 4 m/s^2 (nominal below 1.5)
    and cmd_vel keeps asking for motion (speed, or a turn once the planner turns on the spot) at a standstill."""
    assert 'soft_collision' in sim.SIM_ONLY_TYPES and 'soft_collision' not in sim.parse_anomaly_types('all')
    with pytest.raises(ValueError, match="^types: unknown anomaly type 'soft_collision'"):
        sim.inject_anomalies([], ('soft_collision',))
    config = sim.SimConfig(seed=4, minutes=2.0, anomalies=2, anomaly_types='soft_collision', imu=True, commands=True)
    track, truth, items, _ = sim_track(config)
    assert [entry['type'] for entry in truth] == ['soft_collision'] * 2
    decel = [(i, -a) for i, a in track.derivative(track.v, 0.1)]
    nominal = max(d for i, d in decel if not inside(track.t[i], truth, 0.2))
    imu = [(s, m.linear_acceleration.x) for topic, s, m in items if topic == sim.IMU_TOPIC]
    commands = [(s, max(abs(m.linear.x), abs(m.angular.z))) for topic, s, m in items if topic == sim.CMD_TOPIC]
    assert max(abs(a) for s, a in imu if not inside(s, truth, 0.5)) < 1.5
    for entry in truth:
        assert 0.2 < max(d for i, d in decel if inside(track.t[i], [entry])) < nominal, entry
        assert max(abs(a) for s, a in imu if entry['start'] <= s <= entry['start'] + 0.2) > 4.0, entry
        standing = track.indices(entry['end'] - 2.5, entry['end'] - 0.1)  # the standstill lasts 3 s at least
        assert standing and max(abs(track.v[i]) for i in standing) < 0.05
        assert min(v for s, v in commands if entry['end'] - 2.5 <= s <= entry['end'] - 0.1) > 0.5, entry


def test_unlimited_run_keeps_going():
    simulator = sim.Simulator(sim.SimConfig(minutes=0, anomalies=1, anomaly_types='localization_jump',
                                            warmup=1.0, gap=1.0, rate=50))
    for _ in range(50 * 40):
        simulator.step()
    assert not simulator.done and simulator.time == pytest.approx(40.0)
    assert [e['type'] for e in simulator.truth] == ['localization_jump']


# ---------------------------------------------------------------------------------------------------------
# bags and truth files

def test_simulate_to_bag_ten_minutes(tmp_path):
    import rosbag
    path = str(tmp_path / 'sim.bag')
    began = time.time()
    truth = sim.simulate_to_bag(path, sim.SimConfig())
    took = time.time() - began
    print('simulate_to_bag: 10 simulated minutes at 100 Hz in %.2f s' % took)
    assert took < 30.0
    assert sorted(os.listdir(str(tmp_path))) == ['sim.bag', 'sim.bag.truth.json']
    assert sim.load_truth(sim.truth_path(path)) == truth
    with open(sim.truth_path(path)) as stream:
        document = json.load(stream)
    assert document['topic'] == sim.ODOM_TOPIC and document['config']['seed'] == 0
    with rosbag.Bag(path) as bag:
        info = bag.get_type_and_topic_info()
        assert info.topics[sim.ODOM_TOPIC].message_count == 60000
        assert info.topics[sim.ODOM_TOPIC].msg_type == 'nav_msgs/Odometry'
        assert info.topics[sim.TRUTH_TOPIC].message_count == 2 * len(truth) == 12
        assert sim.IMU_TOPIC not in info.topics
        stamps = []
        for topic, msg, t in bag.read_messages(topics=[sim.ODOM_TOPIC]):
            assert msg.header.stamp == t
            stamps.append(t.to_sec())
    assert stamps == sorted(stamps)
    assert (len(stamps) - 1) / (stamps[-1] - stamps[0]) == pytest.approx(100.0, abs=0.05)
    assert 599.9 < stamps[-1] - stamps[0] < 600.0


def test_bags_are_deterministic(tmp_path):
    config = dict(minutes=1.5, anomalies=2, imu=True, seed=5)
    paths = [str(tmp_path / name) for name in ('a.bag', 'b.bag', 'c.bag')]
    truth_a = sim.simulate_to_bag(paths[0], sim.SimConfig(**config))
    truth_b = sim.simulate_to_bag(paths[1], sim.SimConfig(**config), truth_file=str(tmp_path / 'b.json'))
    config['seed'] = 6
    sim.simulate_to_bag(paths[2], sim.SimConfig(**config), compression='none')
    digests = [hashlib.sha256(open(p, 'rb').read()).hexdigest() for p in paths]
    assert digests[0] == digests[1] != digests[2]
    assert truth_a == truth_b == sim.load_truth(str(tmp_path / 'b.json'))
    assert not [name for name in os.listdir(str(tmp_path)) if '.tmp-' in name]


# ---------------------------------------------------------------------------------------------------------
# injecting into recorded odometry

def odom_track(records, topic):
    return Track((r.stamp, r.msg) for r in records if r.topic == topic)


def test_inject_into_real_husky_odometry(husky_records):
    before = [serialized(r.msg) for r in husky_records]
    out, truth = sim.inject_anomalies(husky_records, sim.ANOMALY_TYPES, seed=0, topic=HUSKY_ODOM)
    assert [serialized(r.msg) for r in husky_records] == before          # the input is untouched
    assert len(out) == len(husky_records)
    assert [e['type'] for e in truth] == list(sim.ANOMALY_TYPES)
    changed = 0
    for original, record, data in zip(husky_records, out, before):
        assert (record.stamp, record.topic) == (original.stamp, original.topic)
        if record.topic != HUSKY_ODOM or record.stamp < truth[0]['start']:
            assert serialized(record.msg) == data                     # unchanged before the first anomaly
        elif not inside(record.stamp, truth):
            assert record.msg.header == original.msg.header           # after one: the recording, carried on
            assert record.msg.twist == original.msg.twist
        elif serialized(record.msg) != data:
            changed += 1
            assert record.msg.header == original.msg.header
    assert changed > 100
    check_carried_on(odom_track(husky_records, HUSKY_ODOM), odom_track(out, HUSKY_ODOM), truth)
    for before_entry, after_entry in zip(truth, truth[1:]):
        assert after_entry['start'] - before_entry['end'] >= 20.0
    track = odom_track(out, HUSKY_ODOM)
    for entry in truth:
        check_signature(track, entry, limits=sim.BWIBOT_LIMITS)
    # the message at `end` is the first with the recorded twist again; the one before it was changed
    odom = [(o, r) for o, r in zip(husky_records, out) if r.topic == HUSKY_ODOM]
    for entry in truth:
        position = next(i for i, (o, r) in enumerate(odom) if r.stamp == entry['end'])
        assert odom[position][1].msg.twist == odom[position][0].msg.twist
        assert serialized(odom[position - 1][1].msg) != serialized(odom[position - 1][0].msg)


def test_inject_is_deterministic_and_seeded(husky_records):
    first = sim.inject_anomalies(husky_records, ['collision', 'localization_jump'], seed=3)
    again = sim.inject_anomalies(husky_records, ['collision', 'localization_jump'], seed=3)
    other = sim.inject_anomalies(husky_records, ['collision', 'localization_jump'], seed=4)
    assert first[1] == again[1] != other[1]
    assert [serialized(r.msg) for r in first[0]] == [serialized(r.msg) for r in again[0]]
    assert first[1][0]['type'] == 'collision'


def test_inject_into_simulated_100hz(tmp_path):
    """The same models at 100 Hz: into a nominal simulated stream."""
    simulator = sim.Simulator(sim.SimConfig(minutes=4.0, anomalies=0, seed=11))
    records = [Record(stamp, topic, msg) for topic, stamp, msg in simulator.messages()]
    out, truth = sim.inject_anomalies(records, sim.ANOMALY_TYPES, seed=1)
    track = odom_track(out, sim.ODOM_TOPIC)
    for entry in truth:
        check_signature(track, entry)
    check_nominal(track, truth, pad=0.0)
    for original, record in zip(records, out):
        if record.stamp < truth[0]['start'] or record.topic != sim.ODOM_TOPIC:
            assert record is original
    check_carried_on(odom_track(records, sim.ODOM_TOPIC), track, truth)


def test_inject_refuses_what_does_not_fit(husky_records):
    short = [r for r in husky_records if r.stamp < husky_records[0].stamp + 60.0]
    with pytest.raises(ValueError) as error:
        sim.inject_anomalies(short, sim.ANOMALY_TYPES, seed=0)
    assert str(error.value).startswith('types: ')
    with pytest.raises(ValueError) as error:
        sim.inject_anomalies(short, ['teleport'], seed=0)
    assert str(error.value).startswith('types: ')
    with pytest.raises(ValueError) as error:
        sim.inject_anomalies([r for r in short if r.topic == '/imu/data'], ['collision'], seed=0)
    assert str(error.value).startswith('topic: ')


def test_nominal_envelope_of_husky(husky_records):
    envelope = sim.nominal_envelope(husky_records, HUSKY_ODOM)
    track = odom_track(husky_records, HUSKY_ODOM)
    assert 0.5 < envelope.max_speed <= max(abs(v) for v in track.v)     # smoothed: below the noisy peak
    assert all(value >= 0.1 * limit for value, limit in zip(envelope, sim.BWIBOT_LIMITS))
    with pytest.raises(ValueError) as error:
        sim.nominal_envelope(husky_records[:5], HUSKY_ODOM)
    assert str(error.value).startswith('topic: ')
    with pytest.raises(ValueError) as error:
        sim.inject_anomalies(husky_records, ['collision'], topic=HUSKY_ODOM, scale=envelope._replace(max_decel=0.0))
    assert str(error.value).startswith('scale: ')


def deviation(records, out, truth, field):
    """The largest |injected - recorded| of ``field`` ('v' or 'w') inside the one anomaly of ``truth``."""
    entry = truth[0]
    pairs = [(o.msg.twist.twist, r.msg.twist.twist) for o, r in zip(records, out)
             if r.topic == HUSKY_ODOM and entry['start'] <= r.stamp < entry['end']]
    pick = (lambda twist: twist.linear.x) if field == 'v' else (lambda twist: twist.angular.z)
    return max(abs(pick(a) - pick(b)) for a, b in pairs)


@pytest.mark.parametrize('kind, field, quantity', [('excessive_twisting', 'w', 'max_yaw_rate'),
                                                   ('sudden_acceleration', 'v', 'max_speed')])
def test_inject_at_the_robot_scale(husky_records, kind, field, quantity):
    """A scale twice the BWIBot's in one quantity doubles the anomaly's magnitude in it; None is the BWIBot's."""
    base = sim.inject_anomalies(husky_records, [kind], seed=2, topic=HUSKY_ODOM)
    same = sim.inject_anomalies(husky_records, [kind], seed=2, topic=HUSKY_ODOM, scale=None)
    assert [serialized(r.msg) for r in base[0]] == [serialized(r.msg) for r in same[0]]
    doubled = sim.BWIBOT_LIMITS._replace(**{quantity: 2.0 * getattr(sim.BWIBOT_LIMITS, quantity)})
    # the return to the recorded twist is not the test: unbounded
    unlimited = sim.Limits(*(10.0 * x for x in sim.BWIBOT_LIMITS))._replace(max_speed=sim.BWIBOT_LIMITS.max_speed)
    one = sim.inject_anomalies(husky_records, [kind], seed=2, topic=HUSKY_ODOM, scale=sim.BWIBOT_LIMITS,
                               limits=unlimited)
    two = sim.inject_anomalies(husky_records, [kind], seed=2, topic=HUSKY_ODOM, scale=doubled, limits=unlimited)
    assert one[1][0]['start'] == two[1][0]['start']
    ratio = deviation(husky_records, two[0], two[1], field) / deviation(husky_records, one[0], one[1], field)
    assert 1.7 < ratio < 2.3


def body_steps(track, i):
    """(forward, sideways, turn) of the step from message i-1 to i, in the frame of the mean heading."""
    heading = 0.5 * (track.yaw[i - 1] + track.yaw[i])
    dx, dy = track.x[i] - track.x[i - 1], track.y[i] - track.y[i - 1]
    return (math.cos(heading) * dx + math.sin(heading) * dy, -math.sin(heading) * dx + math.cos(heading) * dy,
            track.yaw[i] - track.yaw[i - 1])


def check_carried_on(recorded, injected, truth):
    """Outside the anomalies the base makes the recording's own steps (its pose moved rigidly, nothing else)."""
    for i in range(1, len(recorded)):
        if not inside(injected.t[i - 1], truth) and not inside(injected.t[i], truth):
            assert body_steps(injected, i) == pytest.approx(body_steps(recorded, i), abs=1e-9), i


@pytest.mark.parametrize('kind', ['planning_failure', 'collision', 'sudden_acceleration', 'excessive_twisting',
                                  'wheels_slipping'])
def test_an_injected_base_never_slides_sideways(husky_records, kind):
    """Odometry is integrated from the twist: the injected base moves along its heading (no sideways step beyond
    the recording's own), and after the anomaly the recording carries on from where the base was left, instead
    of the pose sliding back onto the recorded track (which the features saw as a sideways velocity error)."""
    recorded = odom_track(husky_records, HUSKY_ODOM)
    envelope = sim.nominal_envelope(husky_records, HUSKY_ODOM)
    out, truth = sim.inject_anomalies(husky_records, [kind], seed=2, topic=HUSKY_ODOM, scale=envelope,
                                      limits=envelope)
    injected = odom_track(out, HUSKY_ODOM)
    dt = [injected.t[i] - injected.t[i - 1] for i in range(1, len(injected))]
    own = max(abs(body_steps(recorded, i)[1]) / dt[i - 1] for i in range(1, len(recorded)) if dt[i - 1] > 0)
    slide = max(abs(body_steps(injected, i)[1]) / dt[i - 1] for i in range(1, len(injected)) if dt[i - 1] > 0)
    assert slide <= own + 1e-3
    inside_steps = [i for i in range(1, len(injected)) if inside(injected.t[i], truth)]
    assert any(body_steps(injected, i) != body_steps(recorded, i) for i in inside_steps)  # the anomaly is there
    check_carried_on(recorded, injected, truth)
    assert (injected.x[-1], injected.y[-1]) != (recorded.x[-1], recorded.y[-1])  # carried, not blended back


def test_collision_at_the_robot_scale_brakes_by_its_deceleration(husky_records):
    """Robot scale: the collision's deceleration is a multiple of the envelope's, whatever the speed."""
    def stop_seconds(scale):
        out, truth = sim.inject_anomalies(husky_records, ['collision'], seed=1, topic=HUSKY_ODOM, scale=scale)
        track = odom_track(out, HUSKY_ODOM)
        start = track.t.index(truth[0]['start'])
        still = next(i for i in range(start, len(track.t)) if abs(track.v[i]) < 0.1 * abs(track.v[start - 1]))
        return track.t[still] - track.t[start - 1], abs(track.v[start - 1])
    soft, speed = stop_seconds(sim.BWIBOT_LIMITS._replace(max_decel=0.05))
    hard, _ = stop_seconds(sim.BWIBOT_LIMITS._replace(max_decel=5.0))
    assert speed > 0.3
    assert soft > 0.5 and hard < 0.2       # 0.05 m/s^2 x ~20: ~1 m/s^2; 5 m/s^2 x ~20: ~100 m/s^2
