"""Routes (cc_log.base.routes): a window cut once into one file per route, each route a topic set in its own
format; the configuration declares them; bad routes are one line naming the entry."""
import collections
import contextlib
import io
import json
import os

import pytest
import rosbag
import yaml
from conftest import ROOT

from cc_log import sim
from cc_log.logger import config
from cc_log.base.records import LogWindow, Record, Trigger
from cc_log.base.routes import parse_routes, split
from cc_log.base.topic_select import TopicSelection
from cc_log.offline import cli
from cc_log.storage import log_format
from cc_log.storage.bag.bag_format import METADATA_TOPIC

FORMATS = ('bag-lz4', 'json-xz')
NUMERIC = {'name': 'numeric', 'topics': ['/odom', 're:/imu/.*'], 'format': 'json-xz'}


def window(topics, part=0, final=True):
    records = [Record(100.0 + i, topic, None, 10) for i, topic in enumerate(topics)]
    return LogWindow(records, [Trigger(101.0, 'collision', None, 'bumper')], part, final, key=7)


def test_a_window_is_cut_once_by_route_in_order():
    routes = parse_routes([NUMERIC, {'name': 'scans', 'topics': ['/scan', '/odom'], 'format': 'bag-lz4'}], FORMATS)
    parts = split(window(['/camera', '/odom', '/imu/data', '/scan', '/odom', '/camera']), routes)
    named = [(route.name if route else None, [r.topic for r in part.records]) for route, part in parts]
    assert named == [(None, ['/camera', '/camera']), ('numeric', ['/odom', '/imu/data', '/odom']),
                     ('scans', ['/scan'])]  # the first route that matches takes a topic
    assert all(part.triggers[0].reason == 'collision' and part.key == 7 for _, part in parts)
    assert sum(len(part) for _, part in parts) == 6


def test_a_copy_route_takes_its_topics_and_leaves_them_in_the_window_own_part():
    routes = parse_routes([dict(NUMERIC, copy=True)], FORMATS)
    parts = split(window(['/camera', '/odom', '/imu/data']), routes)
    named = [(route.name if route else None, [r.topic for r in part.records]) for route, part in parts]
    assert named == [(None, ['/camera', '/odom', '/imu/data']), ('numeric', ['/odom', '/imu/data'])]
    assert [route.copy for route in parse_routes([NUMERIC], FORMATS)] == [False]  # a route moves by default


def test_without_routes_the_window_is_its_own_file():
    whole = window(['/odom', '/camera'])
    assert split(whole, []) == [(None, whole)]


def test_every_part_of_a_window_in_parts_reaches_every_route():
    routes = parse_routes([NUMERIC], FORMATS)
    parts = split(window(['/camera'], part=3, final=True), routes)  # the last part: routes must finish their file
    assert [(route.name if route else None, len(part), part.part, part.final) for route, part in parts] == \
        [(None, 1, 3, True), ('numeric', 0, 3, True)]


@pytest.mark.parametrize('value, error', [
    (5, 'routes: a list of {name, topics, format}, not 5'),
    ([{'name': 'a b', 'topics': ['x'], 'format': 'json-xz'}], "routes[0]: name: 'a b' must be"),
    ([{'name': 'a', 'topics': [], 'format': 'json-xz'}], 'routes[0] (a): topics: a list'),
    ([{'name': 'a', 'topics': ['x'], 'format': 'zip'}], "routes[0] (a): format: 'zip' is not one of: bag-lz4"),
    ([NUMERIC, NUMERIC], 'routes[1]: name numeric is used twice'),
    ('[{name: a, topics: [x], format: json-xz, size: 1}]', "routes[0]: unknown key 'size'"),
    ([{'name': 'a', 'topics': ['re:(a+)+'], 'format': 'json-xz'}], 'routes[0] (a): topics'),
    ([dict(NUMERIC, copy='yes')], "routes[0] (numeric): copy: true or false, not 'yes'"),
])
def test_bad_routes_are_one_line_naming_the_entry(value, error):
    with pytest.raises(ValueError) as raised:
        config.Config.from_dict({'routes': value})
    assert error in str(raised.value) and '\n' not in str(raised.value)


