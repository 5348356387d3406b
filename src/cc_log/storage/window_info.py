"""The metadata every window file carries: what it is built from (``window_metadata``, ``Contents``, gathered a
part at a time), how a reader checks it (``check_metadata``) and the summary ``cclog info`` and ``stats`` read
instead of the messages (``summary_of``, ``merged_summary``). Pure."""
import collections
import datetime
import io
import math

from cc_log import __version__
from cc_log.base import msg_codec, raw_message, why as why_


def utc_text(stamp):
    """``1432236698.0275`` -> ``'2015-05-21T19:31:38.027500Z'`` (ISO 8601, UTC)."""
    moment = datetime.datetime(1970, 1, 1) + datetime.timedelta(seconds=float(stamp))
    return moment.strftime('%Y-%m-%dT%H:%M:%S.%fZ')


def _score(value):
    if value is None:
        return None
    return msg_codec.encode_float(float(value))


def window_metadata(window, codec, extra=None, triggers=None):
    """The metadata every window file carries; keys of ``extra`` (JSON-able) are added, overriding.

    topics, types ({topic: type}), counts ({topic: messages}), count, start/end (float seconds of the first/last
    record), start_utc/end_utc, triggers ([{stamp, reason, score, name, why}]; name only for triggers that have one,
    why (``base.why.bounded``) only for those that say one, the first and the most anomalous of each trigger:
    ``base.why.said``), reasons and names (distinct, in order: every trigger of
    the window), part (0, or 1, 2, ... for a split window), codec, cc_log_version, and the summary ``cclog info``
    and ``stats`` read instead of the messages (``SUMMARY_KEYS``, see ``Contents``). ``triggers``: those to say
    (default: the window's).
    """
    contents = Contents()
    contents.add(window.records)
    return contents.metadata(window.triggers if triggers is None else triggers, getattr(window, 'part', 0), codec,
                             extra)


#: Metadata keys of the summary of a window's records (``Contents``): what ``cclog info`` and ``cclog stats`` read
#: instead of decoding every message. Present only when they describe the records in the file (``read_metadata``).
SUMMARY_KEYS = ('topic_bytes', 'topic_spans', 'raw_json_bytes')
#: The row-JSON bytes of a topic's records are measured on its first JSON_SAMPLE_FIRST records and then on one in
#: JSON_SAMPLE_EVERY (each decoded if held as bytes); the rest are scaled by their serialized bytes.
JSON_SAMPLE_FIRST = 32
JSON_SAMPLE_EVERY = 64


