"""What the counters say on /diagnostics (logger/health): WARN whenever a message that belonged in a window is
not on disk and while the logger is paused; the driving topic's silence names where its type is published."""
from cc_log.logger import health
from cc_log.logger.health import OK, WARN

ODOMETRY = 'nav_msgs/Odometry'


def stats(**values):
    base = dict(enabled=True, messages_refused=0, last_refused='', messages_shed=0, shed_by_topic={},
                buffer_trimmed=0)
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