def test_json_xz_precision_may_round_a_routed_topic_set():
    cfg = config.Config.from_dict({'format': 'bag-lz4', 'routes': [NUMERIC],
                                   'json_xz': {'precision': {'pose.pose.position.*': 1e-4}}})
    assert [route.format for route in cfg.routes] == ['json-xz'] and cfg.precision
    with pytest.raises(ValueError, match='rounds json-xz windows only'):
        config.Config.from_dict({'format': 'bag-lz4', 'json_xz': {'precision': {'a': 0.1}}})


# -- end to end: cclog replay writes a window as one bag-lz4 file and one json-xz file per route ------------

def test_a_window_only_triggers_with_keep_opened_holds_only_their_topics():
    from cc_log.buffer import window_prep
    records = [Record(100.0 + i, topic, None, 10) for i, topic in enumerate(['/odom', '/camera', '/scan', '/diag'])]
    bumper = LogWindow(list(records), [Trigger(101.0, 'pressed', None, 'bumper')])
    keep = {'bumper': TopicSelection(['/camera']), 'silent': TopicSelection(['/diag'])}
    assert [r.topic for r in window_prep.restrict(bumper, keep, '/odom').records] == ['/odom', '/camera']
    both = LogWindow(list(records), [Trigger(101.0, 'pressed', None, 'bumper'),
                                     Trigger(102.0, 'quiet', None, 'silent')])
    assert [r.topic for r in window_prep.restrict(both, keep, '/odom').records] == ['/odom', '/camera', '/diag']
    other = LogWindow(list(records), [Trigger(101.0, 'pressed', None, 'bumper'), Trigger(102.0, 'x', 0.1, 'motion')])
    assert len(window_prep.restrict(other, keep, '/odom').records) == 4  # another trigger: every topic
    cfg = config.Config.from_dict({'driving_topic': 'odom', 'triggers': [
        {'name': 'bumper', 'kind': 'rule', 'topic': 'bumper', 'arrival': True, 'keep': 'camera/image_raw scan'}]})
    kept = cfg.logger_options(cfg.build_triggers(None, lambda _: None))['keep']
    assert list(kept) == ['bumper'] and kept['bumper'].names == ['/camera/image_raw', '/scan']
    with pytest.raises(ValueError, match=r'triggers\[0\] \(bumper\): keep: 5 is not a list of topic names'):
        config.Config.from_dict({'triggers': [{'name': 'bumper', 'kind': 'rule', 'topic': 'b', 'arrival': True,
                                               'keep': 5}]})


def replayed(tmp_path, windows, keep=None):
    """A simulated run (camera, scan, odometry, IMU) replayed with a window every 10 s and the numeric route;
    the output directory."""
    from cc_log.offline import cli
    bag = str(tmp_path / 'run.bag')
    sim.simulate_to_bag(bag, sim.SimConfig(seed=3, minutes=0.5, anomalies=0, imu=True, camera=True, scan=True))
    cfg = tmp_path / 'routes.yaml'
    cfg.write_text(yaml.safe_dump({
        'driving_topic': sim.ODOM_TOPIC, 'topics': ['*'], 'windows': windows,
        'format': 'bag-lz4', 'routes': [{'name': 'numeric', 'topics': [sim.ODOM_TOPIC, sim.IMU_TOPIC],
                                         'format': 'json-xz'}],
        'triggers': [dict({'name': 'every10s', 'kind': 'periodic', 'every': '10s'},
                          **({'keep': keep} if keep else {}))]}))
    out = tmp_path / 'out'
    assert cli.main(['replay', bag, '--config', str(cfg), '--out', str(out)]) == 0
    return str(out)


