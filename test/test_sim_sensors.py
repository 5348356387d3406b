"""The simulated BWIBot's camera and laser scanner (cc_log.sim.sensors): rates, walls, determinism, collisions, bags."""
import hashlib
import math

import numpy
import pytest

from cc_log import sim
from cc_log.sim import sensors

RED = (150, 60)  # a pixel is the obstacle's red when R > 150 and G, B < 60


def run(config):
    """Every (topic, stamp, msg) of a simulated run and its truth."""
    simulator = sim.Simulator(config)
    items = list(simulator.messages())
    return items, simulator.truth


@pytest.fixture(scope='module')
def collision_run():
    """One minute with one collision, camera and scan on."""
    config = sim.SimConfig(minutes=1.0, anomalies=1, anomaly_types='collision', seed=3, warmup=15.0, gap=10.0,
                           camera=True, scan=True)
    return run(config)


def bwi_sensors():
    return sensors.Sensors(sim.FloorPlan.bwi_floor(), seed=0, rate=100.0)


def test_the_default_simulator_publishes_no_camera_and_no_scan():
    items, _ = run(sim.SimConfig(minutes=0.05, anomalies=0))
    assert {topic for topic, _, _ in items} == {sim.ODOM_TOPIC}


def test_images_at_15_hz_and_scans_at_10_hz_of_the_right_shape(collision_run):
    items, _ = collision_run
    images = [(stamp, msg) for topic, stamp, msg in items if topic == sim.CAMERA_TOPIC]
    scans = [(stamp, msg) for topic, stamp, msg in items if topic == sim.SCAN_TOPIC]
    assert len(images) == 900 and len(scans) == 600
    for stamp, image in images[:3]:
        assert (image._type, image.width, image.height, image.encoding, image.step, len(image.data)) == (
            'sensor_msgs/Image', 320, 240, 'rgb8', 960, 320 * 240 * 3)
        assert abs(image.header.stamp.to_sec() - stamp) < 1e-9 and image.header.frame_id == 'camera_link'
    gaps = numpy.diff([stamp for stamp, _ in images])
    assert abs(numpy.mean(gaps) - 1 / 15.0) < 1e-3 and gaps.max() < 1 / 15.0 + 0.011
    scan = scans[0][1]
    assert scan._type == 'sensor_msgs/LaserScan' and len(scan.ranges) == 481
    assert math.isclose(scan.angle_min, -math.radians(120)) and math.isclose(scan.angle_max, math.radians(120))
    assert [msg.header.seq for _, msg in scans[:3]] == [0, 1, 2]


def test_scan_ranges_are_the_distances_to_the_walls_of_the_floor_plan():
    # the lab is a 5 m box around (-5, 10); its door (1 m wide) opens east onto the west corridor (x <= 1.2)
    ranges = bwi_sensors().ranges((-5.0, 10.0, 0.0))
    beam = lambda degrees: ranges[int(round((degrees + 120) * 2))]  # noqa: E731
    assert beam(90) == pytest.approx(2.5, abs=0.05) and beam(-90) == pytest.approx(2.5, abs=0.05)
    assert beam(0) == pytest.approx(6.2, abs=0.05)                   # through the door to the corridor's far wall
    assert beam(-60) == pytest.approx(2.5 / math.sin(math.radians(60)), abs=0.05)
    turned = bwi_sensors().ranges((-5.0, 10.0, math.pi / 2))
    assert turned[240] == pytest.approx(2.5, abs=0.05)               # facing north: the lab's north wall
    corridor = bwi_sensors().ranges((20.0, 0.0, 0.0))                # the south corridor, looking east
    assert math.isinf(corridor[240]) and corridor[60] == pytest.approx(1.2, abs=0.05)  # east wall: 21.2 m > 20 m


def test_the_image_shows_where_the_robot_is():
    camera = bwi_sensors()
    lab = camera.render((-5.0, 10.0, 0.0))
    assert lab.shape == (240, 320, 3) and lab.dtype == numpy.uint8
    moved = camera.render((-4.0, 10.0, 0.0))
    turned = camera.render((-5.0, 10.0, math.pi))
    assert numpy.abs(lab.astype(int) - moved).mean() > 5 and numpy.abs(lab.astype(int) - turned).mean() > 5
    assert numpy.array_equal(lab, camera.render((-5.0, 10.0, 0.0)))
    assert len({tuple(pixel) for pixel in lab.reshape(-1, 3)[::7]}) > 20   # walls, floor tiles, ceiling


def test_the_same_seed_gives_the_same_frames_and_scans():
    config = dict(minutes=0.1, anomalies=0, camera=True, scan=True)

    def digest(seed):
        items, _ = run(sim.SimConfig(seed=seed, **config))
        return hashlib.sha256(b''.join(sim.serialized(msg) for topic, _, msg in items
                                       if topic in (sim.CAMERA_TOPIC, sim.SCAN_TOPIC))).hexdigest()
    assert digest(1) == digest(1) != digest(2)


def test_a_collision_puts_an_obstacle_in_front_of_the_camera_and_the_scanner(collision_run):
    items, truth = collision_run
    (collision,) = truth
    during = lambda stamp: collision['start'] <= stamp < collision['end']  # noqa: E731
    red_frames = []
    for topic, stamp, msg in items:
        if topic == sim.CAMERA_TOPIC:
            centre = numpy.frombuffer(msg.data, numpy.uint8).reshape(240, 320, 3)[120, 160]
            red_frames.append((during(stamp), centre[0] > RED[0] and max(centre[1:]) < RED[1]))
        elif topic == sim.SCAN_TOPIC:
            ahead = msg.ranges[240]
            assert (ahead < 0.35) == during(stamp), (stamp, ahead)
    assert sum(red for inside, red in red_frames if inside) == sum(inside for inside, _ in red_frames) > 30
    assert not any(red for inside, red in red_frames if not inside)


def test_simulate_to_bag_writes_the_frames_and_scans(tmp_path):
    rosbag = pytest.importorskip('rosbag')
    config = sim.SimConfig(minutes=0.1, anomalies=0, camera=True, scan=True, seed=4)
    path = str(tmp_path / 'run.bag')
    sim.simulate_to_bag(path, config)
    expected = [(topic, sim.serialized(msg)) for topic, _, msg in run(sim.SimConfig(**dict(
        config.to_dict(), anomaly_types=tuple(config.anomaly_types))))[0]]
    with rosbag.Bag(path) as bag:
        info = bag.get_type_and_topic_info().topics
        read = [(topic, raw[1]) for topic, raw, _ in bag.read_messages(raw=True)]
    assert info[sim.CAMERA_TOPIC].msg_type == 'sensor_msgs/Image' and info[sim.CAMERA_TOPIC].message_count == 90
    assert info[sim.SCAN_TOPIC].msg_type == 'sensor_msgs/LaserScan' and info[sim.SCAN_TOPIC].message_count == 60
    assert sorted(read) == sorted(expected)
