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
