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
import sys

import numpy as np

from cc_log.base import raw_message
from cc_log.features import FeatureStream, stamp_of
from cc_log.base.records import Record
from cc_log.storage.bag import bag_reader
from cc_log.storage.bag.bag_open import (  # noqa: F401  (bagio.*)
    _one_line, check_topic, only_topic_of_type, open_bag, read_raw, topics_of)


def read_messages(path, topics, expected_types=None):
    """Yield Record(stamp, topic, msg) of ``topics`` in bag order; stamp is the header stamp, else bag time.

    ``expected_types``: optional dict topic -> type to check (and to read, when the topic has several).
    Messages of a topic's other types are skipped (see the module docstring). Raises ValueError (before
    yielding anything) for an unreadable bag or a missing topic, and naming the file for a damaged chunk or
    a message that cannot be decoded.
    """
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


__all__ = ['open_bag', 'check_topic', 'only_topic_of_type', 'topics_of', 'read_messages', 'read_raw', 'feature_vectors']
