"""Reading bags for replay, collect and learning (edge module: imports rosbag).

Every failure to read a bag is a ValueError with one clear line naming the file: missing, not a regular
file, not a bag, truncated or unindexed, a chunk declaring more bytes than it can hold or a connection with
an unsafe message definition (``safe_input.check_bag``), topic not in the bag (the topics are listed), topic
of another type.

``read_messages`` reads through ``bag_reader`` (chunks decompressed once, their declared sizes capped), then
decodes each message. A topic carrying messages of several types (two publishers, a replayed bag) is read as
its first type, or the type the caller expects: messages of the others are skipped and counted, in one
warning line on stderr.
"""
import collections
import os
import struct
import sys

import numpy as np
import rosbag

from cc_log.core import raw_message, safe_input
from cc_log.features import FeatureStream, stamp_of
from cc_log.core.records import Record


def open_bag(path, skip_index=False):
    """Open a bag for reading; raise ValueError('<path>: <what is wrong>') when it cannot be read, is not a
    regular file, or a connection's message definition is unsafe (checked before any message is read:
    rosbag generates a class from each definition). ``skip_index``: do not read the per-message index
    (``bag_reader`` reads it itself)."""
    if not os.path.exists(path):
        raise ValueError('%s: no such bag file' % path)
    if os.path.isdir(path):
        raise ValueError('%s: is a directory, not a bag file' % path)
    try:
        with safe_input.open_input(path) as stream:
            magic = stream.read(13)
    except (IOError, OSError) as error:
        raise ValueError('%s: cannot read: %s' % (path, error.strerror or error))
    if not magic.startswith(b'#ROSBAG V'):
        raise ValueError('%s: not a ROS bag (no #ROSBAG header)' % path)
    if not magic.startswith(b'#ROSBAG V2.0'):
        raise ValueError('%s: unsupported bag version %s (cc_log reads 2.0)'
                         % (path, magic[9:12].decode('ascii', 'replace')))
    try:
        bag = rosbag.Bag(path, 'r', allow_unindexed=False, skip_index=skip_index)
    except rosbag.ROSBagUnindexedException:
        raise ValueError('%s: bag is unindexed or truncated (try `rosbag reindex` on a copy)' % path)
    except (rosbag.ROSBagException, rosbag.ROSBagFormatException, struct.error, EOFError, ValueError,
            KeyError, IndexError, OSError) as error:
        raise ValueError('%s: bag is truncated or damaged (%s)' % (path, _one_line(error)))
    try:
        _check_index(bag, path)
        safe_input.check_bag(bag, path)
    except Exception:
        bag.close()
        raise
    return bag


def _one_line(error):
    text = str(error).strip().splitlines()
    return (text[0] if text else type(error).__name__)[:200]


def _check_index(bag, path):
    """An indexed bag whose chunks lie beyond the end of the file was cut after it was indexed."""
    size = os.path.getsize(path)
    for chunk in getattr(bag, '_chunks', []):
        if chunk.pos >= size:
            raise ValueError('%s: bag is truncated (chunk at byte %d, file has %d bytes)' % (path, chunk.pos, size))


def types_of(bag):
    """dict topic -> the message types of its connections, in connection order (the first is ``topics_of``'s)."""
    types = collections.OrderedDict()
    for connection in bag._connections.values():
        kinds = types.setdefault(connection.topic, [])
        if connection.datatype not in kinds:
            kinds.append(connection.datatype)
    return types


def topics_of(bag):
    """dict topic -> message type of an open bag."""
    return {topic: info.msg_type for topic, info in bag.get_type_and_topic_info().topics.items()}


def check_topic(bag, topic, expected_type=None):
    """Return the type of ``topic`` in the open bag; ValueError when absent or not ``expected_type``."""
    topics = topics_of(bag)
    if topic not in topics:
        listing = ', '.join('%s (%s)' % (name, topics[name]) for name in sorted(topics)) or 'none'
        raise ValueError('%s: topic %s is not in the bag; its topics: %s' % (bag.filename, topic, listing))
    if expected_type is not None and topics[topic] != expected_type:
        if expected_type in types_of(bag).get(topic, ()):
            return expected_type  # one of its types: the others are skipped (read_messages)
        raise ValueError('%s: topic %s is %s, expected %s' % (bag.filename, topic, topics[topic], expected_type))
    return topics[topic]


