"""``cclog top``: a live view of the running cc_log nodes, read from their /diagnostics (needs a roscore).

Per node: its level and message, windows opened and saved, the last trigger, the writer's queue and what
was lost; per topic: messages and MB per second, and messages dropped because the writer fell behind. The
view is built from the key-value pairs the nodes publish (``node_common.Diagnostics``: ``rate <topic> Hz``,
``MB/s <topic>``, ``dropped per topic (writer behind)``), so it needs nothing else from them. ``render`` is
pure; ``watch`` subscribes (rospy).
"""
import collections
import sys
import time

from cc_log.core.safe_input import printable

PREFIX = 'cc_log: '   # the name of every cc_log node's DiagnosticStatus
LEVELS = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}
NODE_KEYS = (('windows opened', 'opened'), ('windows saved', 'saved'), ('last trigger', 'last trigger'),
             ('writer queue', 'writer queue'), ('messages lost', 'lost'))


def _counts(text):
    """``{topic: n}`` of ``'/a: 3, /b: 1'`` ('none': empty)."""
    counts = {}
    for item in str(text).split(', '):
        topic, _, number = item.rpartition(': ')
        if topic and number.isdigit():
            counts[topic] = int(number)
    return counts


def topics_of(values):
    """``{topic: {'Hz', 'MB/s', 'dropped'}}`` of a node's diagnostics values (a dict)."""
    rows = collections.defaultdict(lambda: {'Hz': '-', 'MB/s': '-', 'dropped': 0})
    for key, value in values.items():
        if key.startswith('rate ') and key.endswith(' Hz'):
            rows[key[len('rate '):-len(' Hz')]]['Hz'] = value
        elif key.startswith('MB/s '):
            rows[key[len('MB/s '):]]['MB/s'] = value
    for topic, count in _counts(values.get('dropped per topic (writer behind)', '')).items():
        rows[topic]['dropped'] = count
    return dict(rows)


def render(statuses):
    """The lines of the view of ``statuses`` (``{node name: (level, message, {key: value})}``)."""
    lines = []
    for name in sorted(statuses):
        level, message, values = statuses[name]
        lines.append(printable('%s  [%s] %s' % (name, LEVELS.get(level, level), message)))
        lines.append(printable('  ' + '  '.join('%s %s' % (label, values.get(key, '-')) for key, label in NODE_KEYS)))
        rows = topics_of(values)
        if rows:
            width = max(len(topic) for topic in rows)
            lines.append('  %-*s %10s %10s %9s' % (width, 'topic', 'Hz', 'MB/s', 'dropped'))
            for topic in sorted(rows):
                row = rows[topic]
                lines.append(printable('  %-*s %10s %10s %9s' % (width, topic, row['Hz'], row['MB/s'], row['dropped'])))
    return lines or ['no cc_log node has published on /diagnostics yet']


def watch(once=False, timeout=10.0, period=1.0, out=sys.stdout):
    """Print the view every ``period`` seconds until Ctrl-C (``once``: the first view with every node heard
    within ``timeout`` seconds, then return); 0, or 1 when no cc_log node was heard."""
    import rospy
    from diagnostic_msgs.msg import DiagnosticArray
    statuses = {}

    def heard(array):
        for status in array.status:
            if status.name.startswith(PREFIX):
                statuses[status.name[len(PREFIX):]] = (status.level, status.message,
                                                       dict((kv.key, kv.value) for kv in status.values))
    rospy.init_node('cclog_top', anonymous=True, disable_signals=False)
    rospy.Subscriber('/diagnostics', DiagnosticArray, heard, queue_size=100)
    deadline = time.monotonic() + timeout
    while once and not statuses and time.monotonic() < deadline and not rospy.is_shutdown():
        time.sleep(0.05)
    if once and statuses:
        time.sleep(period)  # the other nodes' next statuses too
    while not rospy.is_shutdown():
        view = render(dict(statuses))
        if not once and out.isatty():
            out.write('\x1b[H\x1b[2J')
        out.write('\n'.join(view) + '\n')
        out.flush()
        if once:
            break
        time.sleep(period)
    return 0 if statuses else 1
