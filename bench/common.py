"""Shared helpers of the bench/ scripts: machine description, data paths and hashes, tables, memory.

Every bench script prints ``machine: ...`` and ``data: ...`` lines first, so each figure in docs/RESULTS.md
names the machine and the data that produced it. Run the scripts with the ROS workspace sourced:

    cd /work/main && source .catkin_ws/devel/setup.bash && export PATH=/usr/bin:$PATH
    python3 bench/<script>.py [--quick]
"""
import hashlib
import os
import platform
import resource
import socket
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SRC = os.path.join(ROOT, 'src')
if SRC not in sys.path:
    sys.path.insert(0, SRC)

DATA = os.path.normpath(os.path.join(ROOT, '..', 'shared', 'data', 'real'))
HUSKY_BAG = os.path.join(DATA, 'husky_outdoor_2015.bag')
HUSKY_ODOM = '/husky_velocity_controller/odom'
HUSKY_IMU = '/imu/data'


def cpu_model():
    try:
        with open('/proc/cpuinfo') as stream:
            for line in stream:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except IOError:
        pass
    return platform.processor() or 'unknown CPU'


def machine():
    """One line: host, CPU model, cores, load, Python and library versions."""
    import numpy
    try:
        import sklearn
        skl = sklearn.__version__
    except ImportError:
        skl = 'none'
    try:
        load = '%.2f' % os.getloadavg()[0]
    except OSError:
        load = '?'
    return ('%s, %s, %d cores, load(1 min) %s at start, Python %s, numpy %s, scikit-learn %s'
            % (socket.gethostname(), cpu_model(), os.cpu_count() or 0, load, platform.python_version(),
               numpy.__version__, skl))


def sha12(path):
    digest = hashlib.sha256()
    with open(path, 'rb') as stream:
        for block in iter(lambda: stream.read(1 << 20), b''):
            digest.update(block)
    return digest.hexdigest()[:12]


def describe_data(path, note=''):
    """``data: <file> (sha256 <12 hex>..., <bytes> bytes)<note>`` for a file."""
    shown = os.path.relpath(path, ROOT) if path.startswith(ROOT) else path
    return 'data: %s (sha256 %s..., %d bytes)%s' % (shown, sha12(path), os.path.getsize(path),
                                                    (' ' + note) if note else '')


def revision():
    """The commit of this tree (``git describe --always --dirty``), or 'unknown' outside git."""
    import subprocess
    try:
        return subprocess.run(['git', '-C', ROOT, 'describe', '--always', '--dirty'], stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, universal_newlines=True).stdout.strip() or 'unknown'
    except OSError:
        return 'unknown'


def header(title, data_lines=(), argv=None):
    """Print the standard header of a bench script."""
    print('# %s' % title)
    words = [os.path.relpath(os.path.abspath(sys.argv[0]), ROOT)] + list(sys.argv[1:] if argv is None else argv)
    print('command: python3 %s' % ' '.join(words))
    print('machine: %s' % machine())
    for line in data_lines:
        print(line)
    print()
    sys.stdout.flush()


def table(headers, rows, title=None):
    """Print rows (lists) as an aligned plain-text table (also valid Markdown)."""
    cells = [[str(h) for h in headers]] + [[_fmt(value) for value in row] for row in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]
    if title:
        print(title)
    print('| ' + ' | '.join(cell.ljust(w) for cell, w in zip(cells[0], widths)) + ' |')
    print('|' + '|'.join('-' * (w + 2) for w in widths) + '|')
    for row in cells[1:]:
        print('| ' + ' | '.join(cell.ljust(w) for cell, w in zip(row, widths)) + ' |')
    print()
    sys.stdout.flush()


def count_of(part, whole):
    """``'part/whole'`` (``'3/18'``), or ``'-'`` when there is no whole."""
    return '%d/%d' % (part, whole) if whole else '-'


def _fmt(value):
    if isinstance(value, float):
        if value != value:
            return 'n/a'
        if abs(value) >= 100:
            return '%.0f' % value
        if abs(value) >= 10:
            return '%.1f' % value
        return '%.2f' % value
    return str(value)


def peak_rss_mb():
    """Peak resident set size of this process so far, MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def cpu_seconds():
    """User + system CPU seconds of this process so far."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


class Timer(object):
    """Wall and process CPU seconds of a with-block."""

    def __enter__(self):
        self.wall0, self.cpu0 = time.perf_counter(), cpu_seconds()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self.wall0
        self.cpu = cpu_seconds() - self.cpu0
        return False