def test_a_replayed_window_is_one_bag_and_one_json_xz_file_read_as_one(tmp_path):
    out = replayed(tmp_path, {'pre': '2s', 'post': '2s'})
    files = log_format.window_files(out)
    own = [f for f in files if '+' not in os.path.basename(f)]
    routed = [f for f in files if os.path.basename(f).endswith('+numeric.json.xz')]
    assert own and len(routed) == len(own) == len(files) / 2  # each window: its bag and its route's file
    for path in own:
        with rosbag.Bag(path) as reader:  # the heavy topics, as rosbag reads them
            topics = set(reader.get_type_and_topic_info().topics)
        assert {sim.CAMERA_TOPIC, sim.SCAN_TOPIC} <= topics and not topics & {sim.ODOM_TOPIC, sim.IMU_TOPIC}
    metadata, records = log_format.read_window(routed[0])
    assert set(metadata['topics']) == {sim.ODOM_TOPIC, sim.IMU_TOPIC} and metadata['route'] == 'numeric'
    # every reader sees a window's files as one window
    [files_of_first] = [s for s in log_format.window_sets([routed[0]])]
    assert files_of_first == [own[0], routed[0]]
    metadata, records = log_format.read_window_set(files_of_first)
    assert set(metadata['topics']) == {sim.ODOM_TOPIC, sim.IMU_TOPIC, sim.CAMERA_TOPIC, sim.SCAN_TOPIC}
    assert [r.stamp for r in records] == sorted(r.stamp for r in records)
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        assert cli.main(['info', out, '--json']) == 0
    info = json.loads(text.getvalue())
    assert info['total']['windows'] == len(own)
    assert info['windows'][0]['files'] == files_of_first
    assert info['total']['bytes'] == sum(os.path.getsize(f) for f in files)


def test_a_window_in_parts_is_still_one_window_with_its_route_files(tmp_path):
    out = replayed(tmp_path, {'pre': '2s', 'post': '2s', 'max': 150})  # parts of 150 odometry messages
    files = log_format.window_files(out)
    own = [f for f in files if '+' not in os.path.basename(f)]
    parts = [f for f in files if '+numeric.' in os.path.basename(f)]
    assert own and len(parts) > len(own)  # one bag per window (parts appended), a json-xz file per part
    sets = log_format.window_sets(files)
    assert len(sets) == len(own) and all(s[0] in own and len(s) > 2 for s in sets)
    for files_of_one in sets:
        metadata, records = log_format.read_window_set(files_of_one)
        assert {sim.ODOM_TOPIC, sim.CAMERA_TOPIC} <= set(metadata['topics'])
        stamps = [r.stamp for r in records if r.topic == sim.ODOM_TOPIC]
        assert stamps == sorted(set(stamps))  # no odometry message twice, none out of order


def test_a_trigger_that_keeps_the_camera_keeps_no_scan(tmp_path):
    out = replayed(tmp_path, {'pre': '2s', 'post': '2s'}, keep=[sim.CAMERA_TOPIC])
    for files in log_format.window_sets(log_format.window_files(out)):
        metadata, _ = log_format.read_window_set(files)
        assert set(metadata['topics']) == {sim.ODOM_TOPIC, sim.CAMERA_TOPIC}, metadata['topics']


def readme_camera_configuration():
    """The YAML block of README.md's "Cameras and lidars" section, as text."""
    with open(os.path.join(ROOT, 'README.md')) as stream:
        section = stream.read().split('### Cameras and lidars', 1)[1]
    return section.split('```yaml\n', 1)[1].split('```', 1)[0]