class Contents(object):
    """What the metadata says of a window's records, gathered a part at a time: types, counts, span, and the
    summary (``SUMMARY_KEYS``): per topic the serialized bytes (``topic_bytes``: of each record's bytes, or of its
    message serialized) and the first and last stamps (``topic_spans``: [min, max]), and ``raw_json_bytes``, the
    row-per-message JSON bytes of the records (``msg_codec.row_json_bytes``) estimated per topic from a sample
    (``JSON_SAMPLE_FIRST``, ``JSON_SAMPLE_EVERY``): exact for a topic of at most JSON_SAMPLE_FIRST records, else
    the sampled records' JSON bytes per serialized byte times the topic's serialized bytes."""

    def __init__(self):
        self.types, self.counts = {}, {}
        self.count = 0
        self.start = self.end = None
        self._sizes = {}  # topic -> [serialized bytes, min stamp, max stamp, sampled records, bytes, JSON bytes]
        self._summary = True  # False once a record could not be measured (no summary is written)
        self._json = None  # msg_codec.RowJsonCounter, made when first needed

    def add(self, records):
        """Take the next records of the window, in window order."""
        types, counts, sizes = self.types, self.counts, self._sizes
        for record in records:
            topic, stamp = record.topic, record.stamp
            if topic not in types:
                types[topic] = raw_message.type_of(record)
                sizes[topic] = [0, stamp, stamp, 0, 0, 0]
            seen = counts.get(topic, 0)
            counts[topic] = seen + 1
            entry = sizes[topic]
            if stamp < entry[1]:
                entry[1] = stamp
            elif stamp > entry[2]:
                entry[2] = stamp
            sampled = seen < JSON_SAMPLE_FIRST or seen % JSON_SAMPLE_EVERY == 0
            if sampled or record.raw is None:
                self._measure(entry, record, sampled)
            else:  # the live path: bytes, not sampled
                entry[0] += len(record.raw)
        if records:
            self.count += len(records)
            if self.start is None:
                self.start = records[0].stamp
            self.end = records[-1].stamp

    def no_summary(self):
        """Leave the summary out of the metadata (and do not measure the records for it)."""
        self._summary = False

    def _measure(self, entry, record, sampled):
        """Add a record's serialized bytes (and, when ``sampled``, its row-JSON bytes) to its topic's entry."""
        if not self._summary:
            return
        msg = record.msg
        try:
            size = len(record.raw) if record.raw is not None else _serialized_length(msg)
        except Exception:  # a message genpy cannot serialize: the format fails on it; no summary
            self._summary = False
            return
        entry[0] += size
        if not sampled:
            return
        try:
            if msg is None:
                msg = raw_message.decoded(record).msg
        except raw_message.DECODE_ERRORS:
            return  # not measured: the format leaves such a record out, and its file keeps no summary
        if self._json is None:
            self._json = msg_codec.RowJsonCounter()
        try:
            json_bytes = self._json.count(msg)
        except Exception:  # a value row JSON cannot hold: no summary
            self._summary = False
            return
        entry[3] += 1
        entry[4] += size
        entry[5] += json_bytes

    def summary(self):
        """The summary's metadata entries (``SUMMARY_KEYS``; {} when a record could not be measured)."""
        spans = [stamp for entry in self._sizes.values() for stamp in entry[1:3]]
        if not self._summary or not all(math.isfinite(stamp) for stamp in spans):
            return {}
        raw = 0.0
        for topic, (size, _, _, sampled, sampled_bytes, json_bytes) in self._sizes.items():
            if sampled == self.counts[topic]:
                raw += json_bytes
            elif sampled_bytes:
                raw += json_bytes * size / float(sampled_bytes)
            elif sampled:
                raw += json_bytes * self.counts[topic] / float(sampled)
        return {'topic_bytes': {topic: entry[0] for topic, entry in self._sizes.items()},
                'topic_spans': {topic: [float(entry[1]), float(entry[2])] for topic, entry in self._sizes.items()},
                'raw_json_bytes': int(round(raw))}

    def metadata(self, triggers, part, codec, extra=None):
        """``window_metadata`` of the records taken."""
        entries, explained = [], why_.said(triggers)
        for index, trigger in enumerate(triggers):
            entry = {'stamp': float(trigger.stamp), 'reason': str(trigger.reason), 'score': _score(trigger.score)}
            if getattr(trigger, 'name', None) is not None:
                entry['name'] = str(trigger.name)
            if index in explained:
                entry['why'] = why_.bounded(trigger.why)
            entries.append(entry)
        meta = {
            'topics': list(self.types),
            'types': dict(self.types),
            'counts': dict(self.counts),
            'count': self.count,
            'start': float(self.start),
            'end': float(self.end),
            'start_utc': utc_text(self.start),
            'end_utc': utc_text(self.end),
            'triggers': entries,
            'reasons': list(dict.fromkeys(entry['reason'] for entry in entries)),
            'names': list(dict.fromkeys(entry.get('name', entry['reason']) for entry in entries)),
            'part': int(part),
            'codec': codec,
            'cc_log_version': __version__,
        }
        meta.update(self.summary())
        meta.update(extra or {})
        return meta


def _serialized_length(msg):
    buffer = io.BytesIO()
    msg.serialize(buffer)
    return buffer.tell()


def trigger_name(trigger):
    """The name of a records.Trigger: its ``name``, or its reason when it has none."""
    name = getattr(trigger, 'name', None)
    return str(trigger.reason if name is None else name)


def _is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_count(value):
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _is_score(value):
    return value is None or _is_number(value) or (isinstance(value, str) and value in msg_codec.NON_FINITE)


