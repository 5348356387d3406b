"""Opening a bag with rosbag, checked (``bagio``'s errors: one line naming the file), its topics and types, and
its raw records as rosbag reads them: what ``bagio`` and ``bag_reader`` share (edge module: imports rosbag)."""
import collections
import os
import struct

import rosbag

from cc_log.base import raw_message, safe_input
from cc_log.base.records import Record


def open_bag(path, skip_index=False):
    """Open a bag for reading; raise ValueError('<path>: <what is wrong>') when it cannot be read, is not a
    regular file, or a connection's message definition is unsafe (checked before any message is read:
    rosbag generates a class from each definition). ``skip_index``: do not read the per-message index
    (``bag_reader`` reads it itself, and inflates the chunks itself, bounded)."""
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
        safe_input.check_bag(bag, path, inflate_bz2=not skip_index)  # skip_index: bag_reader inflates, bounded
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


def only_topic_of_type(bag, type_name):
    """The one topic of the open bag whose type is ``type_name``; ValueError naming the candidates (or the bag's
    topics when there is none) when there is not exactly one."""
    topics = topics_of(bag)
    found = sorted(topic for topic, kind in topics.items() if kind == type_name)
    if len(found) == 1:
        return found[0]
    if found:
        raise ValueError('%s: %d topics carry %s (%s): give --topic'
                         % (bag.filename, len(found), type_name, ', '.join(found)))
    listing = ', '.join('%s (%s)' % (name, topics[name]) for name in sorted(topics)) or 'none'
    raise ValueError('%s: no topic carries %s; its topics: %s' % (bag.filename, type_name, listing))


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
        except (rosbag.ROSBagException, struct.error, EOFError, OSError) as error:  # OSError: roslz4, bz2
            raise ValueError('%s: bag is truncated or damaged (%s)' % (path, _one_line(error)))
    finally:
        bag.close()
