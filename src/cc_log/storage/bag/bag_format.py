"""The rosbag 2.0 format's constants (the file's magic line, the record op codes), its bag time, and the topic of a
cc_log window's metadata: what ``bag_writer``, ``bag_salvage``, ``bag_reader`` and ``formats.bag_lz4`` share."""
import math

MAGIC = b'#ROSBAG V2.0\n'
OP_MSG_DATA, OP_FILE_HEADER, OP_INDEX_DATA, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION = 2, 3, 4, 5, 6, 7  # record ops
METADATA_TOPIC = '/cc_log/metadata'  # a window's metadata (JSON in a std_msgs/String), first in its bag


def bag_stamp(stamp):
    """Float seconds -> (secs, nsecs) of a bag time, nanoseconds rounded to nearest; ValueError for negative or
    not finite."""
    stamp = float(stamp)
    if not math.isfinite(stamp) or stamp < 0:
        raise ValueError('stamp %r cannot be a bag time (must be finite and >= 0)' % stamp)
    secs = int(math.floor(stamp))
    nsecs = int(round((stamp - secs) * 1e9))
    if nsecs >= 1000000000:
        secs, nsecs = secs + 1, nsecs - 1000000000
    return secs, nsecs