_METADATA_TYPES = (  # key, test, what it must be (keys a reader uses; each may be absent)
    ('count', lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0, 'a count'),
    ('part', lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0, 'a count'),
    ('split', _is_count, 'a count'),
    ('splits', _is_count, 'a count'),
    ('window_start', _is_number, 'a number'),
    ('window_end', _is_number, 'a number'),
    ('start', _is_number, 'a number'),
    ('end', _is_number, 'a number'),
    ('threshold', lambda v: v is None or _is_number(v), 'a number'),
    ('topics', lambda v: isinstance(v, list) and all(isinstance(t, str) for t in v), 'a list of strings'),
    ('reasons', lambda v: isinstance(v, list) and all(isinstance(t, str) for t in v), 'a list of strings'),
    ('names', lambda v: isinstance(v, list) and all(isinstance(t, str) for t in v), 'a list of strings'),
    ('types', lambda v: isinstance(v, dict) and all(isinstance(t, str) for t in v.values()),
     'an object of strings'),
    ('counts', lambda v: isinstance(v, dict) and all(_is_number(n) for n in v.values()), 'an object of counts'),
    ('topic_bytes', lambda v: isinstance(v, dict) and all(_is_count(n) for n in v.values()), 'an object of counts'),
    ('topic_spans', lambda v: isinstance(v, dict) and all(
        isinstance(span, list) and len(span) == 2 and all(_is_number(t) for t in span) for span in v.values()),
     'an object of [first, last] stamps'),
    ('raw_json_bytes', lambda v: _is_count(v), 'a count'),
    ('triggers', lambda v: isinstance(v, list) and all(
        isinstance(t, dict) and _is_number(t.get('stamp')) and isinstance(t.get('reason', ''), str)
        and _is_score(t.get('score')) and isinstance(t.get('name', ''), str) and why_.check(t.get('why', []))
        for t in v),
     'a list of objects {"stamp": number, "reason": string, "score": number or null, "name": string, "why": at '
     'most %d objects of short strings (text at most %d characters) and finite numbers}'
     % (why_.MAX_ENTRIES, why_.MAX_TEXT)),
)
_METADATA_STRINGS = ('codec', 'reason', 'trigger', 'driving_topic', 'start_utc', 'end_utc', 'cc_log_version')


def check_metadata(metadata):
    """Raise ValueError('metadata: <key> must be ...') unless ``metadata`` is an object whose known keys have
    the types cc_log writes (readers such as ``cclog info`` and ``plot`` rely on them)."""
    if not isinstance(metadata, dict):
        raise ValueError('metadata must be an object')
    for key, test, what in _METADATA_TYPES:
        if key in metadata and not test(metadata[key]):
            raise ValueError('metadata: %s must be %s' % (key, what))
    for key in _METADATA_STRINGS:
        if key in metadata and not isinstance(metadata[key], str):
            raise ValueError('metadata: %s must be a string' % key)


WindowSummary = collections.namedtuple('WindowSummary', 'counts types topic_bytes topic_spans raw_json_bytes')
WindowSummary.__doc__ = """What a window file's metadata says of its records (``summary_of``): per topic, in order of
first appearance, ``counts`` (messages), ``types``, ``topic_bytes`` (serialized bytes) and ``topic_spans`` ((first,
last) stamp), and ``raw_json_bytes`` (their row-per-message JSON, estimated: ``Contents``)."""


def summary_of(metadata):
    """The ``WindowSummary`` of a window's metadata (``read_metadata``'s), or None when it does not hold one (a
    file of a cc_log before it, one with records left out, metadata whose topics do not agree)."""
    if not all(key in metadata for key in SUMMARY_KEYS + ('topics', 'types', 'counts')):
        return None
    topics = metadata['topics']
    if not all(set(topics) == set(metadata[key]) for key in ('types', 'counts', 'topic_bytes', 'topic_spans')):
        return None
    if len(set(topics)) != len(topics) or not all(_is_count(metadata['counts'][topic]) for topic in topics):
        return None
    return WindowSummary(*(collections.OrderedDict((topic, metadata[key][topic]) for topic in topics)
                           for key in ('counts', 'types', 'topic_bytes')),
                         collections.OrderedDict((topic, tuple(metadata['topic_spans'][topic])) for topic in topics),
                         metadata['raw_json_bytes'])


def merged_summary(summaries):
    """One ``WindowSummary`` of the files of one window (its own and its routes', its split files): messages and
    bytes per topic summed, spans from the first first stamp to the last last one."""
    if len(summaries) == 1:
        return summaries[0]
    counts, types, topic_bytes, spans = (collections.OrderedDict() for _ in range(4))
    for summary in summaries:
        types.update(summary.types)
        for topic, count in summary.counts.items():
            counts[topic] = counts.get(topic, 0) + count
            topic_bytes[topic] = topic_bytes.get(topic, 0) + summary.topic_bytes[topic]
            first, last = summary.topic_spans[topic]
            old = spans.get(topic, (first, last))
            spans[topic] = (min(old[0], first), max(old[1], last))
    return WindowSummary(counts, types, topic_bytes, spans,
                         raw_json_bytes=sum(summary.raw_json_bytes for summary in summaries))
