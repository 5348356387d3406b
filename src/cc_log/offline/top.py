"""``cclog top``: a live view of the running cc_log nodes, read from their /diagnostics (needs a roscore).

Per node: its level and message, windows opened and saved, the last trigger, the writer's queue and what
was lost; per topic: messages and MB per second, and messages dropped because the writer fell behind. The
view is built from the key-value pairs the nodes publish (``node_common.Diagnostics``: ``rate <topic> Hz``,
``MB/s <topic>``, ``dropped per topic (writer behind)``), so it needs nothing else from them. ``render`` is
pure; ``watch`` subscribes (rospy). What a publisher sends is bounded (``Statuses``): each text cut to
MAX_TEXT characters, at most MAX_VALUES values per node and MAX_NODES nodes kept, a node not heard for
FORGET_AFTER seconds forgotten.
"""
import collections
import itertools
import sys
import threading
import time

from cc_log.base.safe_input import printable

PREFIX = 'cc_log: '   # the name of every cc_log node's DiagnosticStatus
LEVELS = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}
NODE_KEYS = (('windows opened', 'opened'), ('windows saved', 'saved'), ('last trigger', 'last trigger'),
             ('writer queue', 'writer queue'), ('messages lost', 'lost'))
#: Longest name, message, key or value kept from a status (characters; longer ones end in '...').
MAX_TEXT = 300
#: Most key-value pairs kept of one node's status (a cc_log node publishes ~20 plus 2 per topic).
MAX_VALUES = 400
#: Most nodes kept (the newest heard replaces the one heard longest ago).
MAX_NODES = 64
#: Seconds after which a node no longer heard leaves the view.
FORGET_AFTER = 30.0


def _cut(text):
    """``text`` as str of at most MAX_TEXT characters."""
    text = text if isinstance(text, str) else str(text)[:MAX_TEXT + 1]
    return text if len(text) <= MAX_TEXT else text[:MAX_TEXT - 3] + '...'


class Statuses(object):
    """The latest status of each cc_log node heard, bounded (``MAX_TEXT``, ``MAX_VALUES``, ``MAX_NODES``,
    ``FORGET_AFTER``): ``heard(statuses, now)`` takes a DiagnosticArray's statuses, ``view(now)`` gives
    ``render``'s ``{node name: (level, message, {key: value})}``."""

    def __init__(self):
        self._latest = collections.OrderedDict()  # name -> (time heard, (level, message, values)), oldest first
        self._lock = threading.Lock()  # heard on rospy's thread, viewed on the caller's

    def heard(self, statuses, now):
        """Keep the cc_log statuses among ``statuses`` (objects with name, level, message, values), heard at
        ``now`` (seconds)."""
        for status in statuses:
            name = status.name
            if not isinstance(name, str) or not name.startswith(PREFIX):
                continue
            values = {}
            for kv in itertools.islice(status.values, MAX_VALUES):
                values[_cut(kv.key)] = _cut(kv.value)
            name, kept = _cut(name[len(PREFIX):]), (status.level, _cut(status.message), values)
            with self._lock:
                self._latest.pop(name, None)
                self._latest[name] = (now, kept)
                while len(self._latest) > MAX_NODES:
                    self._latest.popitem(last=False)

    def view(self, now):
        """``{node name: (level, message, {key: value})}`` of the nodes heard within FORGET_AFTER of ``now``."""
        with self._lock:
            while self._latest and next(iter(self._latest.values()))[0] < now - FORGET_AFTER:
                self._latest.popitem(last=False)
            return {name: status for name, (_, status) in self._latest.items()}


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
    kept = Statuses()

    def heard(array):
        kept.heard(array.status, time.monotonic())
    rospy.init_node('cclog_top', anonymous=True, disable_signals=False)
    rospy.Subscriber('/diagnostics', DiagnosticArray, heard, queue_size=100)
    deadline = time.monotonic() + timeout
    while once and not kept.view(time.monotonic()) and time.monotonic() < deadline and not rospy.is_shutdown():
        time.sleep(0.05)
    if once and kept.view(time.monotonic()):
        time.sleep(period)  # the other nodes' next statuses too
    statuses = {}
    while not rospy.is_shutdown():
        statuses = kept.view(time.monotonic())
        view = render(statuses)
        if not once and out.isatty():
            out.write('\x1b[H\x1b[2J')
        out.write('\n'.join(view) + '\n')
        out.flush()
        if once:
            break
        time.sleep(period)
    return 0 if statuses else 1