def husky_records(topics=(HUSKY_ODOM,)):
    """Record(stamp, topic, msg) of the Husky bag's ``topics``, in bag order."""
    from cc_log.storage.bag import bagio
    return list(bagio.read_messages(HUSKY_BAG, list(topics)))


def split_half(records, topic):
    """(first half, second half) of records by the time of ``topic``'s messages."""
    stamps = [r.stamp for r in records if r.topic == topic]
    half = stamps[0] + (stamps[-1] - stamps[0]) / 2.0
    return [r for r in records if r.stamp < half], [r for r in records if r.stamp >= half]


def write_bag(path, records, compression='none'):
    """Write records to a bag (bag time = record stamp); return its size in bytes."""
    import rosbag
    import rospy
    with rosbag.Bag(path, 'w', compression=compression) as bag:
        for record in records:
            bag.write(record.topic, record.msg, rospy.Time.from_sec(record.stamp))
    return os.path.getsize(path)


# -- simulated runs and smart-logger replay in memory ------------------------------------------------------

def sim_records(config):
    """(records, truth) of a whole simulated run: Record(stamp, topic, msg) in time order (header stamps)."""
    from cc_log import sim
    from cc_log.base.records import Record
    simulator = sim.Simulator(config)
    records = [Record(stamp, topic, msg) for topic, stamp, msg in simulator.messages()]
    return records, simulator.truth


def window_vectors(records, topic, config, stride=1):
    """(stamps, vectors) of sliding windows over ``topic``'s odometry, one every ``stride`` messages, computed
    as every mode computes them (``features.FeatureStream``: whole windows since the last restart)."""
    import numpy as np
    from cc_log.features import FeatureStream
    stream = FeatureStream(config, every=stride)
    stamps, vectors = [], []
    for record in records:
        if record.topic != topic:
            continue
        vector = stream.add(record.msg, record.stamp)
        if vector is not None:
            stamps.append(record.stamp)
            vectors.append(vector)
    return np.array(stamps), np.array(vectors)


def smart_replay(model, records, driving_topic, directory, side_topics=(), fmt='json-xz', pre='100',
                 post='100', retrigger='every', triggers=()):
    """Feed records (decoded or serialized) to a SmartLogger through ``offline.replay.replay_records``, the
    replay of ``cclog replay``; return a dict: stats (SmartLogger.stats()), windows [{start, end, messages,
    path, bytes, triggers: [stamps]}]. ``triggers``: more triggers beside ``model``'s classifier."""
    from cc_log.storage import log_format
    from cc_log.logger.smart import SmartLogger
    from cc_log.offline.replay import replay_records
    logger = SmartLogger(model, directory, fmt, pre, post, driving_topic=driving_topic,
                         side_topics=tuple(side_topics), retrigger=retrigger, triggers=triggers, wait_for_writer=True)
    windows = replay_records(logger, records)['windows']
    for window in windows:
        window['bytes'] = os.path.getsize(window['path'])
        meta, _ = log_format.read_window(window['path'])
        window['triggers'] = [t['stamp'] for t in meta.get('triggers', [])]
    return {'stats': logger.stats(), 'windows': windows}


def kept_messages(records, topic, windows, truth, pre, post):
    """(messages of ``topic`` inside saved windows, messages of ``topic`` within [start - pre, end + post] of
    any anomaly of ``truth``): what was kept against what the anomalies needed (pre, post in seconds)."""
    stamps = [r.stamp for r in records if r.topic == topic]
    spans = [(w['start'], w['end']) for w in windows]
    needed = [(e['start'] - pre, e['end'] + post) for e in truth]
    kept = sum(1 for t in stamps if any(a <= t <= b for a, b in spans))
    need = sum(1 for t in stamps if any(a <= t <= b for a, b in needed))
    return kept, need


def match_anomalies(truth, windows, reach):
    """Which anomalies were caught (a trigger in [start, end + reach]) and kept (every message of
    [start, end] inside saved windows); which windows are false (no trigger near any anomaly).

    Returns (per-anomaly list of dicts {type, start, end, caught, kept, delay}, false window count)."""
    out = []
    triggers = sorted(t for w in windows for t in w['triggers'])
    for entry in truth:
        near = [t for t in triggers if entry['start'] <= t <= entry['end'] + reach]
        kept = any(w['start'] <= entry['start'] and w['end'] >= entry['end'] for w in windows)
        out.append({'type': entry['type'], 'start': entry['start'], 'end': entry['end'], 'caught': bool(near),
                    'kept': kept, 'delay': (near[0] - entry['start']) if near else float('nan')})
    false = 0
    for w in windows:
        if not any(e['start'] <= t <= e['end'] + reach for t in w['triggers'] for e in truth):
            false += 1
    return out, false
