"""Routes (cc_log.core.routes): a window cut once into one file per route, each route a topic set in its own
format; the configuration declares them; bad routes are one line naming the entry."""
import pytest

from cc_log.core import config
from cc_log.core.records import LogWindow, Record, Trigger
from cc_log.core.routes import parse_routes, split

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
