"""What a completed window gets before the writer takes it: thinned to the memory budget when the writer has
fallen behind (``thin``), and the newest message of each latched topic at its start (``Latched``), as
``rosbag record`` writes latched messages when it subscribes. Pure: used by ``smart.SmartLogger``.
"""
import collections

from cc_log.base import raw_message
from cc_log.base.topic_select import TopicSelection

__all__ = ['thin', 'CarriedDrops', 'restrict', 'Latched', 'any_latched', 'HEAVY_BYTES', 'LATCHED_KEPT']

HEAVY_BYTES = 64 * 1024  # a message this large (an image, a cloud, a scan) may be dropped when the writer falls behind
LATCHED_KEPT = 4        # messages remembered per latched topic (the newest before a window's start is written)


def thin(window, room):
    """``{topic: messages dropped}`` from ``window`` so that its records cost at most ``room`` bytes: its heavy
    messages (``HEAVY_BYTES`` or more: images, clouds, scans) are thinned evenly, over the window, until it
    fits; light ones (odometry, IMU, diagnostics) are always kept."""
    if not window.records:
        return {}
    cost = sum(record.cost for record in window.records)
    if cost <= room:
        return {}
    heavy = [record.cost >= HEAVY_BYTES for record in window.records]
    heavy_bytes = sum(record.cost for record, big in zip(window.records, heavy) if big)
    if not heavy_bytes:
        return {}
    keep = max(0.0, min(1.0, (room - (cost - heavy_bytes)) / float(heavy_bytes)))
    kept, shed, share = [], collections.Counter(), 0.0
    for record, big in zip(window.records, heavy):
        if big:
            share += keep
            if share < 1.0:
                shed[record.topic] += 1
                continue
            share -= 1.0
        kept.append(record)
    window.records = kept
    return dict(shed)


class CarriedDrops(object):
    """What ``thin`` dropped from a part it left empty (no file is written for an empty part) goes in the metadata
    of the window's next part, so that every drop is said in a file: ``said(window, shed)`` -> the counts to write
    with ``window`` (``{}`` for an empty part that is not the window's last)."""

    def __init__(self):
        self._held = {}  # window key -> Counter of drops not said yet

    def said(self, window, shed):
        counts = self._held.pop(window.key, collections.Counter())
        counts.update(shed)
        if not window.records and not window.final:
            self._held[window.key] = counts
            return {}
        return dict(counts)


def selections(keep):
    """``keep`` (``{trigger name: topic_select.TopicSelection or topic names}``) as ``{name: TopicSelection}``."""
    return dict((name, topics if isinstance(topics, TopicSelection) else TopicSelection(topics))
                for name, topics in (keep or {}).items())


def restrict(window, keep, driving_topic):
    """``window`` with only ``driving_topic`` and the topics its triggers keep, when each of its triggers has
    its own ``keep`` (``{trigger name: topic_select.TopicSelection}``; a window any other trigger opened or
    extended keeps every topic): a collision keeps the cameras, a silent topic only the diagnostics."""
    names = set(trigger.name or trigger.reason for trigger in window.triggers)
    if not keep or not names or not names <= set(keep):
        return window
    selections = [keep[name] for name in names]
    kept = dict((topic, topic == driving_topic or any(selection.matches(topic) for selection in selections))
                for topic in set(record.topic for record in window.records))
    window.records = [record for record in window.records if kept[record.topic]]
    return window


def any_latched(connections):
    """Whether any of ``connections`` latches."""
    distinct = dict(zip(map(id, connections), connections)).values()
    return any(raw_message.is_latched(connection) for connection in distinct)


class Latched(object):
    """The last LATCHED_KEPT records of each latched topic (connection header ``latching: '1'``: ``/tf_static``,
    maps), to be written at the start of every window."""

    def __init__(self):
        self._topics = {}  # latched topic -> its last records

    def note(self, topic, record):
        """Remember ``record`` of the latched ``topic``."""
        self._topics.setdefault(topic, collections.deque(maxlen=LATCHED_KEPT)).append(record)

    def first_in(self, window, streams):
        """``window`` with, first, the newest message of each latched topic from before its start (not one it
        holds), restamped at its start; only in the first part of a window whose parts go into one file
        (``streams``: the format writes parts into one file)."""
        if not self._topics or not window.records or (window.part > 1 and streams):
            return window
        held = set(id(record) for record in window.records)
        start = window.start
        first = []
        for topic in sorted(self._topics):
            before = [record for record in self._topics[topic] if record.stamp <= start and id(record) not in held]
            if before:
                first.append(before[-1]._replace(stamp=start))
        if first:
            window.records[:0] = first
        return window
