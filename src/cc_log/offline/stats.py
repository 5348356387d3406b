"""``cclog stats DIR``: what a robot did and what cc_log kept, from the context track and the windows.

``run_stats(directory, since=None, until=None, odom=None)`` returns a dict:

- ``distance_m``: distance driven, from the odometry of the context track (``<DIR>/context/*.bag``; the
  odometry topic with the most messages unless ``odom`` names one): between consecutive samples, the chord
  between the positions lengthened to the arc of a constant turn (``chord * (dyaw/2) / sin(dyaw/2)``),
  which is exact for a base driving arcs between samples (1 Hz odometry of a turning robot loses nothing);
- ``moving_s``, ``stopped_s``: time between samples with an average speed at or above ``MOVING_SPEED``
  m/s, or below; ``gap_s``: time between samples more than ``MAX_GAP`` s apart (no data: the logger was
  off), counted in neither;
- ``windows``: windows (file parts of one window counted once) by trigger name, and per hour of the covered
  time (``hours``: from the first to the last stamp of the context track and windows in range);
- ``stored_bytes``: bytes on disk of the window and context files in range; ``rosbag_record_bytes``: an
  estimate of what ``rosbag record`` of the same topics would have stored over the covered time: for each
  topic, its full rate (measured inside windows, which hold every message; else in the context track, for a
  topic it does not thin) times the covered seconds times its mean serialized size plus ``ROSBAG_OVERHEAD``
  bytes per message (record header and index entry), uncompressed.

``since`` / ``until``: float seconds (stamps) bounding what is counted; files are read only when their span
overlaps. A window file written by this cc_log is not read past its metadata (``log_format.read_metadata``: its
summary holds the per-topic figures); an older one is read whole. Unreadable files are skipped and listed in
``skipped`` ([path, why]). Pure apart from rosbag.
"""
import collections
import io
import math
import os

from cc_log.storage.bag import bagio
from cc_log.storage import context_track, log_format, window_info

__all__ = ['run_stats', 'odometry_summary', 'parse_time', 'format_text', 'MOVING_SPEED', 'MAX_GAP', 'ROSBAG_OVERHEAD']

ODOMETRY = 'nav_msgs/Odometry'
MOVING_SPEED = 0.05   # m/s: slower between two samples is stopped
MAX_GAP = 10.0        # s: samples further apart are a gap in the data, neither moving nor stopped
ROSBAG_OVERHEAD = 57  # bytes per message in a rosbag: record header (op, conn, time, lengths) 45 + index entry 12


def _yaw(orientation):
    q = orientation
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _arc(chord, dyaw):
    """Length of a constant-curvature arc with ``chord`` and heading change ``dyaw``."""
    half = abs(math.atan2(math.sin(dyaw), math.cos(dyaw))) / 2.0
    return chord if half < 1e-9 else chord * half / math.sin(half)


def odometry_summary(samples, moving_speed=MOVING_SPEED, max_gap=MAX_GAP):
    """``{distance_m, moving_s, stopped_s, gap_s, samples}`` of ``[(stamp, x, y, yaw)]`` (sorted here)."""
    samples = sorted(samples)
    distance = moving = stopped = gap = 0.0
    for (t0, x0, y0, a0), (t1, x1, y1, a1) in zip(samples, samples[1:]):
        dt = t1 - t0
        if dt <= 0:
            continue
        if dt > max_gap:
            gap += dt
            continue
        step = _arc(math.hypot(x1 - x0, y1 - y0), a1 - a0)
        distance += step
        if step / dt >= moving_speed:
            moving += dt
        else:
            stopped += dt
    return {'distance_m': distance, 'moving_s': moving, 'stopped_s': stopped, 'gap_s': gap,
            'samples': len(samples)}


def parse_time(value, name):
    """Float seconds of ``1600000000.5`` or a UTC time ``2020-09-13T12:26:40[.5]Z``; ValueError('<name>: ...')."""
    import datetime
    text = str(value).strip()
    try:
        return float(text)
    except ValueError:
        pass
    for layout in ('%Y-%m-%dT%H:%M:%S.%fZ', '%Y-%m-%dT%H:%M:%SZ', '%Y-%m-%dT%H:%MZ', '%Y-%m-%dZ', '%Y-%m-%d'):
        try:
            moment = datetime.datetime.strptime(text, layout)
        except ValueError:
            continue
        return (moment - datetime.datetime(1970, 1, 1)).total_seconds()
    raise ValueError('%s: %r is not seconds (1600000000.5) or a UTC time (2020-09-13T12:26:40Z)' % (name, value))