def test_the_readme_camera_configuration_writes_one_bag_per_window_that_replays_it_all(tmp_path):
    text = readme_camera_configuration()
    with open(os.path.join(ROOT, 'config', 'cameras.yaml')) as stream:
        assert stream.read() == text  # config/cameras.yaml is the README's block
    bag = str(tmp_path / 'run.bag')
    sim.simulate_to_bag(bag, sim.SimConfig(seed=3, minutes=0.5, anomalies=0, imu=True, camera=True, scan=True))
    data = yaml.safe_load(text)
    simulated = {sim.ODOM_TOPIC, sim.IMU_TOPIC, sim.CAMERA_TOPIC, sim.SCAN_TOPIC}
    data['topics'] = [t for t in data['topics'] if '/' + t in simulated]  # replay refuses topics a bag lacks
    assert len(data['topics']) == 4
    data = dict(data, driving_topic=sim.ODOM_TOPIC, triggers=[
        {'name': 'every10s', 'kind': 'periodic', 'every': '10s', 'pre': '2s', 'post': '2s'}])
    cfg = tmp_path / 'cameras.yaml'
    cfg.write_text(yaml.safe_dump(data))
    out = str(tmp_path / 'out')
    assert cli.main(['replay', bag, '--config', str(cfg), '--out', out]) == 0
    sets = log_format.window_sets(log_format.window_files(out))
    assert len(sets) >= 2
    kept = 0
    for files in sets:
        bags = [f for f in files if f.endswith('.bag')]
        copies = [f for f in files if f not in bags]
        assert len(bags) == 1 and '+' not in os.path.basename(bags[0]), files  # the window: one bag
        assert copies and all('+numeric' in os.path.basename(f) and f.endswith('.json.xz') for f in copies), files
        with rosbag.Bag(bags[0]) as reader:  # every topic of the moment, as rosbag play reads it
            counts = {topic: info.message_count for topic, info in reader.get_type_and_topic_info().topics.items()
                      if topic != METADATA_TOPIC}
        assert {sim.ODOM_TOPIC, sim.IMU_TOPIC, sim.CAMERA_TOPIC, sim.SCAN_TOPIC} <= set(counts), counts
        copied = collections.Counter()
        for path in copies:
            copied.update(r.topic for r in log_format.read_window(path)[1])
        assert set(copied) == {sim.ODOM_TOPIC, sim.IMU_TOPIC}
        assert copied[sim.ODOM_TOPIC] == counts[sim.ODOM_TOPIC] and copied[sim.IMU_TOPIC] == counts[sim.IMU_TOPIC]
        metadata, records = log_format.read_window_set(files)  # readers count the copied topics once
        assert metadata['counts'] == counts and metadata['count'] == sum(counts.values()) == len(records)
        assert log_format.merged_metadata([log_format.read_metadata(f) for f in files], files)['counts'] == counts
        kept += sum(counts.values())
    # the logger counts a copy once too (kept, and what /diagnostics says was dropped: never below zero)
    from cc_log.offline import replay
    reader = replay.open_bag(bag)
    try:
        options, _, _ = replay.replay_setup(config.Config.from_dict(data), reader)
    finally:
        reader.close()
    logger = replay.offline_logger(str(tmp_path / 'again'), options)
    summary = replay.replay_into(logger, bag)
    stats = logger.stats()
    assert stats['messages_kept'] == kept and 0 <= stats['messages_not_kept'] <= stats['messages_seen'] - kept
    assert len(summary['windows']) == len(sets)  # and so does replay's summary, a window's files as one
    assert sum(window['messages'] for window in summary['windows']) == kept


def test_a_heavy_topic_written_as_json_xz_is_advised_bag_lz4():
    from cc_log.base.routes import format_of
    from cc_log.storage.formats.json_xz import heavy_topic_advice
    routes = parse_routes([NUMERIC, {'name': 'cameras', 'topics': ['re:/camera/.*'], 'format': 'json-xz'}], FORMATS)
    assert [format_of(topic, routes, 'bag-lz4') for topic in ('/odom', '/camera/image_raw', '/scan')] == [
        'json-xz', 'json-xz', 'bag-lz4']
    written_as = format_of('/camera/image_raw', routes, 'bag-lz4')
    advice = heavy_topic_advice('/camera/image_raw', 'sensor_msgs/Image', written_as)
    assert advice == ('json-xz carries about 16 MB/s per core: /camera/image_raw (sensor_msgs/Image) is better kept '
                      'as bag-lz4 (a route: routes: [{name: sensors, topics: [/camera/image_raw], format: bag-lz4}], '
                      'or format: bag-lz4)')
    assert heavy_topic_advice('/points', 'sensor_msgs/PointCloud2', format_of('/points', [], 'json-xz'))
    assert heavy_topic_advice('/scan', 'sensor_msgs/LaserScan', format_of('/scan', routes, 'bag-lz4')) is None
    assert heavy_topic_advice('/odom', 'nav_msgs/Odometry', format_of('/odom', routes, 'bag-lz4')) is None
    assert heavy_topic_advice('/camera/x', 'sensor_msgs/CompressedImage', 'json-xz').startswith('json-xz carries')