def read_messages(path, topics, expected_types=None):
    """Yield Record(stamp, topic, msg) of ``topics`` in bag order; stamp is the header stamp, else bag time.

    ``expected_types``: optional dict topic -> type to check (and to read, when the topic has several).
    Messages of a topic's other types are skipped (see the module docstring). Raises ValueError (before
    yielding anything) for an unreadable bag or a missing topic, and naming the file for a damaged chunk or
    a message that cannot be decoded.
    """
    from cc_log.storage.bag import bag_reader
    if isinstance(topics, str):
        topics = [topics]
    bag = open_bag(path, skip_index=True)
    try:
        chosen = dict((topic, check_topic(bag, topic, (expected_types or {}).get(topic))) for topic in topics)
    finally:
        bag.close()
    skipped = collections.Counter()
    for run in bag_reader.read_runs(path, topics):
        for record in run:
            kind = record.connection['type']
            if kind != chosen[record.topic]:
                skipped[record.topic, kind] += 1
                continue
            try:
                msg = raw_message.decode(record.raw, record.connection)
            except raw_message.DECODE_ERRORS as error:
                raise ValueError('%s: a %s message on %s at %.3f cannot be decoded (%s)'
                                 % (path, kind, record.topic, record.stamp, _one_line(error)))
            yield Record(stamp_of(msg, record.stamp), record.topic, msg)
    if skipped:
        sys.stderr.write('warning: %s: read as %s; skipped %s\n' % (
            path, ', '.join('%s %s' % (topic, chosen[topic]) for topic in sorted(set(t for t, _ in skipped))),
            ', '.join('%d %s on %s' % (count, kind, topic) for (topic, kind), count in sorted(skipped.items()))))


def read_raw(path, topics):
    """Yield Record(bag time, topic, None, 0, serialized bytes, connection header) of ``topics`` in bag order,
    without decoding (``raw_message.stamp`` finds the header stamp; ``raw_message.decoded`` the message). The
    connection header (a dict of str) is one object per connection. Errors as ``read_messages``."""
    if isinstance(topics, str):
        topics = [topics]
    bag = open_bag(path)
    headers = {}  # id of rosbag's header dict -> (that dict, its text form)
    try:
        for topic in topics:
            check_topic(bag, topic)
        try:
            for topic, msg, t, header in bag.read_messages(topics=list(topics), raw=True,
                                                           return_connection_header=True):
                known = headers.get(id(header))
                if known is None or known[0] is not header:
                    known = headers[id(header)] = (header, raw_message.text_header(header))
                yield Record(t.to_sec(), topic, None, 0, msg[1], known[1])
        except (rosbag.ROSBagException, struct.error, EOFError) as error:
            raise ValueError('%s: bag is truncated or damaged (%s)' % (path, _one_line(error)))
    finally:
        bag.close()


def feature_vectors(path, topic, config, stride=1, max_dt=None):
    """Run the features over ``topic`` of a bag: return ``(stamps, X)`` (1-D array, 2-D array).

    ``topic``: the topic of the feature set's first input, or a list of it and the topics of the set's other
    inputs (in the order of ``config.feature.inputs``; each checked for its type). Vectors come from the
    ``features.FeatureStream`` every mode uses: one at every ``stride``-th message once the feature window
    holds a whole window of continuous data (no vector mixes data from both sides of a gap or a backwards
    jump, or is computed from a few rows after one).
    """
    if stride < 1:
        raise ValueError('stride: must be at least 1, got %r' % stride)
    topics = [topic] if isinstance(topic, str) else list(topic)
    inputs = config.feature.inputs
    if len(topics) != len(inputs):
        raise ValueError('topic: the %s feature set reads %d topic(s) (%s), got %d'
                         % (config.feature_set, len(inputs), ', '.join(role for role, _ in inputs), len(topics)))
    roles = {name: role for name, (role, _) in zip(topics[1:], inputs[1:])}
    stream = FeatureStream(config, every=stride, max_dt=max_dt)
    stamps, vectors = [], []
    for record in read_messages(path, topics, {name: kind for name, (_, kind) in zip(topics, inputs)}):
        if record.topic in roles:
            stream.observe(roles[record.topic], record.msg, record.stamp)
            continue
        vector = stream.add(record.msg, record.stamp)
        if vector is not None:
            stamps.append(record.stamp)
            vectors.append(vector)
    width = len(vectors[0]) if vectors else 0
    return np.array(stamps, dtype=float), np.array(vectors, dtype=float).reshape(len(vectors), width)


__all__ = ['open_bag', 'check_topic', 'topics_of', 'read_messages', 'read_raw', 'feature_vectors']
