"""cclog top (cc_log.offline.top): the live view built from the nodes' /diagnostics values."""
from cc_log.offline import top

VALUES = {'windows opened': '3', 'windows saved': '2', 'last trigger': 'bumper: collision at 2026-11-26T08:00:00Z',
          'writer queue': '1', 'messages lost': '0', 'rate /odom Hz': '100.00', 'rate /camera Hz': '29.97',
          'MB/s /odom': '0.073', 'MB/s /camera': '27.600', 'dropped per topic (writer behind)': '/camera: 12'}


def test_topics_come_from_the_rate_bytes_and_dropped_values():
    rows = top.topics_of(VALUES)
    assert rows == {'/odom': {'Hz': '100.00', 'MB/s': '0.073', 'dropped': 0},
                    '/camera': {'Hz': '29.97', 'MB/s': '27.600', 'dropped': 12}}
    assert top.topics_of({'dropped per topic (writer behind)': 'none'}) == {}


def test_the_view_has_a_block_per_node_and_a_row_per_topic():
    lines = top.render({'smart_logger': (1, 'writer behind', VALUES), 'record_1': (0, 'logging', {})})
    assert lines[0] == 'record_1  [OK] logging'
    block = lines[lines.index('smart_logger  [WARN] writer behind'):]
    assert 'opened 3  saved 2  last trigger bumper: collision at 2026-11-26T08:00:00Z' in block[1]
    assert block[2].split() == ['topic', 'Hz', 'MB/s', 'dropped']
    assert block[3].split() == ['/camera', '29.97', '27.600', '12'] and block[4].split()[0] == '/odom'
    assert top.render({}) == ['no cc_log node has published on /diagnostics yet']


class _Status(object):
    """A diagnostic_msgs/DiagnosticStatus as rospy hands it over (name, level, message, values)."""

    def __init__(self, name, message='logging', values=(), level=0):
        self.name, self.level, self.message = name, level, message
        self.values = [_KeyValue(key, value) for key, value in values]


class _KeyValue(object):
    def __init__(self, key, value):
        self.key, self.value = key, value


def _render_kept(statuses, now=0.0):
    """The view of ``statuses`` heard at ``now``: through ``Statuses`` where there is one, else (the view before
    bounds) each status as it came."""
    if hasattr(top, 'Statuses'):
        kept = top.Statuses()
        kept.heard(statuses, now)
        return top.render(kept.view(now))
    return top.render({status.name[len(top.PREFIX):]: (status.level, status.message,
                                                       {kv.key: kv.value for kv in status.values})
                       for status in statuses})


def test_a_huge_status_gives_a_bounded_view():
    # one 2.3 MB status: a long message, a long trigger, a long topic name and 20,000 values
    huge = 'x' * 600000
    values = [('last trigger', huge), ('rate /%s Hz' % huge, '1.0')]
    values += [('rate /t%d Hz' % i, '%d' % i) for i in range(20000)]
    lines = _render_kept([_Status(top.PREFIX + 'n' + huge, huge, values)])
    assert sum(map(len, lines)) < 1000000
    assert max(map(len, lines)) <= 10 * top.MAX_TEXT


def test_statuses_are_bounded_and_forgotten():
    kept = top.Statuses()
    kept.heard([_Status(top.PREFIX + 'node%d' % i) for i in range(1000)], 0.0)
    assert len(kept.view(0.0)) == top.MAX_NODES
    assert 'node999' in kept.view(0.0) and 'node0' not in kept.view(0.0)
    kept.heard([_Status(top.PREFIX + 'late', 'still here'), _Status('other: not cc_log')], top.FORGET_AFTER - 1.0)
    assert set(kept.view(top.FORGET_AFTER + 0.5)) == {'late'}
    assert kept.view(top.FORGET_AFTER + 0.5)['late'] == (0, 'still here', {})
    assert kept.view(2 * top.FORGET_AFTER) == {}