def _serialized_size(msg):
    buffer = io.BytesIO()
    msg.serialize(buffer)
    return buffer.tell()


def _inside(stamp, since, until):
    return (since is None or stamp >= since) and (until is None or stamp <= until)


class _Topics(object):
    """Per topic: messages, seconds spanned, serialized bytes (to estimate full rates and sizes)."""

    def __init__(self):
        self.count = collections.Counter()
        self.bytes = collections.Counter()
        self.seconds = collections.Counter()

    def rate_and_size(self, topic):
        if not self.count[topic] or not self.seconds[topic]:
            return None
        return self.count[topic] / self.seconds[topic], self.bytes[topic] / float(self.count[topic])


def _context(directory, since, until, odom, skipped):
    """Odometry samples, per-topic figures of unthinned topics, bytes, first/last stamps of the context track."""
    folder = os.path.join(str(directory), context_track.SUBDIRECTORY)
    samples = collections.defaultdict(list)
    topics, stored, stamps = _Topics(), 0, []
    for path in log_format.window_files(folder):
        try:
            bag = bagio.open_bag(path)
        except ValueError as error:
            skipped.append([path, str(error)])
            continue
        try:
            types = bagio.topics_of(bag)
            spans = collections.defaultdict(list)
            for topic, msg, t in bag.read_messages():
                stamp = bagio.stamp_of(msg, t.to_sec())
                if not _inside(stamp, since, until):
                    continue
                spans[topic].append(stamp)
                topics.count[topic] += 1
                topics.bytes[topic] += _serialized_size(msg)
                if types.get(topic) == ODOMETRY and (odom is None or topic == odom):
                    pose = msg.pose.pose
                    samples[topic].append((stamp, pose.position.x, pose.position.y, _yaw(pose.orientation)))
            for topic, times in spans.items():
                topics.seconds[topic] += max(times) - min(times)
                stamps += [min(times), max(times)]
            if spans:
                stored += os.path.getsize(path)
        except Exception as error:  # a damaged bag: skipped, said
            skipped.append([path, (str(error).strip().splitlines() or [type(error).__name__])[0]])
        finally:
            bag.close()
    return samples, topics, stored, stamps


def _windows(directory, since, until, skipped):
    """Windows by trigger, per-topic figures (every message of a window), bytes, first/last stamps. A window's
    figures come from its metadata's summary (``window_info.summary_of``: its messages are not read) when it
    holds one, else from its records."""
    by_trigger, seen = collections.Counter(), {}  # window -> the trigger names counted
    topics, stored, stamps = _Topics(), 0, []
    files = log_format.window_files(str(directory))
    grouped = dict((path, tuple(group)) for group in log_format.window_sets(files) for path in group)
    for path in files:
        try:
            metadata = log_format.read_metadata(path)
            summary = window_info.summary_of(metadata)
            if summary is None:  # a file of an older cc_log: its records
                metadata, records = log_format.read_window(path)
        except ValueError as error:
            skipped.append([path, str(error)])
            continue
        if not _inside(metadata['start'], since, until) and not _inside(metadata['end'], since, until):
            continue
        stored += os.path.getsize(path)
        stamps += [metadata['start'], metadata['end']]
        first = metadata['triggers'][0]['stamp'] if metadata['triggers'] else metadata['start']
        names = metadata.get('names') or []
        group = grouped.get(path, ())  # a window's files (routes, split at split_mb) and the parts of one are one
        key = group if len(group) > 1 else (first, tuple(names))
        counted = seen.setdefault(key, set())
        by_trigger.update(name for name in names if name not in counted)
        counted.update(names)
        if summary is not None:
            for topic, (first_stamp, last_stamp) in summary.topic_spans.items():
                topics.count[topic] += summary.counts[topic]
                topics.bytes[topic] += summary.topic_bytes[topic]
                topics.seconds[topic] += last_stamp - first_stamp
            continue
        spans = collections.defaultdict(list)
        for record in records:
            spans[record.topic].append(record.stamp)
            topics.count[record.topic] += 1
            topics.bytes[record.topic] += _serialized_size(record.msg)
        for topic, times in spans.items():
            topics.seconds[topic] += max(times) - min(times)
    untriggered = sum(1 for counted in seen.values() if not counted)
    if untriggered:
        by_trigger['window'] += untriggered
    return by_trigger, len(seen), topics, stored, stamps


