"""Topic selection (rosbag record's -a, -e, -x), the configuration's topic patterns, and the topic watcher."""
import pytest

from cc_log.logger import config
from cc_log.base.topic_select import TopicSelection
from cc_log.nodes.topic_watch import TopicWatcher

TOPICS = ['/odom', '/scan', '/camera/rgb/image_raw', '/camera/rgb/image_raw/compressed', '/tf', '/tf_static']


def test_names_regex_all_and_exclusions():
    named = TopicSelection(['/scan'])
    assert named.select(TOPICS) == ['/scan'] and not named.dynamic
    camera = TopicSelection(regex=['/camera/.*'], exclude=['.*/compressed'])
    assert camera.select(TOPICS) == ['/camera/rgb/image_raw'] and camera.dynamic
    assert not TopicSelection(regex=['/camera']).matches('/camera/rgb/image_raw')  # the whole name, as -e
    everything = TopicSelection(all_topics=True, exclude=['/tf'])
    assert everything.select(TOPICS) == [t for t in TOPICS if t != '/tf']


def test_parse_configuration_entries():
    selection = TopicSelection.parse(['/scan', 're:/camera/.*', '!re:.*/compressed', '!/tf_static', '*'])
    assert selection.names == ['/scan'] and selection.all_topics
    assert selection.select(TOPICS) == ['/odom', '/scan', '/camera/rgb/image_raw', '/tf']
    assert TopicSelection.parse(['!/a_b']).exclude[0].fullmatch('/a_b') and \
        not TopicSelection.parse(['!/a_b']).exclude[0].fullmatch('/a_bc')  # a name is not a pattern
    for bad in (['re:('], ['re:'], ['!'], ['!*'], [''], [3], ['!/a.b'], ['/imu/*'], ['regex:/imu/.*']):
        with pytest.raises(ValueError, match='^topics: '):
            TopicSelection.parse(bad)
    assert 'all topics' in selection.describe() and 'except' in selection.describe()


def test_configuration_topics_may_hold_patterns():
    cfg = config.Config.from_dict({'topics': ['imu/data', 're:/camera/.*', '!re:.*/compressed'],
                                   'driving_topic': 'odom'})
    assert cfg.topics == ['imu/data'] and cfg.selection.dynamic
    assert cfg.selection.matches('/camera/depth') and not cfg.selection.matches('/camera/depth/compressed')
    assert cfg.logger_options([])['side_topics'] is None  # every topic the watcher subscribes is kept
    plain = config.Config.from_dict({'topics': ['imu/data'], 'driving_topic': 'odom'})
    assert plain.logger_options([])['side_topics'] == ['/imu/data']
    with pytest.raises(ValueError, match='topics: .*regular expression'):
        config.Config.from_dict({'topics': ['re:[']})


def test_watcher_subscribes_each_new_matching_topic_once():
    published = [('/odom', 'nav_msgs/Odometry')]
    subscribed = []
    watcher = TopicWatcher(TopicSelection(regex=['/camera/.*']), subscribed.append, lambda: list(published),
                           skip=['/odom'])
    assert watcher.poll() == []
    published += [('/camera/a', 'sensor_msgs/Image'), ('/scan', 'sensor_msgs/LaserScan')]
    assert watcher.poll() == ['/camera/a']
    published.append(('/camera/b', 'sensor_msgs/Image'))
    assert watcher.poll() == ['/camera/b'] and watcher.poll() == []
    assert subscribed == ['/camera/a', '/camera/b']


def test_watcher_failures_are_counted_and_retried():
    calls = []

    def flaky(topic):
        calls.append(topic)
        if len(calls) == 1:
            raise RuntimeError('not yet')

    def master_down():
        raise OSError('connection refused')
    down = TopicWatcher(TopicSelection(all_topics=True), flaky, master_down)
    assert down.poll() == [] and down.errors == 1 and 'connection refused' in down.last_error
    watcher = TopicWatcher(TopicSelection(all_topics=True), flaky, lambda: [('/a', 'x')])
    assert watcher.poll() == [] and watcher.errors == 1
    assert watcher.poll() == ['/a'] and calls == ['/a', '/a']


def test_cclog_replay_selects_the_bags_topics_with_patterns(tmp_path, real_bag):
    from cc_log.offline import cli
    from cc_log.storage import log_format
    cfg = tmp_path / 'patterns.yaml'
    cfg.write_text('topics: ["*", "!re:/imu/.*"]\ndriving_topic: /husky_velocity_controller/odom\n'
                   'windows: {pre: 5, post: 5}\n'
                   'triggers: [{name: far, kind: rule, topic: /husky_velocity_controller/odom, '
                   'type: nav_msgs/Odometry, when: "pose.pose.position.x > -1000000", hold_off: 1000s}]\n')
    out = tmp_path / 'out'
    bag = real_bag('husky_outdoor_2015.bag')
    assert cli.main(['replay', bag, '--config', str(cfg), '--out', str(out), '--json']) == 0
    paths = log_format.window_files(str(out))
    assert paths
    metadata, _ = log_format.read_window(paths[0])
    assert '/imu/data' not in metadata['topics'] and '/husky_velocity_controller/odom' in metadata['topics']


def test_the_work_of_a_pattern_is_bounded_bounded_repeats_counted_too():
    """Five ``.{0,9999}`` (which passed as bounded) are refused as ``.*.*.*.*x`` is; a pattern's work on a name
    longer than the longest every pattern is tried on is counted before matching, and a name too long for it is
    neither selected nor excluded by it (counted), so one 301-character or 10,000-character topic costs little."""
    from cc_log.base import topic_select
    for pattern in ('.{0,9999}' * 5 + 'x', '.{0,9999}' * 4, '[a-z]{0,40}' * 5, '(.{0,300}|.*)' * 4):
        with pytest.raises(ValueError) as error:
            TopicSelection.parse(['re:' + pattern])
        assert str(error.value).startswith('topics: regular expression ') and 'ways to try' in str(error.value)
    selection = TopicSelection.parse(['re:/cam.*.*.*x', 're:/ok/.*', '!re:.*/skip'])
    assert topic_select.match_work(selection.regex[0].parsed, topic_select.MAX_NAME_CHARS) <= \
        topic_select.MAX_MATCH_WORK
    assert topic_select.match_work(selection.regex[0].parsed, 10000) > topic_select.MAX_MATCH_WORK
    assert selection.regex[0].fullmatch('/cam' + 'a' * 10000) is None  # not tried: its work is beyond the bound
    assert selection.select(['/cam' + 'a' * 251 + 'x', '/cam' + 'a' * 297 + 'x', '/ok/' + 'b' * 9996,
                             '/ok/a/skip']) == ['/cam' + 'a' * 251 + 'x', '/ok/' + 'b' * 9996]
    assert selection.too_long == 2
    TopicSelection.parse(['re:.{0,3}/a{2,5}/[a-z]{0,40}', 're:.*/(camera|lidar)/.*'])  # ordinary ones pass
