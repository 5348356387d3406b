"""What the counters say on /diagnostics (logger/health): WARN whenever a message that belonged in a window is
not on disk and while the logger is paused; the driving topic's silence names where its type is published; a
named topic that never had a message names the published topics that look like it."""
from cc_log.logger import health
from cc_log.logger.health import OK, WARN

ODOMETRY = 'nav_msgs/Odometry'


def stats(**values):
    base = dict(enabled=True, messages_refused=0, last_refused='', messages_shed=0, shed_by_topic={},
                buffer_trimmed=0, buffer_trimmed_silent=0)
    base.update(values)
    return base


def status(overflowed=0, **values):
    counters = stats(**values)
    level, message = health.smart_head(counters)
    return health.worst(level, message, health.not_kept(counters, overflowed))


def test_logging_with_nothing_lost_is_ok():
    assert status() == (OK, 'logging')


def test_a_paused_logger_warns():
    level, message = status(enabled=False)
    assert level == WARN and message.startswith('paused (~enable false)')


def test_every_message_of_a_window_not_on_disk_warns_with_its_count():
    for values, words in ((dict(messages_shed=3, shed_by_topic={'/camera': 3}), '3 messages of windows not written'),
                          (dict(buffer_trimmed=7), '7 messages trimmed from the buffer'),
                          (dict(buffer_trimmed_silent=9), "9 side messages after an open window's end trimmed"),
                          (dict(overflowed=5), '5 messages dropped: intake queue full')):
        level, message = status(**values)
        assert level == WARN and message.startswith('logging; ') and words in message, (values, message)
    level, message = status(overflowed=2, buffer_trimmed=1, enabled=False)
    assert level == WARN and message.count('; ') == 2


def test_the_driving_topic_silent_names_the_topics_of_its_type_once_asked():
    asked = []

    def published():
        asked.append(1)
        return [('/husky_velocity_controller/odom', ODOMETRY), ('/imu', 'sensor_msgs/Imu'), ('/odom', ODOMETRY)]
    watch = health.DrivingWatch('/odom', ODOMETRY, now=0.0, silence=5.0)
    assert watch.check(4.9, 0, published) == '' and watch.state is None and not asked
    text = watch.check(5.0, 0, published)
    assert text == ('no nav_msgs/Odometry on /odom for 5 s; nav_msgs/Odometry is published on '
                    '/husky_velocity_controller/odom: remap the driving topic (/odom:=/husky_velocity_controller/odom)')
    assert watch.state == ('/husky_velocity_controller/odom',) and len(asked) == 1
    assert watch.check(6.0, 0, published).startswith('no nav_msgs/Odometry on /odom for 6 s') and len(asked) == 1
    assert watch.check(7.0, 1, published) == '' and watch.state is None  # it came
    assert watch.check(11.9, 1, published) == ''
    assert watch.check(12.0, 1, published).startswith('no nav_msgs/Odometry on /odom for 5 s')  # silent again


def test_the_driving_topic_silent_with_no_other_topic_of_its_type_says_so():
    watch = health.DrivingWatch('/odom', ODOMETRY, now=0.0)
    assert watch.check(health.SILENCE, 0, []).endswith('; no other topic carries nav_msgs/Odometry')
    assert watch.state == ()
    unknown = health.DrivingWatch('/odom', None, now=0.0)
    assert unknown.check(health.SILENCE, 0, [('/x', ODOMETRY)]) == 'no message on /odom for 5 s; is it published?'


IMU = 'sensor_msgs/Imu'
PUBLISHED = [('/odom', ODOMETRY), ('/imu/data', IMU), ('/camera/imu', IMU), ('/rosout', 'rosgraph_msgs/Log')]


def test_a_named_topic_never_heard_names_the_published_topics_alike_once_asked():
    asked = []

    def published():
        asked.append(1)
        return PUBLISHED
    watch = health.NamedWatch(['/IMU/data', '/scan'], now=0.0, silence=5.0)
    assert watch.check(4.9, {}, published) == [] and watch.state == {} and not asked
    said = watch.check(5.0, {'/scan': 3}, published)  # /scan had messages: never said
    assert said == [('/IMU/data', 'no message on /IMU/data for 5 s; published: /imu/data (sensor_msgs/Imu)')]
    assert len(asked) == 1 and list(watch.state) == ['/IMU/data']
    assert watch.summary(5.0) == 'no message for 5 s on /IMU/data (published: /imu/data (sensor_msgs/Imu))'
    state = dict(watch.state)
    assert watch.check(7.0, {'/scan': 3}, published)[0][1].startswith('no message on /IMU/data for 7 s; ')
    assert watch.state == state and len(asked) == 1  # the same said: the node logs nothing new
    assert watch.check(10.0, {'/scan': 3}, published) and len(asked) == 2  # asked again after `silence`
    assert watch.check(11.0, {'/scan': 3, '/IMU/data': 1}, published) == [] and watch.state == {}  # it came
    assert watch.summary(11.0) == ''
    assert watch.check(100.0, {'/scan': 3, '/IMU/data': 1}, published) == [] and len(asked) == 2  # heard: done


def test_published_topics_alike_are_the_same_name_ignoring_case_the_same_last_component_or_type():
    listed = PUBLISHED + [('/robot/DATA', 'std_msgs/String')]
    assert health.alike('/IMU/data', None, listed) == [('/imu/data', IMU), ('/robot/DATA', 'std_msgs/String')]
    assert health.alike('/imu', IMU, listed) == [('/camera/imu', IMU), ('/imu/data', IMU)]  # last component first
    assert health.alike('/gps/fix', None, listed) == []
    many = [('/imu%d' % i, IMU) for i in range(9)]
    assert len(health.alike('/x', IMU, many)) == health.MAX_ALIKE


def test_a_named_topic_advertised_with_nothing_alike_says_so_and_its_type_finds_others():
    watch = health.NamedWatch(['/gps/fix', '/imu_in'], now=0.0, types={'/imu_in': IMU})
    said = dict(watch.check(health.SILENCE, {}, PUBLISHED + [('/gps/fix', 'sensor_msgs/NavSatFix')]))
    assert said['/gps/fix'] == ('no message on /gps/fix for 5 s; advertised (sensor_msgs/NavSatFix) but nothing came; '
                                'no published topic looks like it')
    assert said['/imu_in'] == ('no message on /imu_in for 5 s; published: /camera/imu (sensor_msgs/Imu), '
                               '/imu/data (sensor_msgs/Imu)')
    assert watch.summary(health.SILENCE).startswith('no message for 5 s on /gps/fix (advertised ')
    assert '; /imu_in (published: /camera/imu ' in watch.summary(health.SILENCE)


def test_the_names_watched_are_those_of_topics_keep_and_routes_not_patterns():
    from cc_log.logger import config
    cfg = config.Config.from_dict({
        'topics': ['/IMU/data', 're:/camera/.*', '/scan'],
        'triggers': [{'name': 'manual', 'kind': 'manual', 'keep': ['/tf', '!/scan']}],
        'routes': [{'name': 'numeric', 'topics': ['/odom', '/IMU/data', 're:/x.*'], 'format': 'json-xz'}]})
    assert cfg.named_topics() == ['/IMU/data', '/scan', '/tf', '/odom']