def run_stats(directory, since=None, until=None, odom=None):
    """The statistics of a cc_log directory (see the module docstring); ValueError('DIR: ...') when it is not
    a directory or holds no cc_log file in range."""
    directory = str(directory)
    if not os.path.isdir(directory):
        raise ValueError('%s: not a directory' % directory)
    if since is not None and until is not None and until < since:
        raise ValueError('until: %r is before since %r' % (until, since))
    skipped = []
    samples, context_topics, context_bytes, context_stamps = _context(directory, since, until, odom, skipped)
    by_trigger, window_count, window_topics, window_bytes, window_stamps = _windows(directory, since, until,
                                                                                    skipped)
    stamps = context_stamps + window_stamps
    if not stamps:
        raise ValueError('%s: no context track or window files%s' % (
            directory, ' in the time range' if since is not None or until is not None else ''))
    start, end = min(stamps), max(stamps)
    seconds = end - start
    if odom is None and samples:
        odom = max(samples, key=lambda topic: len(samples[topic]))
    motion = odometry_summary(samples.get(odom, []))
    rosbag_bytes = 0.0
    estimated = {}
    for topic in sorted(set(window_topics.count) | set(context_topics.count)):
        figures = window_topics.rate_and_size(topic) or context_topics.rate_and_size(topic)
        if figures is None:
            continue
        rate, size = figures
        estimated[topic] = {'rate_hz': rate, 'message_bytes': size}
        rosbag_bytes += rate * seconds * (size + ROSBAG_OVERHEAD)
    hours = seconds / 3600.0
    stored = context_bytes + window_bytes
    result = collections.OrderedDict([
        ('directory', directory), ('start', start), ('end', end),
        ('start_utc', window_info.utc_text(start)), ('end_utc', window_info.utc_text(end)),
        ('hours', hours), ('odometry_topic', odom), ('odometry_samples', motion['samples']),
        ('distance_m', motion['distance_m']), ('moving_s', motion['moving_s']), ('stopped_s', motion['stopped_s']),
        ('gap_s', motion['gap_s']), ('windows', window_count), ('windows_by_trigger', dict(by_trigger)),
        ('windows_per_hour', dict((name, count / hours) for name, count in by_trigger.items()) if hours else {}),
        ('stored_bytes', stored), ('window_bytes', window_bytes), ('context_bytes', context_bytes),
        ('rosbag_record_bytes', int(round(rosbag_bytes))),
        ('stored_fraction', stored / rosbag_bytes if rosbag_bytes else None),
        ('topics', estimated), ('skipped', skipped)])
    return result


def format_text(result):
    """The human-readable lines of ``run_stats``'s result."""
    def size(count):
        return '%.1f MB' % (count / 1e6) if count >= 1e5 else '%d bytes' % count
    lines = ['%s: %s .. %s (%.2f h)' % (result['directory'], result['start_utc'], result['end_utc'], result['hours']),
             'distance   %.1f m (odometry %s, %d samples)' % (result['distance_m'], result['odometry_topic'] or 'none',
                                                              result['odometry_samples']),
             'moving     %.0f s, stopped %.0f s, no data %.0f s' % (
                 result['moving_s'], result['stopped_s'], result['gap_s']),
             'windows    %d%s' % (result['windows'], ''.join(
                 '; %s %d (%.2f/h)' % (name, count, result['windows_per_hour'].get(name, 0.0))
                 for name, count in sorted(result['windows_by_trigger'].items()))),
             'stored     %s (windows %s, context %s); rosbag record: about %s%s' % (
                 size(result['stored_bytes']), size(result['window_bytes']), size(result['context_bytes']),
                 size(result['rosbag_record_bytes']),
                 ' (%.2f%%)' % (100.0 * result['stored_fraction']) if result['stored_fraction'] else '')]
    lines += ['skipped    %s: %s' % (path, why) for path, why in result['skipped']]
    return lines
